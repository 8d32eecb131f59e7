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
pub mod payload;
#[cfg(feature = "mqtt")]
pub mod publish;

pub use align::{AlignRule, Aligned, Aligner};
pub use config::{SourceConfig, parse};
#[cfg(feature = "mqtt")]
pub use mqtt::MqttSource;

/// The live source a configuration's `[source]` table names, for rows of `columns` (a
/// `certify` configuration's, or a network's wide columns): parsed, checked and connected
/// lazily. `checkpointing` holds acknowledgements for the run's checkpoints.
///
/// # Errors
/// [`CliError::Config`](streamcert_pipeline::CliError::Config) naming the key at fault; a TLS
/// file that cannot be read.
#[cfg(feature = "mqtt")]
pub fn open(
    table: &toml::Table,
    columns: &streamcert_pipeline::config::Columns,
    checkpointing: bool,
) -> Result<MqttSource, streamcert_pipeline::CliError> {
    let cfg = parse(table, columns).map_err(|message| streamcert_pipeline::CliError::Config {
        path: "[source]".into(),
        message,
    })?;
    MqttSource::new(cfg.mqtt, columns.outputs.len(), checkpointing)
}
