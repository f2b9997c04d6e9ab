//! One incoming ROS 2 message (first byte: which type; the rest: its CDR bytes, as the DDS side
//! hands them to the same `cdr-encoding` deserializer) through the live car's frame assembly.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    agvrl_deploy::bag::fuzz::ros2_message(data);
});
