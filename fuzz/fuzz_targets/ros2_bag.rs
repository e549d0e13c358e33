#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| arcnav::fuzzing::ros2_bag(data));
