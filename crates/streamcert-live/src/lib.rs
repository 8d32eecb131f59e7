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

pub use align::{AlignRule, Aligned, Aligner};
pub use config::{SourceConfig, parse};
#[cfg(feature = "mqtt")]
pub use mqtt::MqttSource;
#[cfg(feature = "opcua")]
pub use opcua::OpcUaSource;

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
) -> Result<Box<dyn streamcert_pipeline::source::Source>, streamcert_pipeline::CliError> {
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
