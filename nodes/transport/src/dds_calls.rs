//! Services a node answers from its own loop (`~/load_calibration`, `~/save_calibration`,
//! the lifecycle's): a task on the node's DDS runtime receives each request (in either ROS 2
//! request mapping, [`crate::dds_rpc`], so that `ros2 service call` over rmw_fastrtps and
//! rmw_cyclonedds both get their reply) and hands it to the node as a [`Call`]; the node
//! answers when its loop comes by, and the task sends the reply. The node's loop never waits
//! for DDS.

use std::sync::mpsc;
use std::sync::Arc;

use futures::stream::FuturesUnordered;
use futures::{FutureExt, StreamExt};
use ros2_client::{Name, QosProfile, ServiceMapping, ServiceTypeName};

use rpkm_msgs::RosMessage;

use crate::dds::{DdsNode, Wire};
use crate::dds_rpc::{reply_timer, RpcServer, RpcTypes};
use crate::error::TransportError;

/// A request a node received, and the way to answer it.
pub struct Call<Q, R> {
    /// The request.
    pub request: Q,
    reply: futures::channel::oneshot::Sender<R>,
}

impl<Q, R> Call<Q, R> {
    /// Sends `response` to the caller (a caller that went away is not an error).
    pub fn answer(self, response: R) {
        let _ = self.reply.send(response);
    }
}

/// One running service of a node: `~/<service>` of type `<package>/srv/<type>`.
pub struct CallServer<Q, R> {
    calls: mpsc::Receiver<Call<Q, R>>,
    stop: Option<futures::channel::oneshot::Sender<()>>,
    task: Option<tokio::task::JoinHandle<()>>,
    name: String,
}

impl<Q, R> std::fmt::Debug for CallServer<Q, R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CallServer")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl<Q, R> CallServer<Q, R> {
    /// The next request waiting, if any (one channel poll when there is none).
    pub fn try_next(&self) -> Option<Call<Q, R>> {
        self.calls.try_recv().ok()
    }

    /// The service's name (`/rpkm/tcp_estimator/load_calibration`).
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl<Q, R> Drop for CallServer<Q, R> {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(task) = self.task.take() {
            let _ = futures::executor::block_on(task);
        }
    }
}

/// What a service's type is named by: `rpkm_msgs`, `LoadCalibration` for
/// `rpkm_msgs/srv/LoadCalibration`.
#[derive(Debug, Clone, Copy)]
pub struct ServiceType {
    pub package: &'static str,
    pub name: &'static str,
}

impl DdsNode {
    /// Answers `~/<service>` (relative to this node: `/rpkm/tcp_estimator/<service>`) of
    /// type `kind`, for clients of either request mapping ([`crate::dds_rpc`]); the requests
    /// come out of [`CallServer::try_next`].
    pub fn serve_calls<Q, R>(
        self: &Arc<Self>,
        service: &str,
        kind: ServiceType,
    ) -> Result<CallServer<Q, R>, TransportError>
    where
        Q: RosMessage,
        R: RosMessage,
    {
        let server = self
            .rpc_server::<Q, R>(service, &RpcTypes::new(kind.package, "srv", kind.name))
            .map_err(|reason| TransportError::CreatePort {
                topic: format!("~/{service}"),
                backend: "dds",
                port: "server",
                reason,
            })?;
        let name = server.name().to_owned();
        let (tx, rx) = mpsc::channel();
        let (stop_tx, stop_rx) = futures::channel::oneshot::channel();
        let task = self.runtime().spawn(serve(server, tx, stop_rx));
        Ok(CallServer {
            calls: rx,
            stop: Some(stop_tx),
            task: Some(task),
            name,
        })
    }
}

async fn serve<Q: RosMessage, R: RosMessage>(
    server: RpcServer<Q, R>,
    calls: mpsc::Sender<Call<Q, R>>,
    stop: futures::channel::oneshot::Receiver<()>,
) {
    let mut stop = stop.fuse();
    let requests = server.stream().fuse();
    futures::pin_mut!(requests);
    let matches = server.matches().fuse();
    futures::pin_mut!(matches);
    let mut pending = FuturesUnordered::new();
    loop {
        let mut flush = reply_timer(server.waiting());
        futures::select! {
            _ = stop => break,
            (caller, request) = requests.select_next_some() => {
                let (reply, answer) = futures::channel::oneshot::channel();
                if calls.send(Call { request, reply }).is_err() {
                    break;
                }
                pending.push(answer.map(move |r| (caller, r)));
            },
            (caller, answer) = pending.select_next_some() => match answer {
                Ok(response) => server.reply(caller, &response),
                Err(_) => log::warn!(
                    "service {}: the node dropped a request unanswered", server.name()
                ),
            },
            () = matches.select_next_some() => {},
            () = flush => server.flush(),
        }
    }
}

/// A client of one service of another node (`rpkm launch` bringing its managed nodes up).
pub struct CallClient<Q: RosMessage, R: RosMessage> {
    client: ros2_client::Client<Wire<Q>, Wire<R>>,
    name: String,
}

impl<Q: RosMessage, R: RosMessage> std::fmt::Debug for CallClient<Q, R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CallClient")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl<Q: RosMessage, R: RosMessage> CallClient<Q, R> {
    /// Sends `request` once and waits up to `timeout` for its reply; `None` when none came
    /// (the service not matched yet, or the reply lost).
    pub async fn call_once(&self, request: Q, timeout: std::time::Duration) -> Option<R> {
        let id = self.client.async_send_request(Wire(request)).await.ok()?;
        match tokio::time::timeout(timeout, self.client.async_receive_response(id)).await {
            Ok(Ok(Wire(response))) => Some(response),
            _ => None,
        }
    }

    /// The service's name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl DdsNode {
    /// A client of the service `service` (absolute: `/rpkm/tcp_estimator/change_state`) of
    /// type `kind`.
    pub fn client<Q: RosMessage, R: RosMessage>(
        self: &Arc<Self>,
        service: &str,
        kind: ServiceType,
    ) -> Result<CallClient<Q, R>, TransportError> {
        let err = |reason: String| TransportError::CreatePort {
            topic: service.to_owned(),
            backend: "dds",
            port: "client",
            reason,
        };
        let name = Name::parse(service).map_err(|e| err(format!("{e:?}")))?;
        let qos = QosProfile::publisher_default()
            .history(ros2_client::qos::History::KeepLast { depth: 10 });
        let client = self
            .node
            .lock()
            .map_err(|_| err("node mutex poisoned".into()))?
            .create_client::<Wire<Q>, Wire<R>>(
                ServiceMapping::Cyclone,
                &name,
                &ServiceTypeName::new(kind.package, kind.name),
                qos.clone(),
                qos,
            )
            .map_err(|e| err(e.to_string()))?;
        Ok(CallClient {
            client,
            name: service.to_owned(),
        })
    }
}
