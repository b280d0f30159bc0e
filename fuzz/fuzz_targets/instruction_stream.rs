#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| so101_servo_emulator::fuzzing::instruction_stream(data));
