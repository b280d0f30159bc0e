#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| so101_core::fuzzing::servo_params_json(data));
