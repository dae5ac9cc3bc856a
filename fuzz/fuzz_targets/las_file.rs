#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap::fuzzing::las_file(data));
