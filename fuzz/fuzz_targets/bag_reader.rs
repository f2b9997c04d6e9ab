//! The bag reader on arbitrary MCAP bytes, and every message it yields through the decoder of
//! its type (`agvrl-drive --replay`, `--dump`, `agvrl.read_bag`): never a panic, a hang or an
//! unbounded allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_deploy::bag::fuzz::read_and_decode(data);
});
