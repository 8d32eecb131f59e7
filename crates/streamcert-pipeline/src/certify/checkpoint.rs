//! The `certify` checkpoint: the certifier's state and the run's summary, sealed
//! ([`seal_checkpoint`]), opened for `--resume` ([`open_checkpoint`]) and written atomically.

use std::path::Path;

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Certifier, Encoding};

use super::Summary;
use crate::CliError;
use crate::config::Config;
use crate::resume::write_atomic;

#[derive(Serialize, Deserialize)]
struct Checkpoint {
    certifier: Certifier,
    summary: Summary,
}

/// [`Checkpoint`] borrowed, for writing: the same fields and encoding, without a copy of the
/// state.
#[derive(Serialize)]
struct CheckpointRef<'a> {
    certifier: &'a Certifier,
    summary: &'a Summary,
}

/// The sealed checkpoint of `cert` and `summary` (to be written to `path`).
pub(super) fn checkpoint_bytes(
    path: &Path,
    cert: &Certifier,
    summary: &Summary,
) -> Result<Vec<u8>, CliError> {
    seal_checkpoint(&path.display().to_string(), cert, summary)
}

/// The sealed `certify` checkpoint: the certifier's state and the run's summary, in the
/// compact binary encoding, sealed with the configuration's fingerprint and a checksum
/// ([`seal`](streamcert_certificate::seal)); `label` names it in errors. The CLI writes these
/// bytes to its `--checkpoint` file and the Python package's `Certifier.checkpoint()` returns
/// them, so either restores the other's.
///
/// # Errors
/// [`CliError::Checkpoint`] when the state cannot be encoded.
pub fn seal_checkpoint(
    label: &str,
    cert: &Certifier,
    summary: &Summary,
) -> Result<Vec<u8>, CliError> {
    seal_checkpoint_as(label, cert, summary, Encoding::Binary)
}

/// [`seal_checkpoint`] in the chosen encoding: [`Encoding::Json`] is the readable export
/// (version 4, what checkpoints were before the binary encoding), which
/// [`open_checkpoint`] reads as well.
///
/// # Errors
/// [`CliError::Checkpoint`] when the state cannot be encoded.
pub fn seal_checkpoint_as(
    label: &str,
    cert: &Certifier,
    summary: &Summary,
    encoding: Encoding,
) -> Result<Vec<u8>, CliError> {
    let bad = |message: String| CliError::Checkpoint { path: label.to_string(), message };
    let cp = CheckpointRef { certifier: cert, summary };
    streamcert_certificate::seal_value(&cp, encoding, cert.config())
        .map_err(|e| bad(crate::resume::inner(e)))
}

/// Open a sealed `certify` checkpoint ([`seal_checkpoint`], in either encoding) for the
/// configuration `cfg`: refused, with what is wrong, when it is not a checkpoint, damaged
/// (checksum), written with another configuration (fingerprint), or holds an inconsistent
/// state.
///
/// # Errors
/// [`CliError::Checkpoint`] naming `label`.
pub fn open_checkpoint(
    bytes: &[u8],
    cfg: &Config,
    label: &str,
) -> Result<(Certifier, Summary), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: label.to_string(), message };
    let cp: Checkpoint =
        crate::resume::open(bytes, &cfg.certifier, |cp: &Checkpoint| cp.certifier.config())
            .map_err(bad)?;
    let cert = cp.certifier.verify().map_err(|e| bad(crate::resume::inner(e)))?;
    if cert.config() != &cfg.certifier {
        return Err(bad("the checkpoint was written with a different configuration".into()));
    }
    Ok((cert, cp.summary))
}

pub(super) fn save(path: &Path, cert: &Certifier, summary: &Summary) -> Result<(), CliError> {
    write_atomic(path, &checkpoint_bytes(path, cert, summary)?)
}

pub(super) fn load(path: &Path, cfg: &Config) -> Result<(Certifier, Summary), CliError> {
    let label = path.display().to_string();
    let bytes = std::fs::read(path)
        .map_err(|e| CliError::Checkpoint { path: label.clone(), message: e.to_string() })?;
    open_checkpoint(&bytes, cfg, &label)
}
