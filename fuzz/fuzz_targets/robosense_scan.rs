#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap_fuzzing::robosense_scan(data));
