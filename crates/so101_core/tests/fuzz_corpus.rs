//! The committed fuzz corpora (fuzz/corpus/) replayed through the fuzz targets' bodies: every
//! input the fuzzer kept, findings' reproducers included, stays panic-free in the ordinary suite.

use so101_core::fuzzing::{self, replay_corpus};

#[test]
fn the_servo_params_json_corpus_replays() {
    replay_corpus("servo_params_json", fuzzing::servo_params_json);
}

#[cfg(all(feature = "bag", feature = "ros"))]
#[test]
fn the_episode_bag_mcap_corpus_replays() {
    replay_corpus("episode_bag_mcap", fuzzing::episode_bag_mcap);
}
