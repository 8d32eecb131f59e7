//! An OPC UA server of a simulated plant (feature `opcua-server`): one variable per column,
//! written with its sample's source timestamp, for trying a live run and for the tests.
//!
//! It serves two endpoints: security `None`, and `Basic256Sha256` with `SignAndEncrypt` (its
//! certificate and key created in its PKI directory on first start). Being a simulation, it
//! accepts any client certificate; a plant's server does not.

use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;

use opcua::crypto::SecurityPolicy;
use opcua::types::{DataValue, DateTime, MessageSecurityMode, NodeId, StatusCode, Variant};
use opcua_server::address_space::Variable;
use opcua_server::diagnostics::NamespaceMetadata;
use opcua_server::node_manager::memory::{SimpleNodeManager, simple_node_manager};
use opcua_server::{ANONYMOUS_USER_TOKEN_ID, ServerBuilder, ServerHandle};
use streamcert_pipeline::CliError;

/// The namespace of the simulated plant's nodes.
pub const NAMESPACE_URI: &str = "urn:streamcert:simulated-plant:signals";

/// A running server of a simulated plant.
pub struct PlantServer {
    handle: ServerHandle,
    nodes: Arc<SimpleNodeManager>,
    ids: Vec<NodeId>,
    addr: SocketAddr,
    runtime: Option<tokio::runtime::Runtime>,
}

impl PlantServer {
    /// Serve the variables `columns` (named `NAME` in [`NAMESPACE_URI`], initially 0) at
    /// `addr` (port 0: a free one), with its certificate in `pki_dir`.
    ///
    /// # Errors
    /// The address cannot be bound; the server cannot be built.
    pub fn start(addr: SocketAddr, columns: &[String], pki_dir: &Path) -> Result<Self, CliError> {
        let io = |what: &str, e: String| CliError::io(what.to_string(), std::io::Error::other(e));
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("opcua-server")
            .enable_all()
            .build()
            .map_err(|e| CliError::io("starting the OPC UA server", e))?;
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind(addr))
            .map_err(|e| CliError::io(format!("binding {addr}"), e))?;
        let addr = listener.local_addr().map_err(|e| CliError::io("binding", e))?;
        // The server's parts spawn their tasks on this runtime as they are built.
        let _inside = runtime.enter();
        let builder = builder(addr, pki_dir);
        let (server, handle) = builder.build().map_err(|e| io("building the OPC UA server", e))?;
        let nodes = handle
            .node_managers()
            .get_of_type::<SimpleNodeManager>()
            .ok_or_else(|| io("building the OPC UA server", "no node manager".into()))?;
        let ns = nodes
            .namespaces()
            .iter()
            .find(|(_, uri)| uri.as_str() == NAMESPACE_URI)
            .map(|(i, _)| *i)
            .ok_or_else(|| io("building the OPC UA server", "no namespace".into()))?;
        let ids: Vec<NodeId> = columns.iter().map(|c| NodeId::new(ns, c.clone())).collect();
        {
            let mut space = nodes.address_space().write();
            let vars = ids
                .iter()
                .zip(columns)
                .map(|(id, c)| Variable::new(id, c.as_str(), c.as_str(), 0.0f64))
                .collect();
            space.add_variables(vars, &opcua::types::ObjectId::ObjectsFolder.into());
        }
        // No value until the first sample: a client that subscribes first is told so.
        let waiting =
            DataValue { status: Some(StatusCode::BadWaitingForInitialData), ..DataValue::null() };
        nodes
            .set_values(handle.subscriptions(), ids.iter().map(|id| (id, None, waiting.clone())))
            .map_err(|s| io("building the OPC UA server", s.to_string()))?;
        runtime.spawn(async move {
            if let Err(e) = server.run_with(listener).await {
                eprintln!("opcua server: {e}");
            }
        });
        drop(_inside);
        Ok(Self { handle, nodes, ids, addr, runtime: Some(runtime) })
    }

    /// The endpoint URL, `opc.tcp://IP:PORT/`.
    #[must_use]
    pub fn endpoint(&self) -> String {
        format!("opc.tcp://{}:{}/", self.addr.ip(), self.addr.port())
    }

    /// The columns' node ids, in text form (`ns=1;s=y_b`).
    #[must_use]
    pub fn node_ids(&self) -> Vec<String> {
        self.ids.iter().map(ToString::to_string).collect()
    }

    /// Whether a client monitors any of the columns' nodes (their value, by an enabled
    /// monitored item of its subscription). A client's items are created in one request, which
    /// the server takes whole: a run written from then on reaches it from its first sample.
    #[must_use]
    pub fn monitored(&self) -> bool {
        let subs = self.handle.subscriptions();
        let mut notifier = subs.data_notifier();
        self.ids.iter().any(|id| {
            notifier
                .notify_for(id, opcua::types::AttributeId::Value)
                .is_some_and(|batch| batch.entries().next().is_some())
        })
    }

    /// Write one sample: each column's value, stamped with source time `t` (seconds since the
    /// Unix epoch, to the nearest 100 ns).
    ///
    /// # Errors
    /// The server refused a value.
    pub fn publish(&self, t: f64, values: &[f64]) -> Result<(), CliError> {
        let stamp = DateTime::from(super::ticks(t));
        let now = DateTime::now();
        let data = values.iter().map(|&v| DataValue {
            value: Some(Variant::Double(v)),
            status: Some(StatusCode::Good),
            source_timestamp: Some(stamp),
            source_picoseconds: None,
            server_timestamp: Some(now),
            server_picoseconds: None,
        });
        self.write(data)
    }

    /// Write raw values, one per column (for tests of what a client refuses).
    ///
    /// # Errors
    /// The server refused a value.
    pub fn write(&self, values: impl Iterator<Item = DataValue>) -> Result<(), CliError> {
        let _inside = self.runtime.as_ref().map(tokio::runtime::Runtime::enter);
        let subs = self.handle.subscriptions();
        let items = self.ids.iter().zip(values).map(|(id, dv)| (id, None, dv));
        self.nodes.set_values(subs, items).map_err(|s| {
            CliError::io("writing to the OPC UA server", std::io::Error::other(s.to_string()))
        })
    }

    /// Stop serving: every client's connection is closed.
    pub fn stop(mut self) {
        self.handle.cancel();
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_timeout(std::time::Duration::from_secs(2));
        }
    }
}

/// The server's settings: two endpoints (None; Basic256Sha256 with SignAndEncrypt), any
/// client certificate trusted, and limits that let every written value through.
fn builder(addr: SocketAddr, pki_dir: &Path) -> ServerBuilder {
    let url = format!("opc.tcp://{}:{}/", addr.ip(), addr.port());
    let namespace = NamespaceMetadata { namespace_uri: NAMESPACE_URI.into(), ..Default::default() };
    let users = [ANONYMOUS_USER_TOKEN_ID];
    let mut builder = ServerBuilder::new()
        .application_name("streamcert simulated plant")
        .application_uri("urn:streamcert:simulated-plant")
        .product_uri("urn:streamcert:simulated-plant")
        .host(addr.ip().to_string())
        .port(addr.port())
        .discovery_urls(vec![url])
        .pki_dir(pki_dir)
        .create_sample_keypair(true)
        .trust_client_certs(true)
        .with_node_manager(simple_node_manager(namespace, "plant"))
        .add_endpoint("none", ("/", SecurityPolicy::None, MessageSecurityMode::None, &users[..]))
        .add_endpoint(
            "basic256sha256_sign_encrypt",
            ("/", SecurityPolicy::Basic256Sha256, MessageSecurityMode::SignAndEncrypt, &users[..]),
        );
    // Every value written reaches its subscribers, however close in time to the last.
    builder.limits_mut().subscriptions.min_sampling_interval_ms = 0.0;
    let limits = builder.limits_mut();
    limits.subscriptions.max_queued_notifications = 1_000_000;
    limits.subscriptions.min_publishing_interval_ms = 10.0;
    limits.subscriptions.max_monitored_item_queue_size = 1_000_000;
    limits.subscriptions.max_notifications_per_publish = 100_000;
    limits.max_message_size = 64 << 20;
    limits.max_chunk_count = 1024;
    limits.max_array_length = 1_000_000;
    builder
}

impl Drop for PlantServer {
    fn drop(&mut self) {
        self.handle.cancel();
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_background();
        }
    }
}
