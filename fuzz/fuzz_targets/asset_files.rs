//! A scene TOML, vehicle TOML, vehicle URDF or object URDF (byte 0 picks) loaded as a user's file
//! is, and a simulator built from it driven for a few periods.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_sim::fuzz::asset_file(data);
});
