#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap::fuzzing::foxglove_message(data));
