use serde::{Deserialize, Serialize};

use crate::std_msgs::Header;

/// diagnostic_msgs/KeyValue
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}
crate::ros_message!(
    KeyValue,
    "diagnostic_msgs",
    "KeyValue",
    "string key\nstring value\n"
);

/// diagnostic_msgs/DiagnosticStatus
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// One of [`DiagnosticStatus::OK`], `WARN`, `ERROR`, `STALE`.
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}
impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
    pub const STALE: u8 = 3;
}
crate::ros_message!(
    DiagnosticStatus,
    "diagnostic_msgs",
    "DiagnosticStatus",
    "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n",
    deps: [KeyValue]
);

/// diagnostic_msgs/DiagnosticArray
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}
crate::ros_message!(
    DiagnosticArray,
    "diagnostic_msgs",
    "DiagnosticArray",
    "std_msgs/Header header\nDiagnosticStatus[] status\n",
    deps: [Header, DiagnosticStatus]
);
