//! The committed fuzz corpora (fuzz/corpus/) replayed through the fuzz targets' bodies: every
//! input the fuzzer kept, findings' reproducers included, stays panic-free in the ordinary suite.

use so101_core::fuzzing::replay_corpus;

use so101_camera_node::fuzzing;

#[test]
fn the_camera_calibration_yaml_corpus_replays() {
    replay_corpus("camera_calibration_yaml", fuzzing::calibration_yaml);
}

#[test]
fn the_camera_request_corpus_replays() {
    replay_corpus("camera_request", fuzzing::camera_request);
}

#[test]
fn the_whole_jpeg_corpus_replays() {
    replay_corpus("whole_jpeg", fuzzing::whole_jpeg_frame);
}
