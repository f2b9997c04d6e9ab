//! A map-file track (map_server YAML, centre-line CSV, PGM or PNG image) loaded as `--track`
//! loads one, and a simulator built on it driven for a few periods.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_sim::fuzz::map_file(data);
});
