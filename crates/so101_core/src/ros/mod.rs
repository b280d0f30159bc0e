//! ROS 2 plumbing shared by every node of the stack.

pub mod arm_controller;
pub mod clock;
pub mod command_inbox;
pub mod context;
pub mod crash;
pub mod logging;
pub mod names;
pub mod node;
pub mod parameters;
pub mod qos;
pub mod rate_limit;
pub mod shutdown;

pub use context::{create_context, ContextError, RosEnvironment};
pub use names::{NameError, Names};
pub use node::{NodeArgs, RosNode};
