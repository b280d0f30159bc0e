//! The body of the cargo-fuzz target (fuzz/) over a camera placements file, shared with the corpus
//! replay test (tests/fuzz_corpus.rs) so the two cannot drift. It never panics on any input.

use super::placement::{CameraPlacements, MAX_DISTANCE};

/// A user's placements file (so101-camera-align's, or hand-edited): an accepted one holds only
/// cameras a scene could take, each at a finite place within reach, turned by a unit quaternion,
/// with a field of view and a size the renderer can draw.
pub fn camera_poses_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(placements) = CameraPlacements::from_toml(text, "fuzz") else {
        return;
    };
    assert!(!placements.cameras.is_empty());
    for (name, camera) in &placements.cameras {
        assert!(!name.is_empty());
        assert!(camera
            .position
            .iter()
            .all(|v| v.is_finite() && v.abs() <= MAX_DISTANCE));
        let norm = camera.quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() <= 1e-3, "{norm}");
        assert!(camera.fovy > 1.0 && camera.fovy < 179.0);
        assert_eq!(placements.size(name), Some(camera.size()));
    }
}
