//! A ROS 2 node with the stack's conventions: context from the environment, names under the
//! namespace, rosout mirroring.
//!
//! No ros2-client Spinner runs: it always subscribes /clock as builtin_interfaces/Time, which puts a
//! second, wrong type on /clock in every peer's graph (rclpy then lists /clock with two types) and
//! never matches a standard rosgraph_msgs/Clock publisher anyway. The parameter services come from
//! [`super::parameters`], node discovery from the context's ros_discovery_info, and sim time from
//! [`super::clock::SimClock`].

use ros2_client::{
    Context, Name, Node, NodeOptions, Publisher, QosProfile, Server, ServiceMapping, Subscription,
};
use serde::de::DeserializeOwned;
use so101_msgs::{RosMessage, RosService};

use super::{
    context::ContextError, create_context, logging, names::NameError, qos, Names, RosEnvironment,
};

/// Command-line options every node shares.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct NodeArgs {
    /// Namespace for every topic and service of this node (e.g. `left` gives /left/joint_states),
    /// so two arms can share one ROS graph.
    #[arg(long)]
    pub namespace: Option<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error(transparent)]
    Context(#[from] ContextError),
    #[error(transparent)]
    Name(#[from] NameError),
    #[error("cannot create {what}: {reason}")]
    Create { what: String, reason: String },
    #[error("{0}")]
    Other(String),
}

/// A started node. Dropping it leaves the graph.
pub struct RosNode {
    node: Node,
    base_name: String,
    names: Names,
    // Kept so the participant outlives the node.
    context: Context,
}

impl RosNode {
    /// Creates the node `base_name` in the namespace of `args` .
    pub fn start(base_name: &str, args: &NodeArgs) -> Result<Self, NodeError> {
        let environment = RosEnvironment::from_env()?;
        let names = Names::new(args.namespace.as_deref())?;
        let context = create_context(&environment)?;
        let node = context
            .new_node(
                names.node_name(base_name)?,
                NodeOptions::new()
                    .enable_rosout(true)
                    .start_parameter_services(false),
            )
            .map_err(|error| NodeError::Create {
                what: format!("node {base_name}"),
                reason: format!("{error:?}"),
            })?;
        logging::attach_rosout(node.logging_handle());
        tracing::info!(
            node = %names.resolve(base_name),
            domain_id = environment.domain_id,
            localhost_only = environment.localhost_only,
            "node started"
        );
        Ok(Self {
            node,
            base_name: base_name.to_owned(),
            names,
            context,
        })
    }

    /// The node's name without its namespace (e.g. `so101_sim_node`).
    pub fn base_name(&self) -> &str {
        &self.base_name
    }

    /// The node's name with its namespace (e.g. `/left/so101_sim_node`), as the graph shows it.
    pub fn fully_qualified_name(&self) -> String {
        self.names.resolve(&self.base_name)
    }

    pub fn names(&self) -> &Names {
        &self.names
    }

    pub fn node(&self) -> &Node {
        &self.node
    }

    /// The ros2-client node, for entities the helpers here do not make (action servers).
    pub fn node_mut(&mut self) -> &mut Node {
        &mut self.node
    }

    /// The ROS context (its DDS participant), for nodes that need DDS directly (raw readers).
    pub fn context(&self) -> &Context {
        &self.context
    }

    /// A publisher of `T` on `relative` (resolved in the namespace).
    pub fn publisher<T: RosMessage>(
        &mut self,
        relative: &str,
        qos: QosProfile,
    ) -> Result<Publisher<T>, NodeError> {
        let name = self.names.name(relative)?;
        self.publisher_on::<T>(&name, relative, qos)
    }

    /// A publisher of `T` on the absolute name `absolute`, outside the node's namespace (rcl's
    /// graph-wide topics such as /parameter_events).
    pub fn global_publisher<T: RosMessage>(
        &mut self,
        absolute: &str,
        qos: QosProfile,
    ) -> Result<Publisher<T>, NodeError> {
        let name = Names::new(None)?.name(absolute)?;
        self.publisher_on::<T>(&name, absolute, qos)
    }

    fn publisher_on<T: RosMessage>(
        &mut self,
        name: &Name,
        shown: &str,
        qos: QosProfile,
    ) -> Result<Publisher<T>, NodeError> {
        let topic = self.topic::<T>(name, shown, &qos)?;
        self.node
            .create_publisher(&topic, Some(qos))
            .map_err(|error| NodeError::Create {
                what: format!("publisher {shown}"),
                reason: format!("{error:?}"),
            })
    }

    /// A subscription of `T` on `relative` (resolved in the namespace).
    pub fn subscription<T: RosMessage + DeserializeOwned + 'static>(
        &mut self,
        relative: &str,
        qos: QosProfile,
    ) -> Result<Subscription<T>, NodeError> {
        let name = self.names.name(relative)?;
        let topic = self.topic::<T>(&name, relative, &qos)?;
        self.node
            .create_subscription(&topic, Some(qos))
            .map_err(|error| NodeError::Create {
                what: format!("subscription {relative}"),
                reason: format!("{error:?}"),
            })
    }

    /// A server of service `S` on `relative`, with rclpy's service QoS and the mapping rclpy uses.
    pub fn server<S: RosService>(
        &mut self,
        relative: &str,
    ) -> Result<Server<S::Request, S::Response>, NodeError>
    where
        S::Request: Clone + 'static,
        S::Response: 'static,
    {
        let name = self.names.name(relative)?;
        self.node
            .create_server::<S::Request, S::Response>(
                ServiceMapping::Enhanced,
                &name,
                &S::service_type_name(),
                qos::service(),
                qos::service(),
            )
            .map_err(|error| NodeError::Create {
                what: format!("service {relative}"),
                reason: format!("{error:?}"),
            })
    }

    /// A client of service `S` on `relative`, with rclpy's service QoS and mapping.
    pub fn client<S: RosService>(
        &mut self,
        relative: &str,
    ) -> Result<ros2_client::Client<S::Request, S::Response>, NodeError>
    where
        S::Request: Clone + 'static,
        S::Response: 'static,
    {
        let name = self.names.name(relative)?;
        self.node
            .create_client::<S::Request, S::Response>(
                ServiceMapping::Enhanced,
                &name,
                &S::service_type_name(),
                qos::service(),
                qos::service(),
            )
            .map_err(|error| NodeError::Create {
                what: format!("client of {relative}"),
                reason: format!("{error:?}"),
            })
    }

    fn topic<T: RosMessage>(
        &self,
        name: &Name,
        shown: &str,
        qos: &QosProfile,
    ) -> Result<ros2_client::dds::rustdds::Topic, NodeError> {
        self.node
            .create_topic(name, T::INFO.message_type_name(), qos)
            .map_err(|error| NodeError::Create {
                what: format!("topic {shown}"),
                reason: format!("{error:?}"),
            })
    }
}

/// Starts a node's publishing thread: publishing on its own thread keeps a slow DDS write from
/// delaying a control loop.
pub fn spawn_publisher_thread(
    work: impl FnOnce() + Send + 'static,
) -> Result<std::thread::JoinHandle<()>, NodeError> {
    std::thread::Builder::new()
        .name("publisher".into())
        .spawn(work)
        .map_err(|error| NodeError::Other(format!("cannot start the publisher thread: {error}")))
}
