//! [`SampleTrail`]: the newest samples the regression absorbed, as many as the calibrated
//! windows' block rings are formed from, so that a checkpoint can carry the samples instead of
//! the block sums (`replay.rs`).
//!
//! For the default certifier (`p = m = 1`, `h = 5`, the longest window `16 M = 2 400` columns)
//! that is 2 420 samples of `(t, y, u)`: 58 KB in memory, about 41 KB in a checkpoint (the
//! times packed, [`pack_rows`]), against about 220 KB of block sums in three rings.

use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeStruct, Serializer};
use serde::{Deserialize, Serialize};
use streamcert_regression::{RegressionConfig, SlidingRegression};

/// A ring of the newest `cap` samples `(t, y, u)` (`1 + p + m` values each), and what a replay
/// of them needs besides: the regression's configuration and working origin (not written, set
/// from the regression on restore).
///
/// Serialised as `{width, cap, rows}`, `rows` the held samples oldest first: the bytes of
/// [`pack_rows`] in a binary encoding, numbers in a human-readable one. A deserialised trail
/// holds only its rows until [`settle`](Self::settle) has checked its shape against the
/// configuration and sized its ring (so a damaged file's `cap` allocates nothing).
#[derive(Debug, Clone)]
pub(crate) struct SampleTrail {
    width: usize,
    cap: usize,
    /// A ring of `cap` rows whose next slot is `head`.
    data: Vec<f64>,
    head: usize,
    len: usize,
    /// The newest held time (`−∞` when none): a step that absorbed no sample repeats it.
    last: f64,
    source: Option<(RegressionConfig, Vec<f64>)>,
}

impl PartialEq for SampleTrail {
    /// The same samples, oldest first, bit for bit (where the ring starts aside).
    fn eq(&self, other: &Self) -> bool {
        (self.width, self.cap, self.len) == (other.width, other.cap, other.len)
            && self
                .rows(self.len)
                .zip(other.rows(other.len))
                .all(|(a, b)| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()))
    }
}

impl SampleTrail {
    /// An empty trail of `cap` samples of the regression configured by `reg`.
    pub(crate) fn new(reg: &RegressionConfig, cap: usize) -> Self {
        let width = 1 + reg.outputs + reg.inputs;
        Self {
            width,
            cap,
            data: vec![0.0; cap * width],
            head: 0,
            len: 0,
            last: f64::NEG_INFINITY,
            source: Some((*reg, Vec::with_capacity(reg.outputs + reg.inputs))),
        }
    }

    /// The samples held.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Take `reg`'s newest sample if it is later than the newest held (a step that absorbed
    /// none leaves the trail as it was). `O(p + m)`, no allocation.
    #[inline]
    pub(crate) fn record(&mut self, reg: &SlidingRegression) {
        let Some((t, y, u)) = reg.newest_sample() else { return };
        // `!(t > last)`: also a NaN time, which the regression never absorbs.
        if !(t > self.last) {
            return;
        }
        if self.source.as_ref().is_some_and(|(_, o)| o.is_empty()) {
            self.take_origin(reg);
        }
        let (w, at) = (self.width, self.head * self.width);
        if let (&[y], &[u], Some(row)) = (y, u, self.data.get_mut(at..at + 3)) {
            // One output and one input (the common loop): three stores.
            row.copy_from_slice(&[t, y, u]);
        } else if let Some(row) = self.data.get_mut(at..at + w) {
            row[0] = t;
            for (o, v) in row[1..].iter_mut().zip(y.iter().chain(u)) {
                *o = *v;
            }
        }
        self.last = t;
        self.head = if self.head + 1 == self.cap { 0 } else { self.head + 1 };
        if self.len < self.cap {
            self.len += 1;
        }
    }

    /// The regression's working origin, at the first sample recorded (the origin is set then
    /// and kept).
    #[cold]
    fn take_origin(&mut self, reg: &SlidingRegression) {
        if let Some((_, origin)) = &mut self.source {
            origin.extend_from_slice(reg.origin());
        }
    }

    /// The newest `n` samples (at most [`len`](Self::len)), oldest first, each `[t, y…, u…]`.
    pub(crate) fn rows(&self, n: usize) -> impl Iterator<Item = &[f64]> + Clone {
        let n = n.min(self.len);
        (0..n).map(move |i| {
            let slot = (self.head + self.cap - n + i) % self.cap;
            &self.data[slot * self.width..(slot + 1) * self.width]
        })
    }

    /// The regression's configuration and working origin a replay starts from (`None` after a
    /// restore until [`set_source`](Self::set_source)).
    pub(crate) fn source(&self) -> Option<(&RegressionConfig, &[f64])> {
        self.source.as_ref().map(|(c, o)| (c, &o[..]))
    }

    /// After a restore: `false` unless the trail's shape fits `reg`'s configuration and `cap`
    /// samples; then its ring sized to `cap` (a deserialised trail holds only its rows) and
    /// the replay's source set from `reg` (its working origin once it has absorbed a sample,
    /// else taken at the first sample recorded).
    pub(crate) fn settle(&mut self, reg: &SlidingRegression, cap: usize) -> bool {
        let cfg = reg.config();
        let rows_only = self.data.len() == self.len * self.width;
        let shape_ok = self.width == 1 + cfg.outputs + cfg.inputs
            && self.cap == cap
            && self.len <= cap
            && (rows_only || self.data.len() == cap * self.width)
            && self.data.iter().all(|v| v.is_finite());
        if !shape_ok {
            return false;
        }
        if rows_only {
            self.data.resize(cap * self.width, 0.0);
            self.head = self.len % cap;
        }
        let mut origin = Vec::with_capacity(cfg.outputs + cfg.inputs);
        if reg.columns_built() > 0 || reg.newest_sample().is_some() {
            origin.extend_from_slice(reg.origin());
        }
        self.source = Some((*cfg, origin));
        true
    }

    /// `true` when the trail's shape fits `reg` and `cap` (a restored state's check).
    pub(crate) fn fits(&self, reg: &RegressionConfig, cap: usize) -> bool {
        self.width == 1 + reg.outputs + reg.inputs
            && self.cap == cap
            && self.data.len() == cap * self.width
            && self.len <= cap
            && self.data.iter().all(|v| v.is_finite())
    }
}

/// The held rows, oldest first: numbers in a human-readable encoding, else the bytes of
/// [`pack_rows`].
struct Rows<'a>(&'a SampleTrail);

impl Serialize for Rows<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let t = self.0;
        if s.is_human_readable() {
            return s.collect_seq(t.rows(t.len).flatten().copied());
        }
        s.serialize_bytes(&pack_rows(t.rows(t.len), t.len, t.width))
    }
}

impl Serialize for SampleTrail {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("SampleTrail", 3)?;
        st.serialize_field("width", &self.width)?;
        st.serialize_field("cap", &self.cap)?;
        st.serialize_field("rows", &Rows(self))?;
        st.end()
    }
}

/// `v` as a LEB128 varint.
fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8 & 0x7f) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// The varint at the start of `bytes`, and the bytes after it.
fn take_varint(bytes: &[u8]) -> Option<(u64, &[u8])> {
    let mut v = 0u64;
    for (i, &b) in bytes.iter().enumerate().take(10) {
        v |= u64::from(b & 0x7f) << (7 * i);
        if b & 0x80 == 0 {
            return Some((v, &bytes[i + 1..]));
        }
    }
    None
}

/// The prediction of the next time's bit pattern from the two before: `2 b₁ − b₀`, exact
/// for times on a regular grid within a binade (wrapping: any bits round-trip).
fn predicted(b0: u64, b1: u64) -> u64 {
    b1.wrapping_mul(2).wrapping_sub(b0)
}

/// The rows of `width` values (`n` of them) as bytes, every bit kept:
///
/// ```text
/// varint n
/// n varints: each time's bit pattern less its prediction from the two before (zig-zag)
/// n (width − 1) little-endian f64: the outputs and inputs, row by row
/// ```
///
/// A regular sampling grid then costs about one byte a time instead of eight (the outputs
/// and inputs, noisy, are kept raw).
fn pack_rows<'a>(rows: impl Iterator<Item = &'a [f64]> + Clone, n: usize, width: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(10 + n * (2 + 8 * (width - 1)));
    put_varint(&mut out, n as u64);
    let (mut b0, mut b1) = (0u64, 0u64);
    for row in rows.clone() {
        let b = row[0].to_bits();
        let r = b.wrapping_sub(predicted(b0, b1)) as i64;
        put_varint(&mut out, ((r << 1) ^ (r >> 63)) as u64);
        (b0, b1) = (b1, b);
    }
    for row in rows {
        for v in &row[1..] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// The rows [`pack_rows`] wrote, `width` values each; `None` for bytes of another shape.
fn unpack_rows(bytes: &[u8], width: usize) -> Option<Vec<f64>> {
    let (n, mut rest) = take_varint(bytes)?;
    let n = usize::try_from(n).ok()?;
    // Every row takes at least one byte and `8 (width − 1)` more: what the bytes cannot hold
    // is refused before anything is allocated.
    let raw = n.checked_mul(width.checked_sub(1)?)?.checked_mul(8)?;
    if n > bytes.len() || raw > bytes.len() {
        return None;
    }
    let mut out = vec![0.0; n.checked_mul(width)?];
    let (mut b0, mut b1) = (0u64, 0u64);
    for row in out.chunks_exact_mut(width) {
        let (z, after) = take_varint(rest)?;
        rest = after;
        let r = ((z >> 1) as i64) ^ -((z & 1) as i64);
        let b = predicted(b0, b1).wrapping_add(r as u64);
        row[0] = f64::from_bits(b);
        (b0, b1) = (b1, b);
    }
    if rest.len() != n * (width - 1) * 8 {
        return None;
    }
    let mut values =
        rest.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])));
    for row in out.chunks_exact_mut(width) {
        for v in &mut row[1..] {
            *v = values.next()?;
        }
    }
    Some(out)
}

/// The rows read back: the bytes of [`pack_rows`] (binary) or numbers (human-readable).
enum RowsIn {
    Bytes(Vec<u8>),
    Values(Vec<f64>),
}

impl<'de> Deserialize<'de> for RowsIn {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = RowsIn;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("the trail's samples as bytes or numbers")
            }
            fn visit_bytes<E: de::Error>(self, b: &[u8]) -> Result<RowsIn, E> {
                Ok(RowsIn::Bytes(b.to_vec()))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<RowsIn, A::Error> {
                let mut out = Vec::new();
                while let Some(v) = seq.next_element::<f64>()? {
                    out.push(v);
                }
                Ok(RowsIn::Values(out))
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Deserialize)]
struct TrailIn {
    width: usize,
    cap: usize,
    rows: RowsIn,
}

impl<'de> Deserialize<'de> for SampleTrail {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let TrailIn { width, cap, rows } = TrailIn::deserialize(d)?;
        let bad = || de::Error::custom("the checkpoint's sample trail does not fit its shape");
        let data = match rows {
            RowsIn::Values(v) => v,
            RowsIn::Bytes(b) => unpack_rows(&b, width).ok_or_else(bad)?,
        };
        if width == 0 || cap == 0 || data.len() % width != 0 || data.len() / width > cap {
            return Err(bad());
        }
        let len = data.len() / width;
        let last = if len == 0 { f64::NEG_INFINITY } else { data[(len - 1) * width] };
        // The ring is sized by `settle`, against the configuration.
        Ok(Self { width, cap, data, head: len % cap, len, last, source: None })
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::{pack_rows, unpack_rows};

    proptest! {
        /// Oracle: the rows as given. Every bit pattern round-trips (NaN payloads, signed
        /// zeros, infinities, times in any order), whatever the times' spacing.
        #[test]
        fn packed_rows_round_trip_bit_for_bit(
            bits in proptest::collection::vec(any::<u64>(), 0..200),
            width in 1usize..5,
        ) {
            let n = bits.len() / width;
            let values: Vec<f64> = bits[..n * width].iter().map(|&b| f64::from_bits(b)).collect();
            let bytes = pack_rows(values.chunks_exact(width), n, width);
            let back = unpack_rows(&bytes, width).expect("unpacks");
            prop_assert_eq!(
                back.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
            // Cut short or padded, the bytes are refused.
            if !bytes.is_empty() {
                prop_assert!(unpack_rows(&bytes[..bytes.len() - 1], width).is_none());
            }
            let mut longer = bytes.clone();
            longer.push(0);
            prop_assert!(unpack_rows(&longer, width).is_none());
        }

        /// Bytes that claim more rows or wider rows than they hold are refused before anything
        /// is allocated (a hostile file cannot ask for a large buffer).
        #[test]
        fn bytes_claiming_more_than_they_hold_are_refused(
            n in 1u64..u64::MAX,
            width in 2usize..usize::MAX,
        ) {
            let mut bytes = Vec::new();
            super::put_varint(&mut bytes, n);
            bytes.extend_from_slice(&[0; 16]);
            prop_assume!(n > 17 || (width - 1).saturating_mul(8) > 17);
            prop_assert!(unpack_rows(&bytes, width).is_none());
        }

        /// Times on a regular grid (as parsed from decimal text: `k dt` rounded) cost at most
        /// two bytes each; the outputs and inputs eight.
        #[test]
        fn a_regular_grid_costs_two_bytes_a_time_at_most(
            dt in prop::sample::select(vec![0.001, 0.01, 0.02, 0.1, 0.25]),
            start in 0u32..100_000,
        ) {
            let rows: Vec<[f64; 3]> = (0..2000u32)
                .map(|k| [f64::from(start + k) * dt, 0.5, -0.5])
                .collect();
            let bytes = pack_rows(rows.iter().map(|r| &r[..]), rows.len(), 3);
            prop_assert!(bytes.len() <= 3 + 2000 * (2 + 16), "{} bytes", bytes.len());
        }
    }
}
