#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| arcnav::fuzzing::ros1_bag(data));
