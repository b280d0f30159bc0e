use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// rosgraph_msgs/Clock: the simulation time, published on /clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}
crate::ros_message!(Clock, "rosgraph_msgs", "Clock", "builtin_interfaces/Time clock\n", deps: [Time]);
