//! Sim time for nodes that follow the simulation: the latest rosgraph_msgs/Clock from /clock.
//!
//! ros2-client's own sim-time support listens to /clock as builtin_interfaces/Time, which a standard
//! /clock publisher does not match, so the stack subscribes rosgraph_msgs/Clock itself.

use crate::contract::topics;
use std::sync::{
    atomic::{AtomicI64, Ordering},
    Arc,
};

use futures::StreamExt;
use so101_msgs::{builtin_interfaces::Time, rosgraph_msgs::Clock};

use super::{node::NodeError, qos, shutdown::Shutdown, RosNode};

/// Nanoseconds of the latest /clock message; `None` before the first one.
#[derive(Clone)]
pub struct SimClock {
    latest_nanos: Arc<AtomicI64>,
}

const NO_CLOCK_YET: i64 = i64::MIN;

impl SimClock {
    /// Subscribes /clock (in the node's namespace) and keeps the latest time, until shutdown.
    pub fn subscribe(node: &mut RosNode, shutdown: Shutdown) -> Result<Self, NodeError> {
        let subscription = node.subscription::<Clock>(topics::CLOCK, qos::default_topic())?;
        let clock = Self {
            latest_nanos: Arc::new(AtomicI64::new(NO_CLOCK_YET)),
        };
        let latest = Arc::clone(&clock.latest_nanos);
        std::thread::Builder::new()
            .name("sim-clock".into())
            .spawn(move || {
                smol::block_on(async {
                    let stream = subscription.async_stream();
                    futures::pin_mut!(stream);
                    loop {
                        let stop = async {
                            shutdown.wait().await;
                            None
                        };
                        match smol::future::or(stream.next(), stop).await {
                            Some(Ok((clock, _))) => {
                                latest.store(clock.clock.to_nanos(), Ordering::Release)
                            }
                            Some(Err(error)) => tracing::warn!(%error, "bad /clock message"),
                            None => break,
                        }
                    }
                })
            })
            .map_err(|error| {
                NodeError::Other(format!("cannot start the /clock thread: {error}"))
            })?;
        Ok(clock)
    }

    pub fn now(&self) -> Option<Time> {
        match self.latest_nanos.load(Ordering::Acquire) {
            NO_CLOCK_YET => None,
            nanos => Some(Time::from_nanos(nanos)),
        }
    }
}
