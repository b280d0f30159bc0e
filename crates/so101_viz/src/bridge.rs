//! The stack's messages -> [`SceneLog`], the same for the live topics and for a bag read back:
//! keeps the latest sim time (joint-state stamps) for unstamped topics, the joints known so far,
//! and the image rate limit.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rerun::RecordingStreamResult;
use so101_core::command::targets_from_joint_state;
use so101_core::robot::{JointPositions, JOINT_COUNT};
use so101_msgs::geometry_msgs::PoseStamped;
use so101_msgs::sensor_msgs::{CompressedImage, Image, JointState};

use crate::rerun_log::SceneLog;

/// The packed RGB pixels of an rgb8 or bgr8 image; why not otherwise.
/// The media type of a CompressedImage's `format` ("jpeg", "png", or image_transport's
/// "rgb8; jpeg compressed bgr8"); `None` for anything else (compressedDepth, unknown).
pub fn media_type_of(format: &str) -> Option<&'static str> {
    let format = format.to_ascii_lowercase();
    if format.contains("compresseddepth") {
        return None;
    }
    if format.contains("png") {
        Some(rerun::components::MediaType::PNG)
    } else if format.contains("jpeg") || format.contains("jpg") {
        Some(rerun::components::MediaType::JPEG)
    } else {
        None
    }
}

pub fn rgb_pixels(image: &Image) -> Result<Vec<u8>, String> {
    let (width, height, step) = (
        image.width as usize,
        image.height as usize,
        image.step as usize,
    );
    let row = width * 3;
    if image.encoding != "rgb8" && image.encoding != "bgr8" {
        return Err(format!("encoding {:?}, not rgb8 or bgr8", image.encoding));
    }
    if width == 0 || height == 0 {
        return Err(format!("an empty {width}x{height} image"));
    }
    let needed = step.checked_mul(height);
    if step < row || needed.is_none_or(|needed| image.data.len() < needed) {
        return Err(format!(
            "{} bytes for {width}x{height} with rows of {step} bytes",
            image.data.len()
        ));
    }
    let mut pixels = Vec::with_capacity(row * height);
    for line in image.data.chunks(step).take(height) {
        pixels.extend_from_slice(&line[..row]);
    }
    if image.encoding == "bgr8" {
        pixels
            .chunks_exact_mut(3)
            .for_each(|pixel| pixel.swap(0, 2));
    }
    Ok(pixels)
}

pub fn isometry(pose: &so101_msgs::geometry_msgs::Pose) -> Option<Isometry3<f64>> {
    let (p, q) = (pose.position, pose.orientation);
    let values = [p.x, p.y, p.z, q.w, q.x, q.y, q.z];
    if !values.iter().all(|v| v.is_finite())
        || (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z) < 1e-12
    {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::from(Vector3::new(p.x, p.y, p.z)),
        UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z)),
    ))
}

/// Counts of what was logged and what was skipped, for the closing log line and the tests.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    pub joint_states: u64,
    pub commands: u64,
    pub images: u64,
    pub images_skipped: u64,
    pub poses: u64,
    pub task: u64,
    pub rejected: u64,
}

pub struct Bridge {
    log: SceneLog,
    now: Option<f64>,
    positions: [Option<f64>; JOINT_COUNT],
    /// Minimum sim time between two images of one camera (0: every image).
    image_period: f64,
    last_image: BTreeMap<String, f64>,
    pub counts: Counts,
}

impl Bridge {
    /// `image_rate`: images logged per second of sim time and camera at most (0: all).
    pub fn new(log: SceneLog, image_rate: f64) -> Self {
        let mut bridge = Self {
            log,
            now: None,
            positions: [None; JOINT_COUNT],
            image_period: 0.0,
            last_image: BTreeMap::new(),
            counts: Counts::default(),
        };
        bridge.set_image_rate(image_rate);
        bridge
    }

    /// Images logged per second of sim time and camera at most from now on (0: all).
    pub fn set_image_rate(&mut self, image_rate: f64) {
        self.image_period = if image_rate > 0.0 {
            1.0 / image_rate
        } else {
            0.0
        };
    }

    pub fn log(&self) -> &SceneLog {
        &self.log
    }

    fn at(&mut self, time: f64) {
        self.log.set_time(time);
    }

    pub fn joint_state(&mut self, message: &JointState) -> RecordingStreamResult<()> {
        let Ok(targets) = targets_from_joint_state(&message.name, &message.position) else {
            self.counts.rejected += 1;
            return Ok(());
        };
        for (joint, known) in self.positions.iter_mut().enumerate() {
            if let Some(value) = targets.get(joint) {
                *known = Some(value);
            }
        }
        let time = message.header.stamp.as_secs_f64();
        self.now = Some(time);
        let Some(positions) = complete(&self.positions) else {
            return Ok(());
        };
        self.at(time);
        self.counts.joint_states += 1;
        self.log.joint_state(&positions)
    }

    pub fn command(&mut self, message: &JointState) -> RecordingStreamResult<()> {
        let Ok(targets) = targets_from_joint_state(&message.name, &message.position) else {
            self.counts.rejected += 1;
            return Ok(());
        };
        // Before the first joint state there is no time to put a command at.
        let Some(now) = self.now else { return Ok(()) };
        self.at(now);
        self.counts.commands += 1;
        self.log
            .joint_command(&std::array::from_fn(|joint| targets.get(joint)))
    }

    /// Whether a frame of `camera` stamped `time` is due under the image rate (counts the skip).
    fn image_due(&mut self, camera: &str, time: f64) -> bool {
        if let Some(last) = self.last_image.get(camera) {
            // A stamp going backwards is a restarted sim: log again from there.
            if time >= *last && time - last < self.image_period - 1e-9 {
                self.counts.images_skipped += 1;
                return false;
            }
        }
        true
    }

    /// A frame of `camera` stamped `time` is being logged: the rate limit counts from it.
    fn image_logged(&mut self, camera: &str, time: f64) {
        self.last_image.insert(camera.to_owned(), time);
        self.at(time);
        self.counts.images += 1;
    }

    /// A sensor_msgs/CompressedImage (image_transport's /compressed), logged as the encoded
    /// JPEG or PNG it is: Rerun decodes it, this process never does.
    pub fn compressed_image(
        &mut self,
        camera: &str,
        message: &CompressedImage,
    ) -> RecordingStreamResult<()> {
        let time = message.header.stamp.as_secs_f64();
        if !self.image_due(camera, time) {
            return Ok(());
        }
        let Some(media_type) = media_type_of(&message.format) else {
            tracing::debug!(camera, format = %message.format, "compressed image not logged");
            self.counts.rejected += 1;
            return Ok(());
        };
        self.image_logged(camera, time);
        self.log
            .encoded_image(camera, message.data.clone(), media_type)
    }

    pub fn image(&mut self, camera: &str, message: &Image) -> RecordingStreamResult<()> {
        let time = message.header.stamp.as_secs_f64();
        if !self.image_due(camera, time) {
            return Ok(());
        }
        let pixels = match rgb_pixels(message) {
            Ok(pixels) => pixels,
            Err(reason) => {
                tracing::debug!(camera, %reason, "image not logged");
                self.counts.rejected += 1;
                return Ok(());
            }
        };
        self.image_logged(camera, time);
        self.log
            .image(camera, message.width, message.height, pixels)
    }

    pub fn cube(&mut self, message: &PoseStamped) -> RecordingStreamResult<()> {
        let Some(pose) = isometry(&message.pose) else {
            self.counts.rejected += 1;
            return Ok(());
        };
        self.at(message.header.stamp.as_secs_f64());
        self.counts.poses += 1;
        self.log.cube(&pose)
    }

    pub fn reward(&mut self, value: f64) -> RecordingStreamResult<()> {
        let Some(now) = self.now else { return Ok(()) };
        self.at(now);
        self.counts.task += 1;
        self.log.reward(value)
    }

    pub fn success(&mut self, success: bool) -> RecordingStreamResult<()> {
        let Some(now) = self.now else { return Ok(()) };
        self.at(now);
        self.counts.task += 1;
        self.log.success(success)
    }
}

fn complete(known: &[Option<f64>; JOINT_COUNT]) -> Option<JointPositions> {
    let mut positions = [0.0; JOINT_COUNT];
    for (slot, value) in positions.iter_mut().zip(known) {
        *slot = (*value)?;
    }
    Some(positions)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compressed_formats_map_to_media_types() {
        assert_eq!(
            media_type_of("rgb8; jpeg compressed bgr8"),
            Some("image/jpeg")
        );
        assert_eq!(media_type_of("jpeg"), Some("image/jpeg"));
        assert_eq!(media_type_of("PNG"), Some("image/png"));
        assert_eq!(media_type_of("16UC1; compressedDepth png"), None);
        assert_eq!(media_type_of("theora"), None);
    }

    fn image(encoding: &str, width: u32, height: u32, step: u32, data: Vec<u8>) -> Image {
        Image {
            encoding: encoding.into(),
            width,
            height,
            step,
            data,
            ..Default::default()
        }
    }

    #[test]
    fn padded_rows_are_packed_and_bgr_turned_to_rgb() {
        let padded = image("bgr8", 1, 2, 4, vec![1, 2, 3, 0, 4, 5, 6, 0]);
        assert_eq!(rgb_pixels(&padded), Ok(vec![3, 2, 1, 6, 5, 4]));
    }

    #[test]
    fn short_buffers_and_other_encodings_are_refused() {
        assert!(rgb_pixels(&image("rgb8", 2, 2, 6, vec![0; 11])).is_err());
        assert!(rgb_pixels(&image("mono8", 2, 2, 2, vec![0; 4])).is_err());
        assert!(rgb_pixels(&image("rgb8", 0, 2, 0, vec![])).is_err());
        assert!(rgb_pixels(&image("rgb8", 1, u32::MAX, u32::MAX, vec![0; 3])).is_err());
    }
}
