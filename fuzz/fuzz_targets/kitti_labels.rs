#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap::fuzzing::kitti_labels(data));
