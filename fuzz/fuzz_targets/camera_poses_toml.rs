#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| so101_sim::cameras::fuzzing::camera_poses_toml(data));
