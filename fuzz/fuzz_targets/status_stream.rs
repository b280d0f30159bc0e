#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| so101_feetech_driver::fuzzing::status_stream(data));
