#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap::fuzzing::ouster_packets(data));
