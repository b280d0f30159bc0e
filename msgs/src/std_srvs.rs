use serde::{Deserialize, Serialize};

use crate::RosService;

/// std_srvs/Trigger request. ROS empty messages carry one dummy byte on the wire
/// (`structure_needs_at_least_one_member`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TriggerRequest {
    pub structure_needs_at_least_one_member: u8,
}
impl ros2_client::Message for TriggerRequest {}

/// std_srvs/Trigger response (also the response of SetBool).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TriggerResponse {
    pub success: bool,
    pub message: String,
}
impl ros2_client::Message for TriggerResponse {}

/// std_srvs/Trigger
pub struct Trigger;
impl RosService for Trigger {
    type Request = TriggerRequest;
    type Response = TriggerResponse;
    const PACKAGE: &'static str = "std_srvs";
    const NAME: &'static str = "Trigger";
    const DEFINITION: &'static str = "---\nbool success\nstring message\n";
}

/// std_srvs/SetBool request
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetBoolRequest {
    pub data: bool,
}
impl ros2_client::Message for SetBoolRequest {}

/// std_srvs/SetBool
pub struct SetBool;
impl RosService for SetBool {
    type Request = SetBoolRequest;
    type Response = TriggerResponse;
    const PACKAGE: &'static str = "std_srvs";
    const NAME: &'static str = "SetBool";
    const DEFINITION: &'static str = "bool data\n---\nbool success\nstring message\n";
}
