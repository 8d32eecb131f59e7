//! Span statistics in `O(1)` per query: each complete block's sums and the second moments of
//! its sums, accumulated along the block ring in *segments* (the segment sums), and the first-order estimate that
//! a comparison (not a certificate) needs from them
//! ([`InstrumentedWindows::fresh_estimate`]).
//!
//! The ring's slots are cut into `SEGMENTS` (4) segments of `E = ⌈cap/4⌉` slots. For block
//! `j` let `R_j` be its record: the block's sums `(N_j, Cw_j, H_j)`, the upper triangle of
//! `v_j v_jᵀ` with `v_j = [vec N_j; vec Cw_j]`, and the upper triangle of `h_j h_jᵀ` with `h_j`
//! the upper triangle of `H_j`. Slot `i` of segment `[S₀, S₁)` holds
//!
//! ```text
//! the segment being filled, i < head:   P_i = Σ_{s = S₀..=i} R_s    (a prefix, added to as blocks come)
//! every other slot:                     S_i = Σ_{s = i..S₁} R_s     (a suffix, formed when its segment was filled)
//! ```
//!
//! so that a span of the newest blocks, cut at the segments' bounds, is a sum of at most
//! six pieces, each `P_y − P_{x−1}` or `S_x − S_y` (one subtraction over at most `E`
//! blocks). The rounding error of a span's sums is therefore bounded by a quarter of the
//! ring's magnitude, whatever the length of the run, and no refresh is needed. Every value
//! is a function of the ring's contents and head alone (a prefix of the filled slots of
//! the open segment, a suffix of the later slots of its own segment), so
//! [`InstrumentedWindows::rebuild_moments`] recomputes the same bits after a restore, and
//! the checkpoint need not carry them. (One segment, the whole ring, would make a span one
//! piece, but the block that fills the ring would pay a suffix pass over all of it: the
//! slowest step's share, which a quarter of the ring bounds.)
//!
//! Cost: a block's record is `O((d k + p k)²)` products, about 100 for `p = m = 1` with the
//! intercept (`d = k = 3`), once per block; a segment's suffix pass one record and one
//! addition per value per block, at the block that fills the segment. Memory: one record
//! per block of the longest window.

use super::{InstrumentedWindows, Layout};

/// The per-block records and their segment sums (see the module docs); not serialised. Equal
/// when their segment sums are (the rest is scratch).
#[derive(Debug, Clone, Default)]
pub(super) struct Moments {
    /// Values per record: `stride + nv (nv + 1)/2 + nh (nh + 1)/2`.
    pub(super) len: usize,
    /// `nv = (d + p) k`, the entries of `[vec N_j; vec Cw_j]`.
    pub(super) nv: usize,
    /// `nh = k (k + 1)/2`, the distinct entries of `H_j`.
    pub(super) nh: usize,
    /// Slots per segment `E = ⌈cap / SEGMENTS⌉` (module docs).
    pub(super) segment: usize,
    /// `cap` slots of `len` values: prefixes before the head, suffixes from it.
    pub(super) acc: Vec<f64>,
    /// One record (scratch) and a span's record (scratch).
    pub(super) rec: Vec<f64>,
    pub(super) span: Vec<f64>,
    /// Scratch of the first-order estimate: the score coefficients (`p² × nv`),
    /// `X = Q A⁻¹ T` read as `k × p`, and the weights of `h` (`nh`).
    pub(super) coef: Vec<f64>,
    pub(super) xt: Vec<f64>,
    pub(super) wh: Vec<f64>,
}

impl PartialEq for Moments {
    fn eq(&self, other: &Self) -> bool {
        self.len == other.len && self.acc == other.acc
    }
}

/// Index of the upper-triangle entry `(a, b)`, `a <= b < n`, stored row by row.
#[inline(always)]
pub(super) fn upper(a: usize, b: usize, n: usize) -> usize {
    a * n - a * (a + 1) / 2 + b
}

/// Segments of the ring (module docs): a segment's suffix pass is the slowest step's share
/// (a quarter of the ring's blocks), and a span is at most `SEGMENTS + 1` pieces per run.
const SEGMENTS: usize = 4;

/// The largest `(d + p) k` (entries of a block's `[vec N_j; vec Cw_j]`) for which
/// [`InstrumentedWindows::with_moments`] keeps the segment sums: 24 covers one or two outputs
/// and inputs with the intercept and `J = 1` (a record of at most 21 + 300 + 55 values).
pub const MAX_MOMENT_ENTRIES: usize = 24;

impl Moments {
    fn new(lay: Layout, cap: usize) -> Self {
        let (nv, nh) = ((lay.d + lay.p) * lay.k, lay.k * (lay.k + 1) / 2);
        let len = lay.stride() + nv * (nv + 1) / 2 + nh * (nh + 1) / 2;
        let pp = lay.p * lay.p;
        Self {
            len,
            nv,
            nh,
            segment: cap.div_ceil(SEGMENTS).max(1),
            acc: vec![0.0; cap * len],
            rec: vec![0.0; len],
            span: vec![0.0; len],
            coef: vec![0.0; pp * nv],
            xt: vec![0.0; lay.k * lay.p],
            wh: vec![0.0; nh],
        }
    }

    /// Forget every segment sum (a reset: the ring's blocks are no longer live).
    pub(super) fn clear(&mut self) {
        self.acc.fill(0.0);
    }

    /// Block `blk`'s record into `out`, for the layout `(p, d, k)` (literal at the callers
    /// that dispatch on the common shapes, so that the compiler unrolls the products).
    #[inline(always)]
    fn record(&self, (p, d, k): (usize, usize, usize), blk: &[f64], out: &mut [f64]) {
        let lay = Layout { p, d, k };
        let stride = lay.stride();
        let (nv, nh) = ((d + p) * k, k * (k + 1) / 2);
        debug_assert_eq!((nv, nh), (self.nv, self.nh));
        out[..stride].copy_from_slice(&blk[..stride]);
        let v = &blk[..nv];
        let mut at = stride;
        for a in 0..nv {
            for b in a..nv {
                out[at] = v[a] * v[b];
                at += 1;
            }
        }
        // The distinct entries of `H_j`, its upper triangle row by row.
        let h = &blk[lay.h()..stride];
        let mut hd = [0.0f64; MAX_DISTINCT_H];
        let mut c = 0;
        for a in 0..k {
            for b in a..k {
                hd[c] = h[a * k + b];
                c += 1;
            }
        }
        for a in 0..nh {
            let ha = hd[a];
            for &hb in &hd[a..nh] {
                out[at] = ha * hb;
                at += 1;
            }
        }
    }
}

/// The most distinct entries of a block's `H` that [`Moments`] keeps: `k (k + 1)/2` for the
/// largest `k` that [`MAX_MOMENT_ENTRIES`] admits (`(d + p) k <= 24` with `d + p >= 2`).
const MAX_DISTINCT_H: usize = 12 * 13 / 2;

/// `f(dims)` with the dimensions `(p, d, k)` literal for the single-output shapes through the
/// origin and with the intercept (the same operations in the same order: the same bits).
macro_rules! with_dims {
    ($lay:expr, $f:expr) => {
        match ($lay.p, $lay.d, $lay.k) {
            (1, 2, 2) => $f((1, 2, 2)),
            (1, 3, 3) => $f((1, 3, 3)),
            dims => $f(dims),
        }
    };
}

impl InstrumentedWindows {
    /// Keep the segment sums of [`fresh_estimate`](Self::fresh_estimate) (module docs): one
    /// record per block of the longest window, about `(d + p)² k²/2` values each. Kept only
    /// where `(d + p) k <= `[`MAX_MOMENT_ENTRIES`] (the record's size grows with its square);
    /// wider windows take the pass over the blocks.
    #[must_use]
    pub fn with_moments(mut self) -> Self {
        self.keep_moments();
        self
    }

    /// [`with_moments`](Self::with_moments) in place, on a state that may already hold
    /// blocks (a restored one): the segment sums are computed from the block ring, the same bits
    /// as if they had been kept all along (module docs).
    pub fn keep_moments(&mut self) {
        let lay = self.layout();
        if (lay.d + lay.p) * lay.k > MAX_MOMENT_ENTRIES {
            return;
        }
        self.moments = Some(Moments::new(lay, self.block_cap()));
        self.rebuild_moments();
    }

    /// Whether the segment sums are kept ([`with_moments`](Self::with_moments)).
    #[must_use]
    pub fn has_moments(&self) -> bool {
        self.moments.is_some()
    }

    /// Recompute the segment sums from the block ring (after a restore: the same bits as the
    /// uninterrupted run, module docs); a no-op without [`with_moments`](Self::with_moments).
    pub fn rebuild_moments(&mut self) {
        let Some(mut mo) = self.moments.take() else { return };
        let (cap, head) = (self.block_cap(), self.block_head);
        let wrapped = self.block_len == cap;
        let seg = mo.segment;
        let mut start = 0;
        while start < cap {
            let end = (start + seg).min(cap);
            if (start..end).contains(&head) && head > start {
                // The open segment: a prefix before the head, the last pass's suffix after.
                self.prefix_run(&mut mo, start, start, head);
                if wrapped {
                    self.suffix_run(&mut mo, head, end);
                }
            } else if end <= head || wrapped {
                self.suffix_run(&mut mo, start, end);
            }
            start = end;
        }
        self.moments = Some(mo);
    }

    /// Slots `from..to` of the segment starting at `start` as prefixes from `start` (the
    /// slots `start..from` already hold theirs).
    fn prefix_run(&self, mo: &mut Moments, start: usize, from: usize, to: usize) {
        with_dims!(self.layout(), |dims| self.prefix_dims(mo, start, from, to, dims));
    }

    /// [`prefix_run`](Self::prefix_run) with the dimensions passed in.
    #[inline(always)]
    fn prefix_dims(
        &self,
        mo: &mut Moments,
        start: usize,
        from: usize,
        to: usize,
        dims: (usize, usize, usize),
    ) {
        let len = mo.len;
        let stride = Layout { p: dims.0, d: dims.1, k: dims.2 }.stride();
        let mut rec = std::mem::take(&mut mo.rec);
        for i in from..to {
            mo.record(dims, &self.blocks[i * stride..(i + 1) * stride], &mut rec);
            if i == start {
                mo.acc[i * len..(i + 1) * len].copy_from_slice(&rec);
            } else {
                let (before, here) = mo.acc.split_at_mut(i * len);
                let prev = &before[(i - 1) * len..];
                for ((o, p), r) in here[..len].iter_mut().zip(prev).zip(&rec) {
                    *o = p + r;
                }
            }
        }
        mo.rec = rec;
    }

    /// Slots `from..to` (a segment's last slots, `to` its end) as suffixes to `to`, from the
    /// last slot down.
    fn suffix_run(&self, mo: &mut Moments, from: usize, to: usize) {
        with_dims!(self.layout(), |dims| self.suffix_dims(mo, from, to, dims));
    }

    /// [`suffix_run`](Self::suffix_run) with the dimensions passed in.
    #[inline(always)]
    fn suffix_dims(&self, mo: &mut Moments, from: usize, to: usize, dims: (usize, usize, usize)) {
        let len = mo.len;
        let stride = Layout { p: dims.0, d: dims.1, k: dims.2 }.stride();
        let mut rec = std::mem::take(&mut mo.rec);
        for i in (from..to).rev() {
            mo.record(dims, &self.blocks[i * stride..(i + 1) * stride], &mut rec);
            if i + 1 == to {
                mo.acc[i * len..(i + 1) * len].copy_from_slice(&rec);
            } else {
                let (here, after) = mo.acc[i * len..].split_at_mut(len);
                for ((o, n), r) in here.iter_mut().zip(&after[..len]).zip(&rec) {
                    *o = r + n;
                }
            }
        }
        mo.rec = rec;
    }

    /// Add the block just written to slot `b` to the segment sums (called before the head
    /// moves on); where it ends its segment, turn the segment into suffixes (`O(E)` blocks,
    /// `E` a quarter of the ring: the slowest step's share).
    pub(super) fn moments_push(&mut self, b: usize) {
        let Some(mut mo) = self.moments.take() else { return };
        let cap = self.block_cap();
        let start = b - b % mo.segment;
        let end = (start + mo.segment).min(cap);
        if b + 1 == end {
            self.suffix_run(&mut mo, start, end);
        } else {
            // The prefix from the segment's start: one record added to the slot before.
            self.prefix_run(&mut mo, start, b, b + 1);
        }
        self.moments = Some(mo);
    }

    /// The first `width` values of the record of the blocks `span` selects (see
    /// `span_blocks`) into `out`, from the segment sums: the span's one or two runs of slots,
    /// each cut at the segments' bounds, each piece one prefix or suffix difference.
    pub(super) fn segment_span(
        &self,
        mo: &Moments,
        (count, skip): (usize, usize),
        width: usize,
        out: &mut [f64],
    ) {
        let (cap, head) = (self.block_cap(), self.block_head);
        let skip = skip.min(count);
        let count = count - skip;
        let out = &mut out[..width];
        out.fill(0.0);
        if count == 0 {
            return;
        }
        let end = (head + cap - skip) % cap;
        if count <= end {
            self.add_run(mo, end - count, end, width, out);
        } else {
            // The span wraps: its older run to the ring's end, then its newer run.
            self.add_run(mo, cap - (count - end), cap, width, out);
            self.add_run(mo, 0, end, width, out);
        }
    }

    /// Add the record of the ring's slots `from..to` (all before the head, or all from it).
    fn add_run(&self, mo: &Moments, from: usize, to: usize, width: usize, out: &mut [f64]) {
        let (cap, head, len, seg) = (self.block_cap(), self.block_head, mo.len, mo.segment);
        let slot = |i: usize| &mo.acc[i * len..i * len + width];
        let mut x = from;
        while x < to {
            let start = x - x % seg;
            let stop = (start + seg).min(cap);
            let y = to.min(stop);
            if (start..stop).contains(&head) && x < head {
                // The open segment's prefix: P_{y−1} − P_{x−1}.
                for (o, v) in out.iter_mut().zip(slot(y - 1)) {
                    *o += v;
                }
                if x > start {
                    for (o, v) in out.iter_mut().zip(slot(x - 1)) {
                        *o -= v;
                    }
                }
            } else {
                // A suffix within a completed segment: S_x − S_y.
                for (o, v) in out.iter_mut().zip(slot(x)) {
                    *o += v;
                }
                if y < stop {
                    for (o, v) in out.iter_mut().zip(slot(y)) {
                        *o -= v;
                    }
                }
            }
            x = y;
        }
    }

    /// The sums of the blocks `span` selects, from the segment sums ([`with_moments`]); `false`
    /// without them. For tests against [`window_sums`](Self::window_sums).
    ///
    /// [`with_moments`]: Self::with_moments
    pub fn span_sums_from_moments(&self, w: usize, skip: usize, out: &mut [f64]) -> bool {
        let Some(mo) = &self.moments else { return false };
        self.segment_span(mo, self.span(w, skip), self.layout().stride(), out);
        true
    }
}
