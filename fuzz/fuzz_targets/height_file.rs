#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| arcnav::fuzzing::height_file(data));
