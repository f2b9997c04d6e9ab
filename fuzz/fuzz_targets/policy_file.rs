//! A policy file, read as `--policy FILE` reads one (decoded, its embedded settings resolved, the
//! policy acting once). The input is the file without its CRC-32, which the body appends, so
//! mutations reach the decoder behind the checksum.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_run::fuzz::policy_file(data);
});
