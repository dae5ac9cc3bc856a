#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| travmap_fuzzing::kitti_calib(data));
