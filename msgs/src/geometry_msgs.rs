use serde::{Deserialize, Serialize};

use crate::std_msgs::Header;

/// geometry_msgs/Point
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
crate::ros_message!(
    Point,
    "geometry_msgs",
    "Point",
    "float64 x\nfloat64 y\nfloat64 z\n"
);

/// geometry_msgs/Quaternion (x, y, z, w order on the wire)
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}
impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}
crate::ros_message!(
    Quaternion,
    "geometry_msgs",
    "Quaternion",
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
);

/// geometry_msgs/Pose
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}
crate::ros_message!(
    Pose,
    "geometry_msgs",
    "Pose",
    "Point position\nQuaternion orientation\n",
    deps: [Point, Quaternion]
);

/// geometry_msgs/PoseStamped
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}
crate::ros_message!(
    PoseStamped,
    "geometry_msgs",
    "PoseStamped",
    "std_msgs/Header header\nPose pose\n",
    deps: [Header, Pose]
);

/// geometry_msgs/Vector3
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
crate::ros_message!(
    Vector3,
    "geometry_msgs",
    "Vector3",
    "float64 x\nfloat64 y\nfloat64 z\n"
);

/// geometry_msgs/Twist
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}
crate::ros_message!(
    Twist,
    "geometry_msgs",
    "Twist",
    "Vector3 linear\nVector3 angular\n",
    deps: [Vector3]
);

/// geometry_msgs/Transform
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}
crate::ros_message!(
    Transform,
    "geometry_msgs",
    "Transform",
    "Vector3 translation\nQuaternion rotation\n",
    deps: [Vector3, Quaternion]
);

/// geometry_msgs/TransformStamped: `transform` is the pose of `child_frame_id` in
/// `header.frame_id`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}
crate::ros_message!(
    TransformStamped,
    "geometry_msgs",
    "TransformStamped",
    "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    deps: [Header, Transform]
);
