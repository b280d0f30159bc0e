//! rcl_interfaces: the messages and services of ROS 2 parameters (`ros2 param`, rclpy's parameter
//! client, rqt_reconfigure).

use serde::{Deserialize, Serialize};

use crate::{builtin_interfaces::Time, RosService};

/// rcl_interfaces/ParameterValue: `kind` says which one of the value fields holds the value.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterValue {
    /// One of the `ParameterValue::*` type constants.
    pub kind: u8,
    pub bool_value: bool,
    pub integer_value: i64,
    pub double_value: f64,
    pub string_value: String,
    #[serde(with = "serde_bytes")]
    pub byte_array_value: Vec<u8>,
    pub bool_array_value: Vec<bool>,
    pub integer_array_value: Vec<i64>,
    pub double_array_value: Vec<f64>,
    pub string_array_value: Vec<String>,
}
impl ParameterValue {
    /// rcl_interfaces/ParameterType's constants.
    pub const NOT_SET: u8 = 0;
    pub const BOOL: u8 = 1;
    pub const INTEGER: u8 = 2;
    pub const DOUBLE: u8 = 3;
    pub const STRING: u8 = 4;
    pub const BYTE_ARRAY: u8 = 5;
    pub const BOOL_ARRAY: u8 = 6;
    pub const INTEGER_ARRAY: u8 = 7;
    pub const DOUBLE_ARRAY: u8 = 8;
    pub const STRING_ARRAY: u8 = 9;
}
crate::ros_message!(
    ParameterValue,
    "rcl_interfaces",
    "ParameterValue",
    "uint8 type\nbool bool_value\nint64 integer_value\nfloat64 double_value\nstring string_value\nbyte[] byte_array_value\nbool[] bool_array_value\nint64[] integer_array_value\nfloat64[] double_array_value\nstring[] string_array_value\n"
);

/// rcl_interfaces/Parameter
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Parameter {
    pub name: String,
    pub value: ParameterValue,
}
crate::ros_message!(
    Parameter,
    "rcl_interfaces",
    "Parameter",
    "string name\nParameterValue value\n",
    deps: [ParameterValue]
);

/// rcl_interfaces/FloatingPointRange (inclusive; step 0 means any value).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FloatingPointRange {
    pub from_value: f64,
    pub to_value: f64,
    pub step: f64,
}
crate::ros_message!(
    FloatingPointRange,
    "rcl_interfaces",
    "FloatingPointRange",
    "float64 from_value\nfloat64 to_value\nfloat64 step\n"
);

/// rcl_interfaces/IntegerRange (inclusive; step 0 means any value).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct IntegerRange {
    pub from_value: i64,
    pub to_value: i64,
    pub step: u64,
}
crate::ros_message!(
    IntegerRange,
    "rcl_interfaces",
    "IntegerRange",
    "int64 from_value\nint64 to_value\nuint64 step\n"
);

/// rcl_interfaces/ParameterDescriptor
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterDescriptor {
    pub name: String,
    /// A `ParameterValue::*` type constant.
    pub kind: u8,
    pub description: String,
    pub additional_constraints: String,
    pub read_only: bool,
    pub dynamic_typing: bool,
    /// At most one.
    pub floating_point_range: Vec<FloatingPointRange>,
    /// At most one.
    pub integer_range: Vec<IntegerRange>,
}
crate::ros_message!(
    ParameterDescriptor,
    "rcl_interfaces",
    "ParameterDescriptor",
    "string name\nuint8 type\nstring description\nstring additional_constraints\nbool read_only false\nbool dynamic_typing false\nFloatingPointRange[<=1] floating_point_range\nIntegerRange[<=1] integer_range\n",
    deps: [FloatingPointRange, IntegerRange]
);

/// rcl_interfaces/SetParametersResult
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersResult {
    pub successful: bool,
    pub reason: String,
}
crate::ros_message!(
    SetParametersResult,
    "rcl_interfaces",
    "SetParametersResult",
    "bool successful\nstring reason\n"
);

/// rcl_interfaces/ListParametersResult
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ListParametersResult {
    pub names: Vec<String>,
    pub prefixes: Vec<String>,
}
crate::ros_message!(
    ListParametersResult,
    "rcl_interfaces",
    "ListParametersResult",
    "string[] names\nstring[] prefixes\n"
);

/// rcl_interfaces/ParameterEvent, published on /parameter_events when parameters change.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterEvent {
    pub stamp: Time,
    /// The node's fully qualified name.
    pub node: String,
    pub new_parameters: Vec<Parameter>,
    pub changed_parameters: Vec<Parameter>,
    pub deleted_parameters: Vec<Parameter>,
}
crate::ros_message!(
    ParameterEvent,
    "rcl_interfaces",
    "ParameterEvent",
    "builtin_interfaces/Time stamp\nstring node\nParameter[] new_parameters\nParameter[] changed_parameters\nParameter[] deleted_parameters\n",
    deps: [Time, Parameter]
);

/// rcl_interfaces/ListParameters request (`depth` 0: every level).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ListParametersRequest {
    pub prefixes: Vec<String>,
    pub depth: u64,
}
impl ros2_client::Message for ListParametersRequest {}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ListParametersResponse {
    pub result: ListParametersResult,
}
impl ros2_client::Message for ListParametersResponse {}

/// rcl_interfaces/ListParameters
pub struct ListParameters;
impl RosService for ListParameters {
    type Request = ListParametersRequest;
    type Response = ListParametersResponse;
    const PACKAGE: &'static str = "rcl_interfaces";
    const NAME: &'static str = "ListParameters";
    const DEFINITION: &'static str =
        "uint64 DEPTH_RECURSIVE=0\nstring[] prefixes\nuint64 depth\n---\nListParametersResult result\n";
}

/// A request naming parameters (GetParameters, GetParameterTypes, DescribeParameters).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterNamesRequest {
    pub names: Vec<String>,
}
impl ros2_client::Message for ParameterNamesRequest {}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetParametersResponse {
    pub values: Vec<ParameterValue>,
}
impl ros2_client::Message for GetParametersResponse {}

/// rcl_interfaces/GetParameters
pub struct GetParameters;
impl RosService for GetParameters {
    type Request = ParameterNamesRequest;
    type Response = GetParametersResponse;
    const PACKAGE: &'static str = "rcl_interfaces";
    const NAME: &'static str = "GetParameters";
    const DEFINITION: &'static str = "string[] names\n---\nParameterValue[] values\n";
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetParameterTypesResponse {
    pub types: Vec<u8>,
}
impl ros2_client::Message for GetParameterTypesResponse {}

/// rcl_interfaces/GetParameterTypes
pub struct GetParameterTypes;
impl RosService for GetParameterTypes {
    type Request = ParameterNamesRequest;
    type Response = GetParameterTypesResponse;
    const PACKAGE: &'static str = "rcl_interfaces";
    const NAME: &'static str = "GetParameterTypes";
    const DEFINITION: &'static str = "string[] names\n---\nuint8[] types\n";
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DescribeParametersResponse {
    pub descriptors: Vec<ParameterDescriptor>,
}
impl ros2_client::Message for DescribeParametersResponse {}

/// rcl_interfaces/DescribeParameters
pub struct DescribeParameters;
impl RosService for DescribeParameters {
    type Request = ParameterNamesRequest;
    type Response = DescribeParametersResponse;
    const PACKAGE: &'static str = "rcl_interfaces";
    const NAME: &'static str = "DescribeParameters";
    const DEFINITION: &'static str = "string[] names\n---\nParameterDescriptor[] descriptors\n";
}

/// A request carrying parameters to set (SetParameters, SetParametersAtomically).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersRequest {
    pub parameters: Vec<Parameter>,
}
impl ros2_client::Message for SetParametersRequest {}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersResponse {
    pub results: Vec<SetParametersResult>,
}
impl ros2_client::Message for SetParametersResponse {}

/// rcl_interfaces/SetParameters: each parameter set (or refused) on its own.
pub struct SetParameters;
impl RosService for SetParameters {
    type Request = SetParametersRequest;
    type Response = SetParametersResponse;
    const PACKAGE: &'static str = "rcl_interfaces";
    const NAME: &'static str = "SetParameters";
    const DEFINITION: &'static str = "Parameter[] parameters\n---\nSetParametersResult[] results\n";
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersAtomicallyResponse {
    pub result: SetParametersResult,
}
impl ros2_client::Message for SetParametersAtomicallyResponse {}

/// rcl_interfaces/SetParametersAtomically: all of them or none.
pub struct SetParametersAtomically;
impl RosService for SetParametersAtomically {
    type Request = SetParametersRequest;
    type Response = SetParametersAtomicallyResponse;
    const PACKAGE: &'static str = "rcl_interfaces";
    const NAME: &'static str = "SetParametersAtomically";
    const DEFINITION: &'static str = "Parameter[] parameters\n---\nSetParametersResult result\n";
}
