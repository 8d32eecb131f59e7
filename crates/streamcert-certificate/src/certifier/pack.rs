//! The binary checkpoint's packed block rings: a calibrated state's three rings of block sums
//! written once where they hold the same numbers. Where the sample trail rebuilds the
//! sliding rings (`calibrated/replay.rs`, tried first), they are left out instead and only
//! the anchored window's ring is packed here.
//!
//! The linear windows' ring and each model guard's larger fit (see `guard::model`) keep, per
//! block of `h` columns, `N = Σ Z Wᵀ`, `Cw = Σ ΔY Wᵀ` and `H = Σ W Wᵀ`. A guard's regressors
//! begin with the linear windows' (`y`, `u`, `τ`, then its extra terms), and its instruments
//! are its regressors of earlier intervals, so every entry of its sums that involves no extra
//! term is formed from the same products in the same order as the linear ring's: the same
//! bits. And `H` is symmetric entry for entry (`w_a w_b` and `w_b w_a` are the same product).
//! A ring is written as the values no other entry determines, as raw little-endian `f64`
//! bytes (8 bytes each where CBOR takes 9):
//!
//! ```text
//! linear ring: N, Cw and the upper triangle of H                 (21 → 18 values per block, p = m = 1)
//! guard ring:  the entries with an extra regressor or instrument (36 → 12, 55 → 27)
//! ```
//!
//! Nothing is assumed: each derived entry is compared bit for bit with its source when the
//! checkpoint is written, and a ring with any difference (a state restored from an older
//! build, rings out of step) is written whole, as before. On restore the rings are rebuilt
//! before the state is parsed; a packed ring that does not fit its layout is refused. The
//! JSON export ([`Encoding::Json`](super::checkpoint::Encoding)) always writes the rings
//! whole. Only the non-human-readable serialisers (the binary checkpoint) go through here.

use ciborium::Value;
use serde::de::Error as _;
use serde::ser::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::calibrated::CalibratedState;

/// Where a packed ring's derived entries come from (the key `blocks_from`).
const FROM_SELF: &str = "self";
const FROM_LINEAR: &str = "linear";

/// One entry of a block's record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    /// Written.
    Stored,
    /// The linear ring's entry at this index of its record.
    Linear(usize),
    /// This record's entry at this (earlier) index: the mirror of a lower entry of `H`.
    Mirror(usize),
}

/// A ring's shape, read from its serialised map.
#[derive(Debug, Clone, PartialEq)]
struct Shape {
    p: usize,
    d: usize,
    intervals: usize,
    horizon: usize,
    lag: usize,
    head: usize,
    len: usize,
    coarse: usize,
    lengths: Vec<usize>,
}

impl Shape {
    fn k(&self) -> usize {
        self.intervals * self.d
    }

    fn stride(&self) -> usize {
        let k = self.k();
        self.d * k + self.p * k + k * k
    }

    fn cap(&self) -> usize {
        self.lengths.last().copied().unwrap_or(0)
    }

    /// Whether `self` (a guard's ring) holds `linear`'s sums in the same blocks.
    fn nests(&self, linear: &Self) -> bool {
        (self.p, self.intervals, self.horizon, self.lag)
            == (linear.p, linear.intervals, linear.horizon, linear.lag)
            && (self.head, self.len, self.coarse, &self.lengths)
                == (linear.head, linear.len, linear.coarse, &linear.lengths)
            && self.d > linear.d
    }

    /// The source of each entry of a record: with `linear`, the entries shared with that
    /// ring's (regressor and instrument indices all below its `d` within each interval).
    fn sources(&self, linear: Option<&Self>) -> Vec<Source> {
        let (p, d, k) = (self.p, self.d, self.k());
        // Instrument `c` (interval c / d, regressor c % d) in the linear ring's numbering.
        let inst = |c: usize, ld: usize| (c % d < ld).then(|| (c / d) * ld + c % d);
        let mut out = Vec::with_capacity(self.stride());
        for r in 0..d {
            for c in 0..k {
                out.push(match linear {
                    Some(l) if r < l.d => {
                        inst(c, l.d).map_or(Source::Stored, |lc| Source::Linear(r * l.k() + lc))
                    }
                    _ => Source::Stored,
                });
            }
        }
        for i in 0..p {
            for c in 0..k {
                out.push(match linear {
                    Some(l) => inst(c, l.d)
                        .map_or(Source::Stored, |lc| Source::Linear(l.d * l.k() + i * l.k() + lc)),
                    None => Source::Stored,
                });
            }
        }
        let h = d * k + p * k;
        for a in 0..k {
            for b in 0..k {
                let shared = linear.and_then(|l| {
                    let (la, lb) = (inst(a, l.d)?, inst(b, l.d)?);
                    Some(Source::Linear(l.d * l.k() + p * l.k() + la * l.k() + lb))
                });
                out.push(shared.unwrap_or(if a > b {
                    Source::Mirror(h + b * k + a)
                } else {
                    Source::Stored
                }));
            }
        }
        out
    }
}

fn entry<'a>(map: &'a [(Value, Value)], key: &str) -> Option<&'a Value> {
    map.iter().find(|(k, _)| k.as_text() == Some(key)).map(|(_, v)| v)
}

fn entry_mut<'a>(map: &'a mut [(Value, Value)], key: &str) -> Option<&'a mut Value> {
    map.iter_mut().find(|(k, _)| k.as_text() == Some(key)).map(|(_, v)| v)
}

fn uint(v: &Value) -> Option<usize> {
    v.as_integer().and_then(|i| usize::try_from(i).ok())
}

fn shape(ring: &[(Value, Value)]) -> Option<Shape> {
    let get = |key| entry(ring, key).and_then(uint);
    let (p, m) = (get("p")?, get("m")?);
    let lengths = entry(ring, "windows")?.as_array()?.iter().map(uint).collect::<Option<_>>()?;
    let shape = Shape {
        p,
        d: p.checked_add(m)?,
        intervals: get("intervals")?,
        horizon: get("horizon")?,
        lag: get("lag")?,
        head: get("block_head")?,
        len: get("block_len")?,
        // Written only when not 1 (`InstrumentedWindows`).
        coarse: entry(ring, "coarse").map_or(Some(1), uint)?,
        lengths,
    };
    // A record of sane size (a damaged or hostile file may name any dimensions): so that
    // `k` and `stride` cannot overflow and `sources` allocates at most this many entries.
    let k = shape.intervals.checked_mul(shape.d)?;
    let stride = shape.d.checked_add(p)?.checked_mul(k)?.checked_add(k.checked_mul(k)?)?;
    (p >= 1 && k >= 1 && stride <= MAX_RECORD).then_some(shape)
}

/// The most entries of a record per stored one that a packed ring may rebuild.
const MAX_EXPANSION: usize = 64;

/// The most values a block record may hold in a packed ring (far above any configuration's:
/// `p = m = 10` with three instrument intervals is about 10⁴).
const MAX_RECORD: usize = 1 << 20;

/// A ring's block sums, when they are an array of `cap · stride` floats.
fn blocks(ring: &[(Value, Value)], shape: &Shape) -> Option<Vec<f64>> {
    let values = entry(ring, "blocks")?.as_array()?;
    (values.len() == shape.cap().checked_mul(shape.stride())?)
        .then(|| values.iter().map(Value::as_float).collect())?
}

/// The stored entries of `ring` (`sources` per record), or `None` where a derived entry
/// differs from its source in any bit.
fn pack_ring(ring: &[f64], sources: &[Source], linear: &[f64]) -> Option<Vec<u8>> {
    let stride = sources.len();
    let stored = sources.iter().filter(|s| **s == Source::Stored).count();
    let cap = ring.len() / stride;
    let lstride = linear.len().checked_div(cap).unwrap_or(0);
    let mut out = Vec::with_capacity(cap * stored * 8);
    for (b, rec) in ring.chunks_exact(stride).enumerate() {
        for (v, s) in rec.iter().zip(sources) {
            let source = match *s {
                Source::Stored => {
                    out.extend_from_slice(&v.to_le_bytes());
                    continue;
                }
                Source::Linear(j) => *linear.get(b * lstride + j)?,
                Source::Mirror(j) => rec[j],
            };
            if source.to_bits() != v.to_bits() {
                return None;
            }
        }
    }
    Some(out)
}

/// The ring rebuilt from its stored entries `bytes` (`sources` per record, `cap` records).
fn unpack_ring(bytes: &[u8], sources: &[Source], cap: usize, linear: &[f64]) -> Option<Vec<f64>> {
    let stride = sources.len();
    let stored = sources.iter().filter(|s| **s == Source::Stored).count();
    // The rebuilt ring is at most `MAX_EXPANSION` times the values read (packing leaves out
    // at most three of four entries of the shapes built here), so a small damaged file
    // cannot ask for a large one.
    if stored == 0
        || stride > MAX_EXPANSION * stored
        || bytes.len() != cap.checked_mul(stored)?.checked_mul(8)?
    {
        return None;
    }
    let lstride = linear.len().checked_div(cap).unwrap_or(0);
    let mut words =
        bytes.chunks_exact(8).map(|w| f64::from_le_bytes(w.try_into().unwrap_or([0; 8])));
    let mut out = Vec::with_capacity(cap * stride);
    for b in 0..cap {
        let start = out.len();
        for s in sources {
            let v = match *s {
                Source::Stored => words.next()?,
                Source::Linear(j) => *linear.get(b * lstride + j)?,
                Source::Mirror(j) => out[start + j],
            };
            out.push(v);
        }
    }
    Some(out)
}

/// Replace `ring`'s `blocks` by its packed entries, when every derived entry matches.
fn pack_map(ring: &mut Ring, linear: Option<(&Shape, &[f64])>) -> Option<()> {
    let own = shape(ring)?;
    if linear.is_some_and(|(l, _)| !own.nests(l)) {
        return None;
    }
    let values = blocks(ring, &own)?;
    let sources = own.sources(linear.map(|(l, _)| l));
    let bytes = pack_ring(&values, &sources, linear.map_or(&[][..], |(_, b)| b))?;
    *entry_mut(ring, "blocks")? = Value::Array(Vec::new());
    let from = if linear.is_some() { FROM_LINEAR } else { FROM_SELF };
    ring.push((Value::Text("blocks_packed".into()), Value::Bytes(bytes)));
    ring.push((Value::Text("blocks_from".into()), Value::Text(from.into())));
    Some(())
}

/// A serialised ring: its map of fields.
type Ring = Vec<(Value, Value)>;

/// The ring maps of a serialised calibrated state: the linear windows', the model guards', and
/// the anchored window's records (when it is on).
struct Rings<'a> {
    linear: &'a mut Ring,
    guards: Vec<&'a mut Ring>,
    anchored: Option<&'a mut Ring>,
}

fn rings(state: &mut Value) -> Option<Rings<'_>> {
    let map = state.as_map_mut()?;
    let (mut linear, mut guards, mut anchored) = (None, Vec::new(), None);
    for (k, v) in map.iter_mut() {
        match k.as_text() {
            Some("windows") => linear = v.as_map_mut(),
            Some("model") => {
                for g in v.as_array_mut()? {
                    guards.push(entry_mut(g.as_map_mut()?, "windows")?.as_map_mut()?);
                }
            }
            Some("anchored") => {
                anchored = v
                    .as_map_mut()
                    .and_then(|a| entry_mut(a, "window"))
                    .and_then(Value::as_map_mut)
                    .and_then(|w| entry_mut(w, "ring"))
                    .and_then(Value::as_map_mut);
            }
            _ => {}
        }
    }
    Some(Rings { linear: linear?, guards, anchored })
}

/// Pack the rings of a serialised calibrated state (module docs); a ring that does not pack
/// is left whole.
fn pack(state: &mut Value) {
    let Some(Rings { linear, guards, anchored }) = rings(state) else { return };
    let base = shape(linear).and_then(|s| blocks(linear, &s).map(|b| (s, b)));
    for g in guards {
        if let Some((s, b)) = &base {
            pack_map(g, Some((s, b)));
        }
    }
    pack_map(linear, None);
    if let Some(ring) = anchored {
        pack_map(ring, None);
    }
}

/// Rebuild one packed ring (`blocks_from` already checked) against `linear`.
fn unpack_map(ring: &mut Ring, linear: Option<(&Shape, &[f64])>) -> Result<(), String> {
    let bad = || "a packed block ring of the checkpoint does not fit its layout".to_string();
    let own = shape(ring).ok_or_else(bad)?;
    if linear.is_some_and(|(l, _)| !own.nests(l)) {
        return Err(bad());
    }
    let at = ring.iter().position(|(k, _)| k.as_text() == Some("blocks_packed")).ok_or_else(bad)?;
    let (_, bytes) = ring.swap_remove(at);
    ring.retain(|(k, _)| k.as_text() != Some("blocks_from"));
    let bytes = bytes.as_bytes().ok_or_else(bad)?;
    let sources = own.sources(linear.map(|(l, _)| l));
    let values = unpack_ring(bytes, &sources, own.cap(), linear.map_or(&[][..], |(_, b)| b))
        .ok_or_else(bad)?;
    let slot = entry_mut(ring, "blocks").ok_or_else(bad)?;
    if slot.as_array().is_none_or(|a| !a.is_empty()) {
        return Err(bad());
    }
    *slot = Value::Array(values.into_iter().map(Value::Float).collect());
    Ok(())
}

fn packed_from(ring: &[(Value, Value)]) -> Option<&str> {
    entry(ring, "blocks_from").and_then(Value::as_text)
}

/// Rebuild the packed rings of a serialised calibrated state: the linear one first, then the
/// guards' from it, and the anchored window's.
fn unpack(state: &mut Value) -> Result<(), String> {
    let Some(Rings { linear, guards, anchored }) = rings(state) else { return Ok(()) };
    let wrong = |what: &str| format!("a block ring of the checkpoint is packed {what}");
    let own = |ring: &mut Ring| match packed_from(ring) {
        None => Ok(()),
        Some(FROM_SELF) => unpack_map(ring, None),
        Some(other) => Err(wrong(&format!("from `{other}`"))),
    };
    own(linear)?;
    if let Some(ring) = anchored {
        own(ring)?;
    }
    let base = shape(linear).and_then(|s| blocks(linear, &s).map(|b| (s, b)));
    for g in guards {
        match packed_from(g) {
            None => {}
            Some(FROM_LINEAR) => {
                let (s, b) = base.as_ref().ok_or_else(|| wrong("against a missing linear ring"))?;
                unpack_map(g, Some((s, b)))?;
            }
            Some(other) => return Err(wrong(&format!("from `{other}`"))),
        }
    }
    Ok(())
}

/// `serialize_with` of [`Certifier`](super::Certifier)'s calibrated state: packed for the
/// binary checkpoint, whole for a human-readable serialiser (JSON).
pub(super) fn serialize<S: Serializer>(
    state: &Option<CalibratedState>,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    let Some(state) = state.as_ref().filter(|_| !serializer.is_human_readable()) else {
        return state.serialize(serializer);
    };
    // The sliding rings left out where the sample trail rebuilds them (`replay.rs`), the
    // rest packed.
    let stripped = state.stripped();
    let mut value =
        Value::serialized(stripped.as_ref().unwrap_or(state)).map_err(S::Error::custom)?;
    pack(&mut value);
    serializer.serialize_some(&value)
}

/// `deserialize_with` of [`Certifier`](super::Certifier)'s calibrated state: the packed rings
/// rebuilt (a binary checkpoint of either version), or the state read directly (JSON).
pub(super) fn deserialize<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<CalibratedState>, D::Error> {
    if deserializer.is_human_readable() {
        return Option::<CalibratedState>::deserialize(deserializer);
    }
    let Some(mut value) = Option::<Value>::deserialize(deserializer)? else { return Ok(None) };
    unpack(&mut value).map_err(D::Error::custom)?;
    value.deserialized().map(Some).map_err(D::Error::custom)
}

#[cfg(test)]
mod tests;
