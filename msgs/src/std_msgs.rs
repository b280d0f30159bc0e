use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// std_msgs/Header
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: std::string::String,
}
crate::ros_message!(Header, "std_msgs", "Header", "builtin_interfaces/Time stamp\nstring frame_id\n", deps: [Time]);

/// std_msgs/Bool
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Bool {
    pub data: bool,
}
crate::ros_message!(Bool, "std_msgs", "Bool", "bool data\n");

/// std_msgs/Float64
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Float64 {
    pub data: f64,
}
crate::ros_message!(Float64, "std_msgs", "Float64", "float64 data\n");

/// std_msgs/String
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct String {
    pub data: std::string::String,
}
crate::ros_message!(String, "std_msgs", "String", "string data\n");

/// std_msgs/MultiArrayDimension
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayDimension {
    pub label: std::string::String,
    pub size: u32,
    pub stride: u32,
}
crate::ros_message!(
    MultiArrayDimension,
    "std_msgs",
    "MultiArrayDimension",
    "string label\nuint32 size\nuint32 stride\n"
);

/// std_msgs/MultiArrayLayout
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayLayout {
    pub dim: Vec<MultiArrayDimension>,
    pub data_offset: u32,
}
crate::ros_message!(
    MultiArrayLayout,
    "std_msgs",
    "MultiArrayLayout",
    "MultiArrayDimension[] dim\nuint32 data_offset\n",
    deps: [MultiArrayDimension]
);

/// std_msgs/Float64MultiArray
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Float64MultiArray {
    pub layout: MultiArrayLayout,
    pub data: Vec<f64>,
}
crate::ros_message!(
    Float64MultiArray,
    "std_msgs",
    "Float64MultiArray",
    "MultiArrayLayout layout\nfloat64[] data\n",
    deps: [MultiArrayLayout]
);
