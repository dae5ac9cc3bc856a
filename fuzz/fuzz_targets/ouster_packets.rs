#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap_fuzzing::ouster_packets(data));
