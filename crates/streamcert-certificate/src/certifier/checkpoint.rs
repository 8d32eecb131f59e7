//! Checkpoint and restore of a [`Certifier`].
//!
//! Format: one header line of text, then the payload, the whole streaming state (floats
//! round-trip exactly):
//!
//! ```text
//! streamcert-checkpoint <version> <FNV-1a 64 of the payload, 16 hex digits> <FNV-1a 64 of the configuration's JSON>
//! <payload>
//! ```
//!
//! Version 7 ([`Encoding::Binary`], what [`Certifier::checkpoint`] writes) encodes the payload
//! in CBOR (RFC 8949; each float in the shortest of 2, 4 or 8 bytes that holds it exactly).
//! The calibrated state's sliding block rings (the linear windows' and the model guards'
//! larger fits') are left out where its sample trail rebuilds them bit for bit, and rebuilt
//! from it on restore (`calibrated/replay.rs`; the trail's times cost about a byte each on a
//! regular grid, `calibrated/trail.rs`); a ring the trail does not rebuild is written, packed:
//! an entry that another entry determines bit for bit (the model guards' sums shared with the
//! linear windows', the lower triangle of each `H`) is not written, and the rest are raw `f64`
//! bytes (`pack.rs`), as is the anchored window's ring. For a default calibrated certifier
//! after 20 000 rows that is 0.09 of the JSON's size, 133 KB (BENCHMARKS.md). Version 6 is the
//! same CBOR with every ring packed and no trail, version 5 every ring whole; version 4
//! ([`Encoding::Json`], [`Certifier::checkpoint_json`]) is JSON text with every ring whole,
//! kept as a readable export and for the checkpoints written before the binary ones.
//! [`Certifier::restore`] reads all four.
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
use serde::de::DeserializeOwned;

use super::Certifier;
#[cfg(doc)]
use crate::CertifierConfig;
use crate::CertifyError;

/// The first word of a checkpoint file.
pub const CHECKPOINT_MAGIC: &str = "streamcert-checkpoint";
/// The checkpoint format version this build writes ([`Encoding::Binary`]); it also reads
/// [`CHECKPOINT_UNPACKED_VERSION`] and [`CHECKPOINT_JSON_VERSION`].
pub const CHECKPOINT_VERSION: u32 = 7;
/// The binary encoding before the sample trail (every block ring written, packed; no trail),
/// still read.
pub const CHECKPOINT_PACKED_VERSION: u32 = 6;
/// The binary encoding before the packed block rings (every ring written whole), still read.
pub const CHECKPOINT_UNPACKED_VERSION: u32 = 5;
/// The version of the JSON encoding ([`Encoding::Json`]): the export, and every checkpoint
/// written before the binary one.
pub const CHECKPOINT_JSON_VERSION: u32 = 4;

/// How a checkpoint's payload is encoded; its header's version says which.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// CBOR (RFC 8949) with the sliding block rings rebuilt from the sample trail and the
    /// rest packed, version [`CHECKPOINT_VERSION`] (versions [`CHECKPOINT_PACKED_VERSION`]
    /// and [`CHECKPOINT_UNPACKED_VERSION`] read as well): the compact default.
    Binary,
    /// JSON text, version [`CHECKPOINT_JSON_VERSION`]: readable, about ten times as large.
    Json,
}

impl Encoding {
    /// The header's version number of this encoding.
    #[must_use]
    pub const fn version(self) -> u32 {
        match self {
            Self::Binary => CHECKPOINT_VERSION,
            Self::Json => CHECKPOINT_JSON_VERSION,
        }
    }

    fn of_version(v: &str) -> Option<Self> {
        if v == CHECKPOINT_UNPACKED_VERSION.to_string()
            || v == CHECKPOINT_PACKED_VERSION.to_string()
        {
            return Some(Self::Binary);
        }
        [Self::Binary, Self::Json].into_iter().find(|e| v == e.version().to_string())
    }
}

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

/// `value` encoded as a checkpoint payload in `encoding`.
///
/// # Errors
/// [`CertifyError::Checkpoint`] if the value cannot be serialised.
pub fn encode<T: Serialize + ?Sized>(
    value: &T,
    encoding: Encoding,
) -> Result<Vec<u8>, CertifyError> {
    let mut out = Vec::new();
    encode_into(value, encoding, &mut out)?;
    Ok(out)
}

/// Append `value`'s payload in `encoding` to `out`.
fn encode_into<T: Serialize + ?Sized>(
    value: &T,
    encoding: Encoding,
    out: &mut Vec<u8>,
) -> Result<(), CertifyError> {
    let bad = |m: String| CertifyError::Checkpoint(m);
    match encoding {
        Encoding::Json => serde_json::to_writer(out, value).map_err(|e| bad(e.to_string())),
        Encoding::Binary => ciborium::into_writer(value, out).map_err(|e| bad(e.to_string())),
    }
}

/// The envelope's header line for a payload with checksum `checksum`.
fn header(encoding: Encoding, checksum: u64, fingerprint: u64) -> String {
    format!("{CHECKPOINT_MAGIC} {} {checksum:016x} {fingerprint:016x}\n", encoding.version())
}

/// The value a payload in `encoding` holds.
///
/// # Errors
/// [`CertifyError::Checkpoint`] naming what does not parse.
pub fn decode<T: DeserializeOwned>(payload: &[u8], encoding: Encoding) -> Result<T, CertifyError> {
    let bad = |m: String| CertifyError::Checkpoint(m);
    match encoding {
        Encoding::Json => serde_json::from_slice(payload).map_err(|e| bad(e.to_string())),
        Encoding::Binary => ciborium::from_reader(payload).map_err(|e| bad(e.to_string())),
    }
}

/// Wrap `payload` (encoded in `encoding`) in the envelope for `config`.
///
/// # Errors
/// [`CertifyError::Checkpoint`] if the configuration cannot be serialised.
pub fn seal<C: Serialize + ?Sized>(
    payload: &[u8],
    encoding: Encoding,
    config: &C,
) -> Result<Vec<u8>, CertifyError> {
    let header = header(encoding, fnv1a64(payload), config_fingerprint(config)?);
    let mut out = Vec::with_capacity(header.len() + payload.len());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(payload);
    Ok(out)
}

/// `value` encoded in `encoding` and sealed for `config`: the bytes of [`encode`] then
/// [`seal`], the payload written once behind the header's place (no second copy of a large
/// state).
///
/// # Errors
/// [`CertifyError::Checkpoint`] if the value or the configuration cannot be serialised.
pub fn seal_value<T: Serialize + ?Sized, C: Serialize + ?Sized>(
    value: &T,
    encoding: Encoding,
    config: &C,
) -> Result<Vec<u8>, CertifyError> {
    let fingerprint = config_fingerprint(config)?;
    // The header's length does not depend on the checksum's value (16 hex digits).
    let start = header(encoding, 0, fingerprint).len();
    let mut out = vec![0; start];
    encode_into(value, encoding, &mut out)?;
    let head = header(encoding, fnv1a64(&out[start..]), fingerprint);
    out[..start].copy_from_slice(head.as_bytes());
    Ok(out)
}

/// The payload of an intact checkpoint and how it is encoded ([`unseal`]).
#[derive(Debug, Clone, Copy)]
pub struct Sealed<'a> {
    /// The header's encoding.
    pub encoding: Encoding,
    /// The payload's bytes, checksum verified.
    pub payload: &'a [u8],
}

impl Sealed<'_> {
    /// The value the payload holds ([`decode`]).
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] naming what does not parse.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, CertifyError> {
        decode(self.payload, self.encoding)
    }
}

/// Check the envelope of `bytes` and return its payload; with `config`, also require the
/// fingerprint of that configuration.
///
/// # Errors
/// [`CertifyError::Checkpoint`] naming what is wrong: not a checkpoint, another version, a
/// checksum mismatch (corruption), another configuration.
pub fn unseal<'a, C: Serialize + ?Sized>(
    bytes: &'a [u8],
    config: Option<&C>,
) -> Result<Sealed<'a>, CertifyError> {
    let (sealed, fingerprint) = open(bytes)?;
    if let Some(config) = config
        && config_fingerprint(config)? != fingerprint
    {
        return Err(CertifyError::Checkpoint(
            "the checkpoint was written with a different configuration".into(),
        ));
    }
    Ok(sealed)
}

/// The payload of a checkpoint whose header and checksum are intact, and the configuration
/// fingerprint its header records.
fn open(bytes: &[u8]) -> Result<(Sealed<'_>, u64), CertifyError> {
    let bad = |m: String| Err(CertifyError::Checkpoint(m));
    let Some(end) = bytes.iter().take(256).position(|&b| b == b'\n') else {
        return bad("not a streamcert checkpoint (no header line)".into());
    };
    let (header, payload) = (&bytes[..end], &bytes[end + 1..]);
    let shown = String::from_utf8_lossy(header);
    let fields: Vec<&str> = std::str::from_utf8(header).unwrap_or("").split(' ').collect();
    let [magic, version, checksum, fingerprint] = fields[..] else {
        return bad(format!("not a streamcert checkpoint (header `{}`)", shown.escape_debug()));
    };
    if magic != CHECKPOINT_MAGIC {
        return bad(format!("not a streamcert checkpoint (header `{}`)", shown.escape_debug()));
    }
    let Some(encoding) = Encoding::of_version(version) else {
        return bad(format!(
            "checkpoint format version `{}`, this build reads versions {CHECKPOINT_VERSION}, \
             {CHECKPOINT_PACKED_VERSION}, {CHECKPOINT_UNPACKED_VERSION} and \
             {CHECKPOINT_JSON_VERSION}",
            version.escape_debug()
        ));
    };
    // Exactly the sixteen lower-case digits `seal` writes, so no edit of the header passes.
    let hex = |s: &str| {
        let canonical = s.len() == 16 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'));
        canonical.then(|| u64::from_str_radix(s, 16).ok()).flatten()
    };
    let (Some(checksum), Some(fingerprint)) = (hex(checksum), hex(fingerprint)) else {
        return bad("the checkpoint header is damaged".into());
    };
    if fnv1a64(payload) != checksum {
        return bad("the checkpoint is corrupted (its checksum does not match its content)".into());
    }
    Ok((Sealed { encoding, payload }, fingerprint))
}

impl Certifier {
    /// Serialise the full streaming state in the checkpoint format (see the module docs), in
    /// the compact binary encoding ([`Encoding::Binary`]).
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] if serialisation fails.
    pub fn checkpoint(&self) -> Result<Vec<u8>, CertifyError> {
        seal_value(self, Encoding::Binary, &self.cfg)
    }

    /// The same checkpoint as JSON text ([`Encoding::Json`], version
    /// [`CHECKPOINT_JSON_VERSION`]): a readable export that [`restore`](Self::restore) reads
    /// as well.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] if serialisation fails.
    pub fn checkpoint_json(&self) -> Result<String, CertifyError> {
        let sealed = seal_value(self, Encoding::Json, &self.cfg)?;
        String::from_utf8(sealed).map_err(|e| CertifyError::Checkpoint(e.to_string()))
    }

    /// Restore a state written by [`checkpoint`](Self::checkpoint) or
    /// [`checkpoint_json`](Self::checkpoint_json): check the envelope, parse, and
    /// [`verify`](Self::verify) it.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] for a damaged envelope, a payload that does not parse or
    /// an inconsistent state.
    pub fn restore(bytes: impl AsRef<[u8]>) -> Result<Self, CertifyError> {
        let (sealed, fingerprint) = open(bytes.as_ref())?;
        let c: Self = sealed.decode()?;
        if config_fingerprint(&c.cfg)? != fingerprint {
            return Err(CertifyError::Checkpoint(
                "the configuration in the checkpoint does not match its header".into(),
            ));
        }
        c.verify()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Oracle: `seal(encode(v))`, the two steps apart. The one-copy path writes the same
    /// bytes in both encodings, and `unseal` gives back the payload and its encoding.
    #[test]
    fn seal_value_equals_encode_then_seal() {
        let value = (vec![0.1_f64, -2.5e-300, 1.0, f64::MAX], "state", 7_u64);
        for encoding in [Encoding::Binary, Encoding::Json] {
            let sealed = seal_value(&value, encoding, &"cfg").expect("seals");
            let apart = seal(&encode(&value, encoding).unwrap(), encoding, &"cfg").unwrap();
            assert_eq!(sealed, apart);
            let opened = unseal(&sealed, Some(&"cfg")).expect("opens");
            assert_eq!(opened.encoding, encoding);
            let back: (Vec<f64>, String, u64) = opened.decode().expect("decodes");
            assert_eq!(
                back.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                value.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
            assert!(unseal(&sealed, Some(&"other")).is_err());
        }
        // Another version, or none, is refused with what this build reads.
        let text = String::from_utf8(seal_value(&value, Encoding::Json, &"cfg").unwrap()).unwrap();
        let err = unseal(text.replacen(" 4 ", " 3 ", 1).as_bytes(), None::<&()>).unwrap_err();
        assert!(err.to_string().contains("reads versions 7, 6, 5 and 4"), "{err}");
    }
}
