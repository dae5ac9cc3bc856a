#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap::fuzzing::rosbag2_metadata(data));
