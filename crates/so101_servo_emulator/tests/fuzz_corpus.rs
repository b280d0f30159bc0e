//! The committed fuzz corpora (fuzz/corpus/) replayed through the fuzz targets' bodies: every
//! input the fuzzer kept, findings' reproducers included, stays panic-free in the ordinary suite.

use so101_core::fuzzing::replay_corpus;

#[test]
fn the_instruction_stream_corpus_replays() {
    replay_corpus(
        "instruction_stream",
        so101_servo_emulator::fuzzing::instruction_stream,
    );
}
