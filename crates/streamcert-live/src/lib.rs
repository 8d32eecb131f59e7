//! # streamcert-live
//!
//! Live plant sources for streamcert: a certify run reads a plant's signals straight from an
//! MQTT broker, as the pipeline's [`Source`](streamcert_pipeline::source::Source), instead
//! of a CSV pipe.
//!
//! - [`align`]: per-signal updates into rows on a grid by source time (sample and hold, a
//!   `max_age`, a reorder window; never interpolated across).
//! - [`payload`]: message payloads into samples (a JSON object or a CSV line per row; a
//!   number or a JSON value with its timestamp per signal), every failure a named kind.
//! - [`config`]: the `[source]` section, with Telegraf's `mqtt_consumer` names.
//! - `mqtt` (feature `mqtt`, on by default): the subscription itself, through rumqttc:
//!   QoS 1 on a persistent session, acknowledgements held for checkpoints, reconnection
//!   with backoff, outages as gaps.
//! - `broker` (feature `broker`): an embedded MQTT broker, to try a live run without
//!   installing one, and the tests' peer.
//! - [`publish`] (feature `mqtt`): a simulated plant published to a broker, for trying a
//!   live run and for tests.
//!
//! - [`verdict`] (feature `mqtt`): the `[verdict]` section and the publisher of verdict
//!   messages on a retained topic, for interlocks.
//!
//! The certifier is untouched by any of this: a source yields rows, gaps and bad payloads,
//! and the pipeline's run loop does the rest. A downstream user who reads files only links
//! no MQTT client (this crate is the command line's, not the pipeline's).

pub mod align;
#[cfg(feature = "broker")]
pub mod broker;
pub mod config;
#[cfg(feature = "mqtt")]
pub mod mqtt;
#[cfg(feature = "opcua")]
pub mod opcua;
pub mod payload;
#[cfg(feature = "mqtt")]
pub mod publish;
mod rows;
#[cfg(feature = "mqtt")]
pub mod verdict;

pub use align::{AlignRule, Aligned, Aligner};
pub use config::{SourceConfig, parse};
#[cfg(feature = "mqtt")]
pub use mqtt::MqttSource;
#[cfg(feature = "opcua")]
pub use opcua::OpcUaSource;

/// The `[source]` table of a network's site: its `[[source.signal]]` (MQTT) or
/// `[[source.node]]` (OPC UA) entries restricted to `columns` (the site's subsystems'), and
/// an MQTT client id suffixed `-site{process}` (a persistent session per site). The shared
/// configuration lists every subsystem's signals; each site subscribes to its own.
#[must_use]
pub fn for_site(
    table: &toml::Table,
    columns: &streamcert_pipeline::config::Columns,
    process: usize,
) -> toml::Table {
    let mut table = table.clone();
    let wanted: Vec<&String> = columns.outputs.iter().chain(&columns.inputs).collect();
    let column_of = |v: &toml::Value| {
        v.get("column").or_else(|| v.get("name")).and_then(toml::Value::as_str).map(String::from)
    };
    for key in ["signal", "node"] {
        if let Some(toml::Value::Array(entries)) = table.get_mut(key) {
            entries.retain(|e| column_of(e).is_some_and(|c| wanted.contains(&&c)));
        }
    }
    if table.get("kind").and_then(toml::Value::as_str) == Some("mqtt") {
        let id = table.get("client_id").and_then(toml::Value::as_str).unwrap_or("streamcert");
        let id = format!("{id}-site{process}");
        table.insert("client_id".into(), toml::Value::String(id));
    }
    table
}

/// The live source a configuration's `[source]` table names, for rows of `columns` (a
/// `certify` configuration's, or a network's wide columns): parsed, checked and connected
/// lazily. `checkpointing` holds an MQTT source's acknowledgements for the run's checkpoints.
///
/// # Errors
/// [`CliError::Config`](streamcert_pipeline::CliError::Config) naming the key at fault, or a
/// kind this build does not include; a TLS file that cannot be read.
pub fn open(
    table: &toml::Table,
    columns: &streamcert_pipeline::config::Columns,
    checkpointing: bool,
) -> Result<Box<dyn streamcert_pipeline::source::Source + Send>, streamcert_pipeline::CliError> {
    let config = |message: String| streamcert_pipeline::CliError::Config {
        path: "[source]".into(),
        message,
    };
    let outputs = columns.outputs.len();
    match parse(table, columns).map_err(config)? {
        #[cfg(feature = "mqtt")]
        SourceConfig::Mqtt(cfg) => Ok(Box::new(MqttSource::new(cfg, outputs, checkpointing)?)),
        #[cfg(feature = "opcua")]
        SourceConfig::OpcUa(cfg) => {
            let _ = checkpointing;
            Ok(Box::new(OpcUaSource::new(cfg, outputs)?))
        }
        #[allow(unreachable_patterns)]
        _ => Err(config(
            "this build has no client for this source kind (features mqtt, opcua)".into(),
        )),
    }
}
