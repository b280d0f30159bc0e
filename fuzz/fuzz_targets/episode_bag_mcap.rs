#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| so101_core::fuzzing::episode_bag_mcap(data));
