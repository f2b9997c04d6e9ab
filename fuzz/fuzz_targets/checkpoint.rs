//! A checkpoint, loaded as `train --resume` loads one (byte 0: PPO or SAC; the rest: the file
//! without its CRC-32, which the body appends).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_rl::fuzz::checkpoint(data);
});
