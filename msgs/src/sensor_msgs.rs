use serde::{Deserialize, Serialize};

use crate::std_msgs::Header;

/// sensor_msgs/JointState: positions in rad, velocities in rad/s, efforts in N m (REP-103).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}
crate::ros_message!(
    JointState,
    "sensor_msgs",
    "JointState",
    "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    deps: [Header]
);

/// sensor_msgs/Image
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: u8,
    pub step: u32,
    /// Raw bytes: serialized as one CDR sequence, not element by element.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}
crate::ros_message!(
    Image,
    "sensor_msgs",
    "Image",
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
    deps: [Header]
);

/// sensor_msgs/CompressedImage
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}
crate::ros_message!(
    CompressedImage,
    "sensor_msgs",
    "CompressedImage",
    "std_msgs/Header header\nstring format\nuint8[] data\n",
    deps: [Header]
);

/// sensor_msgs/RegionOfInterest
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}
crate::ros_message!(
    RegionOfInterest,
    "sensor_msgs",
    "RegionOfInterest",
    "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
);

/// sensor_msgs/CameraInfo (fixed-size arrays serialize without a length, as CDR arrays do)
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}
crate::ros_message!(
    CameraInfo,
    "sensor_msgs",
    "CameraInfo",
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nRegionOfInterest roi\n",
    deps: [Header, RegionOfInterest]
);
