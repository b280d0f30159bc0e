use serde::{Deserialize, Serialize};

use crate::geometry_msgs::TransformStamped;

/// tf2_msgs/TFMessage: what /tf and /tf_static carry.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}
crate::ros_message!(
    TFMessage,
    "tf2_msgs",
    "TFMessage",
    "geometry_msgs/TransformStamped[] transforms\n",
    deps: [TransformStamped]
);
