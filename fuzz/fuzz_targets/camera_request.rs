#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| so101_camera_node::fuzzing::camera_request(data));
