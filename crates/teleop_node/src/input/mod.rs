//! Input sources behind one interface: each control period the node asks its source for a
//! [`Reading`]: a velocity request, or absolute joint targets, plus the controls given since.

pub mod expert;
pub mod gamepad;
pub mod keyboard;
pub mod leader;
pub mod scripted;

use so101_core::robot::JointPositions;

use crate::{controls::Control, motion::Jog};

/// What a source says for one control period.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    pub request: Request,
    pub controls: Vec<Control>,
}

/// How the arm should move this period.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// A velocity request in the node's current mode.
    Jog(Jog),
    /// Absolute joint targets (leader arm, expert).
    Targets(JointPositions),
    /// The device is gone (unplugged, leader silent, terminal closed): hold where the arm is.
    Lost,
}

impl Reading {
    pub fn still() -> Self {
        Self {
            request: Request::Jog(Jog::STILL),
            controls: Vec::new(),
        }
    }

    pub fn lost() -> Self {
        Self {
            request: Request::Lost,
            controls: Vec::new(),
        }
    }
}

/// What every source knows of the world when it is asked.
#[derive(Debug, Clone, Copy)]
pub struct Tick {
    /// Seconds on the node's clock (sim time with --sim-time, else since the node started).
    pub now: f64,
    /// Whether the node is in Cartesian mode (sources map axes differently).
    pub cartesian: bool,
    pub scene: Scene,
}

/// What the node has seen on the stack's topics.
#[derive(Debug, Clone, Copy, Default)]
pub struct Scene {
    /// Latest /cube/pose (world frame: position, orientation w x y z) and how many arrived so far.
    pub cube: Option<([f64; 3], [f64; 4])>,
    pub cube_messages: u64,
    /// Latest /task/success.
    pub task_success: bool,
    /// The node's current joint targets (`None` until the arm's position is known).
    pub targets: Option<JointPositions>,
    /// The arm's latest measured positions (/joint_states).
    pub measured: Option<JointPositions>,
    /// /sim/reset calls that failed so far.
    pub reset_failures: u64,
}

/// A source of operator input.
pub trait Source {
    fn read(&mut self, tick: &Tick) -> Reading;

    /// A summary to write at exit (the expert's episode results).
    fn report(&self) -> Option<serde_json::Value> {
        None
    }
}
