//! rcl's six parameter services for one node (`<node>/list_parameters`, get, set, set atomically,
//! describe, get types) and its /parameter_events, served on their own thread so a call is
//! answered whatever the node's loop is doing. Accepted changes go to the node through
//! [`ParameterServer::changes`]; the node applies them in its loop.
//!
//! Served here rather than by ros2-client's Spinner, which would also subscribe /clock with the
//! wrong type (see [`super::super::node`]).

use std::sync::mpsc::{channel, Receiver, Sender};

use futures::FutureExt;
use ros2_client::{Publisher, Server};
use so101_msgs::{
    builtin_interfaces::Time,
    rcl_interfaces::{
        DescribeParameters, DescribeParametersResponse, GetParameterTypes,
        GetParameterTypesResponse, GetParameters, GetParametersResponse, ListParameters,
        ListParametersResponse, Parameter, ParameterEvent, ParameterNamesRequest, SetParameters,
        SetParametersAtomically, SetParametersAtomicallyResponse, SetParametersRequest,
        SetParametersResponse,
    },
    RosService,
};

use super::store::{Change, Parameters, Value};
use crate::ros::{node::NodeError, qos, RosNode};

type ServerOf<S> = Server<<S as RosService>::Request, <S as RosService>::Response>;

struct Services {
    list: ServerOf<ListParameters>,
    get: ServerOf<GetParameters>,
    types: ServerOf<GetParameterTypes>,
    describe: ServerOf<DescribeParameters>,
    set: ServerOf<SetParameters>,
    set_atomically: ServerOf<SetParametersAtomically>,
    events: Publisher<ParameterEvent>,
}

/// The running services of one node. Dropping it stops them.
pub struct ParameterServer {
    stop: Option<smol::channel::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
    changes: Receiver<Change>,
}

impl ParameterServer {
    /// Serves `parameters` for `node` and announces them on /parameter_events.
    pub fn start(node: &mut RosNode, parameters: Parameters) -> Result<Self, NodeError> {
        let node_name = node.fully_qualified_name();
        let base_name = node.base_name().to_owned();
        let service = |name: &str| format!("{base_name}/{name}");
        let services = Services {
            list: node.server::<ListParameters>(&service("list_parameters"))?,
            get: node.server::<GetParameters>(&service("get_parameters"))?,
            types: node.server::<GetParameterTypes>(&service("get_parameter_types"))?,
            describe: node.server::<DescribeParameters>(&service("describe_parameters"))?,
            set: node.server::<SetParameters>(&service("set_parameters"))?,
            set_atomically: node
                .server::<SetParametersAtomically>(&service("set_parameters_atomically"))?,
            // rcl's /parameter_events is one topic for the whole graph, outside any namespace.
            events: node.global_publisher(PARAMETER_EVENTS, qos::reliable(1000))?,
        };
        let (stop, stopped) = smol::channel::bounded(1);
        let (changed, changes) = channel();
        let thread = std::thread::Builder::new()
            .name("parameters".into())
            .spawn(move || {
                let mut serving = Serving {
                    services,
                    parameters,
                    node_name,
                    changed,
                };
                serving.announce();
                smol::block_on(serving.run(stopped));
            })
            .map_err(|error| {
                NodeError::Other(format!("cannot start the parameter services: {error}"))
            })?;
        Ok(Self {
            stop: Some(stop),
            thread: Some(thread),
            changes,
        })
    }

    /// The changes accepted since the last call, in order.
    pub fn changes(&self) -> Vec<Change> {
        self.changes.try_iter().collect()
    }
}

impl Drop for ParameterServer {
    fn drop(&mut self) {
        self.stop.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The topic of every node's parameter changes.
pub const PARAMETER_EVENTS: &str = "/parameter_events";

struct Serving {
    services: Services,
    parameters: Parameters,
    node_name: String,
    changed: Sender<Change>,
}

impl Serving {
    async fn run(&mut self, stopped: smol::channel::Receiver<()>) {
        loop {
            let s = &self.services;
            futures::select_biased! {
                _ = stopped.recv().fuse() => return,
                request = s.list.async_receive_request().fuse() => {
                    if let Ok((id, request)) = request {
                        let result = self.parameters.list(&request.prefixes, request.depth);
                        respond(&self.services.list, id, ListParametersResponse { result });
                    }
                }
                request = s.get.async_receive_request().fuse() => {
                    if let Ok((id, ParameterNamesRequest { names })) = request {
                        let values = self.parameters.values(&names);
                        respond(&self.services.get, id, GetParametersResponse { values });
                    }
                }
                request = s.types.async_receive_request().fuse() => {
                    if let Ok((id, ParameterNamesRequest { names })) = request {
                        let types = self.parameters.types(&names);
                        respond(&self.services.types, id, GetParameterTypesResponse { types });
                    }
                }
                request = s.describe.async_receive_request().fuse() => {
                    if let Ok((id, ParameterNamesRequest { names })) = request {
                        // An undeclared name gets an empty answer, as from rclcpp.
                        let descriptors = self.parameters.describe(&names).unwrap_or_else(|reason| {
                            tracing::debug!("describe_parameters: {reason}");
                            Vec::new()
                        });
                        respond(&self.services.describe, id, DescribeParametersResponse { descriptors });
                    }
                }
                request = s.set.async_receive_request().fuse() => {
                    if let Ok((id, SetParametersRequest { parameters })) = request {
                        let (results, changes) = self.parameters.set_each(requested(&parameters));
                        log_refusals(results.iter().map(|result| &result.reason));
                        self.apply(changes);
                        respond(&self.services.set, id, SetParametersResponse { results });
                    }
                }
                request = s.set_atomically.async_receive_request().fuse() => {
                    if let Ok((id, SetParametersRequest { parameters })) = request {
                        let (result, changes) = self.parameters.set_all(requested(&parameters));
                        log_refusals(std::iter::once(&result.reason));
                        self.apply(changes);
                        respond(&self.services.set_atomically, id, SetParametersAtomicallyResponse { result });
                    }
                }
            }
        }
    }

    /// rcl announces a node's parameters as new when it declares them.
    fn announce(&self) {
        let new_parameters = self
            .parameters
            .declarations()
            .map(|declaration| parameter(declaration.name(), declaration.value()))
            .collect();
        self.publish(ParameterEvent {
            new_parameters,
            ..self.event()
        });
    }

    fn apply(&self, changes: Vec<Change>) {
        if changes.is_empty() {
            return;
        }
        let changed_parameters = changes
            .iter()
            .map(|change| parameter(&change.name, &change.value))
            .collect();
        for change in changes {
            tracing::info!(parameter = %change.name, value = %change.value, "parameter set");
            let _ = self.changed.send(change);
        }
        self.publish(ParameterEvent {
            changed_parameters,
            ..self.event()
        });
    }

    fn event(&self) -> ParameterEvent {
        ParameterEvent {
            stamp: Time::now(),
            node: self.node_name.clone(),
            ..ParameterEvent::default()
        }
    }

    fn publish(&self, event: ParameterEvent) {
        if let Err(error) = self.services.events.publish(event) {
            tracing::warn!(?error, "cannot publish on /parameter_events");
        }
    }
}

fn requested(parameters: &[Parameter]) -> Vec<(String, Result<Value, String>)> {
    parameters
        .iter()
        .map(|parameter| {
            (
                parameter.name.clone(),
                Value::from_message(&parameter.value),
            )
        })
        .collect()
}

fn parameter(name: &str, value: &Value) -> Parameter {
    Parameter {
        name: name.to_owned(),
        value: value.to_message(),
    }
}

fn log_refusals<'a>(reasons: impl Iterator<Item = &'a String>) {
    for reason in reasons.filter(|reason| !reason.is_empty()) {
        tracing::warn!("parameter refused: {reason}");
    }
}

fn respond<Req, Resp>(server: &Server<Req, Resp>, id: ros2_client::RmwRequestId, response: Resp)
where
    Req: ros2_client::Message + 'static,
    Resp: ros2_client::Message + 'static,
{
    if let Err(error) = server.send_response(id, response) {
        tracing::warn!(?error, "cannot answer a parameter service call");
    }
}
