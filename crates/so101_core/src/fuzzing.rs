//! The bodies of the cargo-fuzz targets (fuzz/) over this crate's parsers of outside input (servo
//! parameter files, episode bags), shared with the corpus replay test (tests/fuzz_corpus.rs) so the
//! two cannot drift. Each takes the raw fuzzer input, never panics on any input, and asserts what
//! the parser promises.

use std::path::{Path, PathBuf};

use crate::servo::ArmServoParams;

/// fuzz/corpus/<target>/ of this checkout: the inputs the fuzzer kept (minimized by cmin, which
/// renames and drops inputs at will).
pub fn corpus_dir(target: &str) -> PathBuf {
    fuzz_dir().join("corpus").join(target)
}

/// fuzz/regressions/<target>/: each finding's reproducer, under a name that says what it found;
/// kept apart from the corpus so minimizing it can never drop one.
pub fn regressions_dir(target: &str) -> PathBuf {
    fuzz_dir().join("regressions").join(target)
}

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

/// Runs every file of the target's corpus and of its regressions (where it has any) through `run`
/// (the target's body): the replay of the corpora in the ordinary test suite. Returns how many
/// inputs ran; panics on an empty corpus.
pub fn replay_corpus(target: &str, run: fn(&[u8])) -> usize {
    let corpus = corpus_dir(target);
    let entries = std::fs::read_dir(&corpus)
        .unwrap_or_else(|error| panic!("cannot read the corpus {}: {error}", corpus.display()));
    let regressions = std::fs::read_dir(regressions_dir(target))
        .into_iter()
        .flatten();
    let mut count = 0;
    for entry in entries.chain(regressions) {
        let path = entry.expect("a corpus directory entry").path();
        let data = std::fs::read(&path)
            .unwrap_or_else(|error| panic!("cannot read {}: {error}", path.display()));
        // Shown with a failure: which input it was.
        eprintln!("{target}: {}", path.display());
        run(&data);
        count += 1;
    }
    assert!(count > 0, "{} holds no input", corpus.display());
    count
}

/// A servo parameter file: an accepted one gives finite gains and limits for every joint, and
/// written back it is accepted again with the same numbers (to the last digit serde_json's float
/// parsing guarantees).
pub fn servo_params_json(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(params) = ArmServoParams::from_json(text) else {
        return;
    };
    for joint in &params.0 {
        let (below, above) = joint.dead_zone();
        for value in [
            joint.kp(),
            joint.kd(),
            joint.ki(),
            joint.torque_ceiling(),
            joint.speed_limit(),
            below,
            above,
        ] {
            assert!(value.is_finite() && value >= 0.0, "{value} of {joint:?}");
        }
        assert!(joint.acceleration_limit() > 0.0);
    }
    let again = ArmServoParams::from_json(&params.to_json())
        .expect("a parameter file's own JSON is accepted");
    for (a, b) in again.0.iter().zip(&params.0) {
        for (x, y) in [
            (a.kp(), b.kp()),
            (a.kd(), b.kd()),
            (a.torque_ceiling(), b.torque_ceiling()),
        ] {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(y.abs()), "{x} != {y}");
        }
    }
}

/// The record length limit the bag target reads with: the reader's memory is bounded by it, and it
/// stays under the fuzzer's allocation limit (scripts/fuzz.sh).
#[cfg(all(feature = "bag", feature = "ros"))]
const BAG_RECORD_LIMIT: usize = 64 << 20;

/// An episode bag's MCAP file, read as so101_viz reads it (in reads of a size the first byte
/// sets): every message's payload is decoded as each message type a bag holds; nothing panics and
/// nothing allocates beyond the record length limit.
#[cfg(all(feature = "bag", feature = "ros"))]
pub fn episode_bag_mcap(data: &[u8]) {
    use crate::bag_read::{decode_cdr, read_messages};
    use so101_msgs::{
        geometry_msgs::PoseStamped,
        sensor_msgs::{CompressedImage, Image, JointState},
        std_msgs::{Bool, Float64},
    };

    let (read_size, file) = match data.split_first() {
        Some((first, rest)) => (usize::from(*first) * 64 + 1, rest),
        None => (1, data),
    };
    let input = Trickle { file, read_size };
    let mut messages = 0usize;
    let ended = read_messages(input, BAG_RECORD_LIMIT, |_topic, payload| {
        messages += 1;
        let _ = decode_cdr::<JointState>(payload);
        let _ = decode_cdr::<PoseStamped>(payload);
        let _ = decode_cdr::<Float64>(payload);
        let _ = decode_cdr::<Bool>(payload);
        let _ = decode_cdr::<Image>(payload);
        let _ = decode_cdr::<CompressedImage>(payload);
        Ok::<(), std::convert::Infallible>(())
    });
    assert!(ended.is_ok(), "reading from memory does not fail");
    if messages > 0 {
        assert!(
            file.starts_with(b"\x89MCAP"),
            "messages only from an MCAP file"
        );
    }
}

/// A file that returns at most `read_size` bytes per read, as a pipe or a slow disk may.
#[cfg(all(feature = "bag", feature = "ros"))]
struct Trickle<'a> {
    file: &'a [u8],
    read_size: usize,
}

#[cfg(all(feature = "bag", feature = "ros"))]
impl std::io::Read for Trickle<'_> {
    fn read(&mut self, buffer: &mut [u8]) -> std::io::Result<usize> {
        let count = buffer.len().min(self.read_size).min(self.file.len());
        buffer[..count].copy_from_slice(&self.file[..count]);
        self.file = &self.file[count..];
        Ok(count)
    }
}
