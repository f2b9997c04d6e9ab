//! A run TOML through the config reader, a written config's round trip, and its env stepped once.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_run::fuzz::run_toml(data);
});
