//! The committed fuzz corpora (fuzz/corpus/) replayed through the fuzz targets' bodies: every
//! input the fuzzer kept, findings' reproducers included, stays panic-free in the ordinary suite.

use so101_core::fuzzing::replay_corpus;

#[test]
fn the_status_stream_corpus_replays() {
    replay_corpus(
        "status_stream",
        so101_feetech_driver::fuzzing::status_stream,
    );
}

#[test]
fn the_calibration_json_corpus_replays() {
    replay_corpus(
        "calibration_json",
        so101_feetech_driver::fuzzing::calibration_json,
    );
}
