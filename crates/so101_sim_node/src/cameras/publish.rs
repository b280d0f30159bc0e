//! The camera topics: Image (rgb8), CameraInfo and optional JPEG per camera, published on their
//! own thread so that neither rendering nor the physics waits for DDS.

use std::{
    sync::mpsc::Receiver,
    time::{Duration, Instant},
};

use ros2_client::Publisher;
use so101_core::{
    contract::topics,
    ros::{qos, rate_limit::RateLimiter, RosNode},
};
use so101_msgs::{
    builtin_interfaces::Time,
    sensor_msgs::{CameraInfo, CompressedImage, Image, RegionOfInterest},
    std_msgs::Header,
};

use so101_core::ros::node::NodeError;
use so101_sim::cameras::{intrinsics::Intrinsics, rig::FrameBatch};

/// The publishers and fixed message parts of one camera.
pub struct CameraTopics {
    frame_id: String,
    intrinsics: Intrinsics,
    image: Publisher<Image>,
    info: Publisher<CameraInfo>,
    compressed: Option<Publisher<CompressedImage>>,
}

impl CameraTopics {
    /// /camera/<name>/image_raw, /camera/<name>/camera_info and, with `jpeg`,
    /// /camera/<name>/image_raw/compressed.
    pub fn advertise(
        node: &mut RosNode,
        name: &str,
        intrinsics: Intrinsics,
        jpeg: bool,
    ) -> Result<Self, NodeError> {
        let base = format!("camera/{name}");
        let qos = qos::default_topic();
        Ok(Self {
            frame_id: topics::camera_optical_frame(name),
            intrinsics,
            image: node.publisher(&format!("{base}/image_raw"), qos.clone())?,
            info: node.publisher(&format!("{base}/camera_info"), qos.clone())?,
            compressed: if jpeg {
                Some(node.publisher(&format!("{base}/image_raw/compressed"), qos)?)
            } else {
                None
            },
        })
    }
}

/// sensor_msgs/CameraInfo of an ideal pinhole camera.
pub fn camera_info(header: Header, intrinsics: &Intrinsics) -> CameraInfo {
    CameraInfo {
        header,
        height: intrinsics.height,
        width: intrinsics.width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: intrinsics.k(),
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: intrinsics.p(),
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

/// JPEG of an rgb8 frame (quality 1-100).
pub fn encode_jpeg(rgb: &[u8], width: u32, height: u32, quality: u8) -> Result<Vec<u8>, String> {
    let (width, height) = (
        u16::try_from(width).map_err(|_| "frame too wide for JPEG")?,
        u16::try_from(height).map_err(|_| "frame too high for JPEG")?,
    );
    let mut jpeg = Vec::with_capacity(rgb.len() / 8);
    jpeg_encoder::Encoder::new(&mut jpeg, quality)
        .encode(rgb, width, height, jpeg_encoder::ColorType::Rgb)
        .map_err(|error| error.to_string())?;
    Ok(jpeg)
}

/// The publishing thread's work: every batch out, in order.
pub fn publish_batches(topics: &[CameraTopics], jpeg_quality: u8, batches: &Receiver<FrameBatch>) {
    let mut failures = RateLimiter::new(Duration::from_secs(5));
    for batch in batches {
        let stamp = Time::from_secs_f64(batch.sim_time);
        for frame in batch.frames {
            let camera = &topics[frame.camera];
            let header = Header {
                stamp,
                frame_id: camera.frame_id.clone(),
            };
            let (width, height) = (camera.intrinsics.width, camera.intrinsics.height);
            let jpeg = camera
                .compressed
                .as_ref()
                .map(|_| encode_jpeg(&frame.rgb, width, height, jpeg_quality));
            let mut ok = camera
                .info
                .publish(camera_info(header.clone(), &camera.intrinsics))
                .is_ok();
            ok &= camera
                .image
                .publish(Image {
                    header: header.clone(),
                    height,
                    width,
                    encoding: "rgb8".into(),
                    is_bigendian: 0,
                    step: 3 * width,
                    data: frame.rgb,
                })
                .is_ok();
            if let (Some(publisher), Some(jpeg)) = (&camera.compressed, jpeg) {
                ok &= jpeg.is_ok_and(|data| {
                    publisher
                        .publish(CompressedImage {
                            header,
                            format: topics::JPEG_FORMAT.into(),
                            data,
                        })
                        .is_ok()
                });
            }
            if !ok {
                if let Some(suppressed) = failures.check(Instant::now()) {
                    tracing::warn!(suppressed, camera = %camera.frame_id, "publishing a camera frame failed");
                }
            }
        }
        if let Some(published) = batch.published {
            let _ = published.send(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_info_carries_the_pinhole_model() {
        let intrinsics = Intrinsics::from_fovy(60.0, 64, 48);
        let info = camera_info(Header::default(), &intrinsics);
        assert_eq!((info.width, info.height), (64, 48));
        assert_eq!(info.k, intrinsics.k());
        assert_eq!(info.p, intrinsics.p());
        assert_eq!(info.d, vec![0.0; 5]);
        assert_eq!(info.r[0] + info.r[4] + info.r[8], 3.0);
    }

    #[test]
    fn jpeg_starts_and_ends_with_its_markers() {
        let rgb: Vec<u8> = (0..32 * 16 * 3).map(|i| (i % 251) as u8).collect();
        let jpeg = encode_jpeg(&rgb, 32, 16, 90).unwrap();
        assert_eq!(&jpeg[..2], &[0xFF, 0xD8]);
        assert_eq!(&jpeg[jpeg.len() - 2..], &[0xFF, 0xD9]);
        assert!(encode_jpeg(&rgb[..10], 32, 16, 90).is_err());
    }
}
