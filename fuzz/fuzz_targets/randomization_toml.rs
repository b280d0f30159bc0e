#![no_main]

libfuzzer_sys::fuzz_target!(
    |data: &[u8]| so101_sim::randomization::fuzzing::randomization_toml(data)
);
