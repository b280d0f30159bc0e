//! The committed fuzz corpora (fuzz/corpus/) replayed through the fuzz targets' bodies: every
//! input the fuzzer kept, findings' reproducers included, stays panic-free in the ordinary suite.

use so101_core::fuzzing::replay_corpus;

#[test]
fn the_randomization_toml_corpus_replays() {
    replay_corpus(
        "randomization_toml",
        so101_sim::randomization::fuzzing::randomization_toml,
    );
}

#[test]
fn the_camera_poses_toml_corpus_replays() {
    replay_corpus(
        "camera_poses_toml",
        so101_sim::cameras::fuzzing::camera_poses_toml,
    );
}
