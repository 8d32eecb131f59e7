//! The client's thread: connect (retrying), subscribe, and hand every value and connection
//! event over to the source.

use std::str::FromStr;
use std::sync::Arc;
use std::sync::mpsc::Sender;
use std::time::Duration;

use futures_util::StreamExt;
use opcua::client::{
    ClientBuilder, IdentityToken, MonitoredItemMap, OnSubscriptionNotificationCore, Session,
    SessionConnectMode, SessionPollResult,
};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    AttributeId, DataChangeFilter, DataChangeNotification, DataChangeTrigger, EndpointDescription,
    ExtensionObject, MessageSecurityMode, MonitoredItemCreateRequest, MonitoringMode,
    MonitoringParameters, NodeId, NotificationMessage, ReadValueId, TimestampsToReturn,
};
use streamcert_pipeline::CliError;
use tokio::sync::oneshot;

use super::{Event, Signals};
use crate::config::{OpcUaConfig, SecurityMode};

/// The application URI the client presents (its certificate must carry it).
pub const APPLICATION_URI: &str = "urn:streamcert";

/// Every node's id, parsed.
///
/// # Errors
/// A node id that does not parse.
pub(super) fn node_ids(cfg: &OpcUaConfig) -> Result<Vec<NodeId>, CliError> {
    cfg.nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            NodeId::from_str(&n.id).map_err(|_| CliError::Config {
                path: "[source]".into(),
                message: format!("source.node[{i}]: `{}` is not a node id (ns=1;s=NAME)", n.id),
            })
        })
        .collect()
}

/// The thread's body: a single-threaded runtime until the source stops it.
pub(super) fn drive(
    cfg: &OpcUaConfig,
    ids: Vec<NodeId>,
    tx: &Sender<Event>,
    stop: oneshot::Receiver<()>,
) {
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            let _ = tx.send(Event::Failed(format!("cannot start the client's runtime: {e}")));
            return;
        }
    };
    runtime.block_on(async move {
        tokio::select! {
            () = run(cfg, ids, tx) => {}
            _ = stop => {}
        }
    });
}

/// Connect (retrying with a doubling wait), watch the session, subscribe, then wait.
async fn run(cfg: &OpcUaConfig, ids: Vec<NodeId>, tx: &Sender<Event>) {
    let mut wait = cfg.backoff.0;
    let (session, event_loop) = loop {
        match connect(cfg).await {
            Ok(pair) => break pair,
            Err(Fatal(why)) => {
                let _ = tx.send(Event::Failed(why));
                return;
            }
            Err(Retry(why)) => {
                let _ = tx.send(Event::Lost(why));
                tokio::time::sleep(wait).await;
                wait = (wait * 2).min(cfg.backoff.1);
            }
        }
    };
    let _closer = session.close_on_drop();
    let watcher = tx.clone();
    let (again, mut new_session) = tokio::sync::mpsc::unbounded_channel::<()>();
    let watch = async move {
        let mut events = std::pin::pin!(event_loop.enter());
        while let Some(event) = events.next().await {
            let sent = match event {
                Ok(SessionPollResult::Reconnected(mode)) => {
                    // A new session has no subscription: it is made again.
                    if matches!(mode, SessionConnectMode::NewSession(_)) {
                        let _ = again.send(());
                    }
                    watcher.send(Event::Connected)
                }
                Ok(SessionPollResult::ConnectionLost(status)) => {
                    watcher.send(Event::Lost(format!("connection lost ({status})")))
                }
                Ok(SessionPollResult::ReconnectFailed(status)) if refused(status) => {
                    watcher.send(Event::Failed(format!(
                        "the server refused the connection ({status}): check security_policy, \
                         security_mode, the credentials, and that the server's certificate is \
                         in {}/trusted (its rejected/ holds what was refused)",
                        cfg.pki_dir.display()
                    )))
                }
                Ok(SessionPollResult::ReconnectFailed(status)) => {
                    watcher.send(Event::Lost(format!("reconnection failed ({status})")))
                }
                Ok(_) => Ok(()),
                Err(status) => watcher.send(Event::Failed(format!("the session ended ({status})"))),
            };
            if sent.is_err() {
                return;
            }
        }
    };
    // Subscribe on every new session (the first, and one after an outage whose session the
    // server did not keep); the session lives until the source stops the thread.
    let subscribe = async {
        while new_session.recv().await.is_some() {
            if !session.wait_for_connection().await {
                continue;
            }
            match subscribe(&session, cfg, &ids, tx.clone()).await {
                Ok(()) => {
                    let _ = tx.send(Event::Subscribed);
                }
                Err(why) => {
                    let _ = tx.send(Event::Failed(why));
                }
            }
        }
    };
    tokio::join!(watch, subscribe);
}

/// A refusal that retrying does not mend: a certificate, a security setting, an identity.
fn refused(status: opcua::types::StatusCode) -> bool {
    let name = status.to_string();
    ["BadCertificate", "BadSecurity", "BadIdentity", "BadUserAccessDenied"]
        .iter()
        .any(|k| name.contains(k))
}

/// Why a connection was not made: worth retrying (the server is away) or not (a setting).
enum Failure {
    Retry(String),
    Fatal(String),
}
use Failure::{Fatal, Retry};

/// One connection attempt.
async fn connect(
    cfg: &OpcUaConfig,
) -> Result<
    (Arc<Session>, opcua::client::SessionEventLoop<opcua::client::transport::TcpConnector>),
    Failure,
> {
    let mut builder = ClientBuilder::new()
        .application_name("streamcert")
        .application_uri(APPLICATION_URI)
        .product_uri(APPLICATION_URI)
        .pki_dir(cfg.pki_dir.clone())
        .create_sample_keypair(false)
        .trust_server_certs(cfg.trust_server_certs)
        .session_retry_limit(-1)
        .recreate_subscriptions(false)
        .session_retry_initial(cfg.backoff.0)
        .session_retry_max(cfg.backoff.1)
        .session_timeout(60_000)
        .keep_alive_interval(Duration::from_secs(1))
        .max_message_size(64 << 20)
        .max_chunk_count(1024)
        .max_array_length(1_000_000);
    if let Some((cert, key)) = &cfg.certificate {
        builder = builder.certificate_path(absolute(cert)).private_key_path(absolute(key));
    }
    let mut client = builder.client().map_err(|e| Fatal(e.join("; ")))?;
    let policy = policy(&cfg.security_policy)
        .ok_or_else(|| Fatal(format!("unknown security policy {}", cfg.security_policy)))?;
    let mode = match cfg.security_mode {
        SecurityMode::None => MessageSecurityMode::None,
        SecurityMode::Sign => MessageSecurityMode::Sign,
        SecurityMode::SignAndEncrypt => MessageSecurityMode::SignAndEncrypt,
    };
    let token = match &cfg.credentials {
        None => IdentityToken::Anonymous,
        Some((user, password)) => IdentityToken::UserName(user.clone(), password.0.clone().into()),
    };
    let endpoint: EndpointDescription = (cfg.endpoint.as_str(), policy.to_str(), mode).into();
    client.connect_to_matching_endpoint(endpoint, token).await.map_err(|e| {
        let text = e.to_string();
        // A server that is not there (yet, or any more) is retried; a refused certificate,
        // an endpoint without this policy, or refused credentials are settings to fix.
        let fatal = ["Certificate", "Security", "Identity", "UserAccess", "NotFound"];
        if fatal.iter().any(|k| text.contains(k)) {
            Fatal(format!(
                "{text} (the server's certificate must be in {}/trusted)",
                cfg.pki_dir.display()
            ))
        } else {
            Retry(format!("cannot connect: {text}"))
        }
    })
}

/// A security policy by its OPC UA name (`Aes128_Sha256_RsaOaep`, as in the policy's URI;
/// async-opcua spells the two AES policies with hyphens).
fn policy(name: &str) -> Option<SecurityPolicy> {
    let p = SecurityPolicy::from_str(&name.replace('_', "-")).ok()?;
    (p != SecurityPolicy::Unknown).then_some(p)
}

/// A path made absolute against the working directory (the client reads certificates
/// relative to its PKI directory otherwise).
fn absolute(p: &std::path::Path) -> std::path::PathBuf {
    std::env::current_dir().map(|d| d.join(p)).unwrap_or_else(|_| p.to_path_buf())
}

/// A subscription's notifications, a publication at a time, handed on in order of source
/// time. A server lists a publication's values node by node, so without the sort one node's
/// values would trail another's by a whole publication (longer when the client falls behind
/// and the server batches intervals); sorted, the alignment's reorder window need only span
/// the skew between publications. The sort is stable: one node's values keep their order,
/// and a value without a source timestamp (refused as bad) goes first.
struct InTimeOrder {
    signals: Signals,
    tx: Sender<Event>,
}

impl OnSubscriptionNotificationCore for InTimeOrder {
    fn on_subscription_notification(
        &mut self,
        notification: NotificationMessage,
        items: MonitoredItemMap<'_>,
    ) {
        let mut values = Vec::new();
        for object in notification.notification_data.into_iter().flatten() {
            let Some(change) = object.into_inner_as::<DataChangeNotification>() else { continue };
            for n in change.monitored_items.into_iter().flatten() {
                let Some(item) = items.get(n.client_handle) else { continue };
                if let Some(&i) = self.signals.get(&item.item_to_monitor().node_id) {
                    values.push((i, n.value));
                }
            }
        }
        values.sort_by_key(|(_, dv)| dv.source_timestamp.map(|t| t.checked_ticks()));
        for (i, dv) in values {
            let _ = self.tx.send(Event::Value(i, dv));
        }
    }
}

/// One subscription, one monitored item per node.
async fn subscribe(
    session: &Session,
    cfg: &OpcUaConfig,
    ids: &[NodeId],
    tx: Sender<Event>,
) -> Result<(), String> {
    let signals: Signals = ids.iter().cloned().enumerate().map(|(i, id)| (id, i)).collect();
    let callback = InTimeOrder { signals, tx };
    let interval = cfg.publishing_interval.max(Duration::from_millis(1));
    let sub = session
        .create_subscription(interval, 600, 20, 0, 0, true, callback)
        .await
        .map_err(|e| format!("cannot create the subscription: {e}"))?;
    // Every change of status, value or source timestamp is reported.
    let filter = ExtensionObject::from_message(DataChangeFilter {
        trigger: DataChangeTrigger::StatusValueTimestamp,
        deadband_type: 0,
        deadband_value: 0.0,
    });
    let items: Vec<MonitoredItemCreateRequest> = ids
        .iter()
        .map(|id| MonitoredItemCreateRequest {
            item_to_monitor: ReadValueId {
                node_id: id.clone(),
                attribute_id: AttributeId::Value as u32,
                ..Default::default()
            },
            monitoring_mode: MonitoringMode::Reporting,
            requested_parameters: MonitoringParameters {
                sampling_interval: cfg.sampling_interval.as_secs_f64() * 1000.0,
                queue_size: cfg.queue_size,
                discard_oldest: true,
                filter: filter.clone(),
                ..Default::default()
            },
        })
        .collect();
    let created = session
        .create_monitored_items(sub, TimestampsToReturn::Both, items)
        .await
        .map_err(|e| format!("cannot create the monitored items: {e}"))?;
    for (item, id) in created.iter().zip(ids) {
        if !item.result.status_code.is_good() {
            return Err(format!("node {id}: {}", item.result.status_code));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_policy_the_configuration_accepts_is_one_the_client_speaks() {
        for name in crate::config::opcua::POLICIES {
            assert!(policy(name).is_some(), "{name}");
        }
        assert_eq!(policy("Aes128_Sha256_RsaOaep"), Some(SecurityPolicy::Aes128Sha256RsaOaep));
        assert!(policy("auto").is_none());
    }
}
