//! The cameras a machine has: each /dev/videoN with its name and its stable /dev/v4l/by-id and
//! by-path links (a /dev/videoN number can change between boots and plugs; the by-id name of a
//! camera does not), and what each node is (a camera, metadata, an output: VIDIOC_QUERYCAP).
//! Reading the directories and asking the nodes is I/O; matching and wording are pure.

use std::{
    fs,
    path::{Path, PathBuf},
};

use v4l::capability::Flags;

/// One video device node.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VideoNode {
    pub path: PathBuf,
    /// The driver's name for it (/sys/class/video4linux/videoN/name), e.g. "HD USB Camera".
    pub name: String,
    /// Links in /dev/v4l/by-id and /dev/v4l/by-path that point at it.
    pub stable_paths: Vec<PathBuf>,
}

/// What a video device node is. A UVC camera has two nodes (the frames, and metadata); a driver
/// such as vivid also has output nodes; the node serves single-planar video capture only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    Camera,
    Metadata,
    Output,
    MemoryToMemory,
    MultiPlanar,
    Other,
}

impl NodeKind {
    /// From VIDIOC_QUERYCAP's device_caps (the node's own, not the whole device's).
    pub fn of_caps(caps: Flags) -> Self {
        if caps.intersects(Flags::VIDEO_M2M | Flags::VIDEO_M2M_MPLANE) {
            Self::MemoryToMemory
        } else if caps.contains(Flags::VIDEO_CAPTURE) {
            Self::Camera
        } else if caps.contains(Flags::VIDEO_CAPTURE_MPLANE) {
            Self::MultiPlanar
        } else if caps.contains(Flags::META_CAPTURE) {
            Self::Metadata
        } else if caps
            .intersects(Flags::VIDEO_OUTPUT | Flags::VIDEO_OUTPUT_MPLANE | Flags::META_OUTPUT)
        {
            Self::Output
        } else {
            Self::Other
        }
    }

    /// Why a node that is not a camera is not served.
    pub fn why_not_a_camera(self) -> Option<&'static str> {
        match self {
            Self::Camera => None,
            Self::Metadata => Some("not a camera: metadata (a UVC camera's second node)"),
            Self::Output => Some("not a camera: an output"),
            Self::MemoryToMemory => Some("not a camera: a memory-to-memory device (a codec)"),
            Self::MultiPlanar => {
                Some("multi-planar capture, which the node does not take (MJPG or YUYV cameras)")
            }
            Self::Other => Some("not a camera: no video capture"),
        }
    }
}

/// What the node at `path` is (VIDIOC_QUERYCAP).
pub fn node_kind(path: &Path) -> Result<NodeKind, String> {
    let caps = v4l::Device::with_path(path)
        .and_then(|device| device.query_caps())
        .map_err(|error| format!("cannot ask {} what it is: {error}", path.display()))?;
    Ok(NodeKind::of_caps(caps.capabilities))
}

/// Every /dev/videoN, in index order. A UVC camera has two: the frames, and metadata (which lists
/// no format).
pub fn video_nodes() -> Vec<VideoNode> {
    let mut paths: Vec<PathBuf> = fs::read_dir("/dev")
        .into_iter()
        .flatten()
        .flatten()
        .map(|entry| entry.path())
        .filter(|path| video_index(path).is_some())
        .collect();
    paths.sort_by_key(|path| video_index(path));
    let links = stable_links();
    paths
        .into_iter()
        .map(|path| {
            let name = path
                .file_name()
                .and_then(|file| {
                    fs::read_to_string(Path::new("/sys/class/video4linux").join(file).join("name"))
                        .ok()
                })
                .map(|name| name.trim().to_owned())
                .unwrap_or_default();
            let stable_paths = links_to(&path, &links);
            VideoNode {
                path,
                name,
                stable_paths,
            }
        })
        .collect()
}

fn video_index(path: &Path) -> Option<u32> {
    path.file_name()?
        .to_str()?
        .strip_prefix("video")?
        .parse()
        .ok()
}

/// (link, the node it resolves to) for each link under /dev/v4l.
fn stable_links() -> Vec<(PathBuf, PathBuf)> {
    ["/dev/v4l/by-id", "/dev/v4l/by-path"]
        .iter()
        .flat_map(|dir| fs::read_dir(dir).into_iter().flatten().flatten())
        .filter_map(|entry| {
            let link = entry.path();
            let target = fs::canonicalize(&link).ok()?;
            Some((link, target))
        })
        .collect()
}

/// The links that resolve to `node`, by-id first.
pub fn links_to(node: &Path, links: &[(PathBuf, PathBuf)]) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = links
        .iter()
        .filter(|(_, target)| target == node)
        .map(|(link, _)| link.clone())
        .collect();
    found.sort_by_key(|link| !link.to_string_lossy().contains("by-id"));
    found
}

/// Why a camera cannot be served: its device node is not there, and what is.
pub fn missing_message(wanted: &Path, present: &[VideoNode]) -> String {
    if present.is_empty() {
        return format!(
            "no camera at {}: this machine has no video device (is the camera plugged in? \
             `ls /dev/v4l/by-id` lists cameras by name)",
            wanted.display()
        );
    }
    let listed: Vec<String> = present.iter().map(describe).collect();
    format!(
        "no camera at {}; the video devices here: {}",
        wanted.display(),
        listed.join("; ")
    )
}

/// "/dev/video0 (HD USB Camera, /dev/v4l/by-id/usb-...-video-index0)".
pub fn describe(node: &VideoNode) -> String {
    let mut about: Vec<String> = Vec::new();
    if !node.name.is_empty() {
        about.push(node.name.clone());
    }
    about.extend(
        node.stable_paths
            .iter()
            .map(|path| path.display().to_string()),
    );
    if about.is_empty() {
        node.path.display().to_string()
    } else {
        format!("{} ({})", node.path.display(), about.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stable_links_are_matched_to_their_node_by_id_first() {
        let links = vec![
            (
                PathBuf::from("/dev/v4l/by-path/pci-0000:00:14.0-usb-0:2:1.0-video-index0"),
                PathBuf::from("/dev/video0"),
            ),
            (
                PathBuf::from("/dev/v4l/by-id/usb-HD_USB_Camera-video-index0"),
                PathBuf::from("/dev/video0"),
            ),
            (
                PathBuf::from("/dev/v4l/by-id/usb-HD_USB_Camera-video-index1"),
                PathBuf::from("/dev/video1"),
            ),
        ];
        let found = links_to(Path::new("/dev/video0"), &links);
        assert_eq!(found.len(), 2);
        assert!(found[0].starts_with("/dev/v4l/by-id"));
    }

    #[test]
    fn only_single_planar_video_capture_nodes_are_cameras() {
        // What vivid's and a UVC camera's nodes report (device_caps, with STREAMING and
        // EXT_PIX_FORMAT set as drivers set them).
        let with = |flag: Flags| NodeKind::of_caps(Flags::STREAMING | Flags::EXT_PIX_FORMAT | flag);
        assert_eq!(with(Flags::VIDEO_CAPTURE), NodeKind::Camera);
        assert_eq!(with(Flags::META_CAPTURE), NodeKind::Metadata);
        assert_eq!(with(Flags::VIDEO_OUTPUT), NodeKind::Output);
        assert_eq!(with(Flags::META_OUTPUT), NodeKind::Output);
        assert_eq!(with(Flags::VIDEO_M2M), NodeKind::MemoryToMemory);
        assert_eq!(with(Flags::VIDEO_CAPTURE_MPLANE), NodeKind::MultiPlanar);
        assert_eq!(NodeKind::Camera.why_not_a_camera(), None);
        assert!(NodeKind::Metadata
            .why_not_a_camera()
            .unwrap()
            .contains("metadata"));
    }

    #[test]
    fn a_missing_camera_is_named_with_the_cameras_that_exist() {
        let wanted = Path::new("/dev/video4");
        let none = missing_message(wanted, &[]);
        assert!(none.contains("no camera at /dev/video4"), "{none}");
        assert!(none.contains("no video device"), "{none}");
        let present = [VideoNode {
            path: "/dev/video0".into(),
            name: "HD USB Camera".into(),
            stable_paths: vec!["/dev/v4l/by-id/usb-HD_USB_Camera-video-index0".into()],
        }];
        let some = missing_message(wanted, &present);
        assert!(
            some.contains(
                "/dev/video0 (HD USB Camera, /dev/v4l/by-id/usb-HD_USB_Camera-video-index0)"
            ),
            "{some}"
        );
        assert_eq!(video_index(Path::new("/dev/video12")), Some(12));
        assert_eq!(video_index(Path::new("/dev/vide")), None);
    }
}
