//! Checkpoint and restore of a [`Certifier`].
//!
//! Format (version 2): one header line, then the JSON of the whole streaming state (floats
//! round-trip exactly):
//!
//! ```text
//! streamcert-checkpoint 2 <FNV-1a 64 of the JSON, 16 hex digits> <FNV-1a 64 of the configuration's JSON>
//! {…}
//! ```
//!
//! The checksum detects every change of one byte with certainty (each FNV-1a step is a
//! bijection of the state for a fixed input byte) and any other corruption with probability
//! `1 − 2⁻⁶⁴`; the configuration fingerprint lets a caller refuse a checkpoint written under
//! another configuration before parsing it. On restore the state is also checked against its
//! configuration and against itself: buffer sizes and counters, the ambiguity spike count
//! against a recount, the regression's running sums against an exact recompute from its
//! window, `‖K‖₂` against the gain, and the calibrated windows' structure. A file that fails
//! any check is refused with a message; none of them panics.

use serde::Serialize;

use super::Certifier;
#[cfg(doc)]
use crate::CertifierConfig;
use crate::CertifyError;

/// The first word of a checkpoint file.
pub const CHECKPOINT_MAGIC: &str = "streamcert-checkpoint";
/// The checkpoint format version this build writes and reads.
pub const CHECKPOINT_VERSION: u32 = 4;

/// FNV-1a, 64 bits: `h ← (h ⊕ b) · 0x100000001b3` from `0xcbf29ce484222325`.
#[must_use]
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The fingerprint of a configuration (a [`CertifierConfig`], or any serialisable one, such as
/// a network's): FNV-1a of its JSON.
///
/// # Errors
/// [`CertifyError::Checkpoint`] if the configuration cannot be serialised.
pub fn config_fingerprint<C: Serialize + ?Sized>(config: &C) -> Result<u64, CertifyError> {
    let json =
        serde_json::to_string(config).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
    Ok(fnv1a64(json.as_bytes()))
}

/// Wrap `payload` in the version-2 envelope for `config`.
///
/// # Errors
/// [`CertifyError::Checkpoint`] if the configuration cannot be serialised.
pub fn seal<C: Serialize + ?Sized>(payload: &str, config: &C) -> Result<String, CertifyError> {
    Ok(format!(
        "{CHECKPOINT_MAGIC} {CHECKPOINT_VERSION} {:016x} {:016x}\n{payload}",
        fnv1a64(payload.as_bytes()),
        config_fingerprint(config)?
    ))
}

/// Check the envelope of `text` and return its payload; with `config`, also require the
/// fingerprint of that configuration.
///
/// # Errors
/// [`CertifyError::Checkpoint`] naming what is wrong: not a checkpoint, another version, a
/// checksum mismatch (corruption), another configuration.
pub fn unseal<'a, C: Serialize + ?Sized>(
    text: &'a str,
    config: Option<&C>,
) -> Result<&'a str, CertifyError> {
    let (payload, fingerprint) = open(text)?;
    if let Some(config) = config {
        if config_fingerprint(config)? != fingerprint {
            return Err(CertifyError::Checkpoint(
                "the checkpoint was written with a different configuration".into(),
            ));
        }
    }
    Ok(payload)
}

/// The payload of a checkpoint whose header and checksum are intact, and the configuration
/// fingerprint its header records.
fn open(text: &str) -> Result<(&str, u64), CertifyError> {
    let bad = |m: String| Err(CertifyError::Checkpoint(m));
    let Some((header, payload)) = text.split_once('\n') else {
        return bad("not a streamcert checkpoint (no header line)".into());
    };
    let fields: Vec<&str> = header.split(' ').collect();
    let [magic, version, checksum, fingerprint] = fields[..] else {
        return bad(format!("not a streamcert checkpoint (header `{}`)", header.escape_debug()));
    };
    if magic != CHECKPOINT_MAGIC {
        return bad(format!("not a streamcert checkpoint (header `{}`)", header.escape_debug()));
    }
    if version != CHECKPOINT_VERSION.to_string() {
        return bad(format!(
            "checkpoint format version `{}`, this build reads version {CHECKPOINT_VERSION}",
            version.escape_debug()
        ));
    }
    // Exactly the sixteen lower-case digits `seal` writes, so no edit of the header passes.
    let hex = |s: &str| {
        let canonical = s.len() == 16 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'));
        canonical.then(|| u64::from_str_radix(s, 16).ok()).flatten()
    };
    let (Some(checksum), Some(fingerprint)) = (hex(checksum), hex(fingerprint)) else {
        return bad("the checkpoint header is damaged".into());
    };
    if fnv1a64(payload.as_bytes()) != checksum {
        return bad("the checkpoint is corrupted (its checksum does not match its content)".into());
    }
    Ok((payload, fingerprint))
}

impl Certifier {
    /// Serialise the full streaming state in the checkpoint format (see the module docs).
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] if serialisation fails.
    pub fn checkpoint(&self) -> Result<String, CertifyError> {
        let json =
            serde_json::to_string(self).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        seal(&json, &self.cfg)
    }

    /// Restore a state written by [`checkpoint`](Self::checkpoint): check the envelope, parse,
    /// and [`verify`](Self::verify) it.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] for a damaged envelope, malformed JSON or an inconsistent
    /// state.
    pub fn restore(text: &str) -> Result<Self, CertifyError> {
        let (json, fingerprint) = open(text)?;
        let c: Self =
            serde_json::from_str(json).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        if config_fingerprint(&c.cfg)? != fingerprint {
            return Err(CertifyError::Checkpoint(
                "the configuration in the checkpoint does not match its header".into(),
            ));
        }
        c.verify()
    }

    /// Check a deserialised state against its configuration and against itself (see the
    /// module docs); returns it unchanged when it passes.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] or the configuration's error, naming the first problem.
    pub fn verify(self) -> Result<Self, CertifyError> {
        let mut c = self;
        c.cfg.validate()?;
        c.regression.check_state().map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        c.regression.check_statistics(1e-9).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        let p = c.cfg.regression.outputs;
        if c.ambiguity.len() != if c.cfg.ambiguity.is_some() { p } else { 0 }
            || c.ambiguity
                .iter()
                .any(|a| Some(*a.config()) != c.cfg.ambiguity || !a.is_consistent())
        {
            return Err(CertifyError::Checkpoint(
                "ambiguity state does not match its configuration".into(),
            ));
        }
        let gain = c.cfg.metric_gain();
        let gain_norm =
            streamcert_regression::linalg::spectral_norm(&gain, c.cfg.regression.inputs, p);
        if c.regression.config() != &c.cfg.regression
            || c.jcl.len() != p * p
            || c.work.len() != p * p
            || c.resid.len() != p
            || c.eig_work.len() != streamcert_regression::linalg::eig_work_len(p)
            || c.gain_norm.to_bits() != gain_norm.to_bits()
            || c.gain != gain
            || c.scaled.len() != if c.cfg.metric.is_some() { p } else { 0 }
            || c.calibrated.is_some() != c.cfg.calibration.is_some()
            || !c.gap.is_consistent(c.cfg.gap_factor)
        {
            return Err(CertifyError::Checkpoint("state does not match its configuration".into()));
        }
        if let Some(state) = &mut c.calibrated {
            state.check(c.cfg.nonlinear, c.cfg.couplings.as_ref(), &c.cfg.regression, &gain)?;
            state.rebuild();
        }
        Ok(c)
    }
}
