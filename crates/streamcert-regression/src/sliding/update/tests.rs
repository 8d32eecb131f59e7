//! The scalar path against the general path and the ordered sums.

use crate::{FastPath, InputIntegral, LoopModel, Model, RegressionConfig, SlidingRegression};

/// Every state a fast path writes, as bits.
fn bits(r: &SlidingRegression) -> Vec<u64> {
    let (g, c, s) = r.statistics();
    let ranges = r.ranges().flat_map(|i| [i.lo, i.hi]);
    g.iter()
        .chain(c)
        .chain(s)
        .chain(&r.peaks)
        .chain(&r.col_z)
        .chain(&r.col_dy)
        .chain(&r.hist_z1)
        .chain(&r.dy1)
        .chain(&r.zt)
        .chain(&r.dyt)
        .chain(&r.col_tau)
        .chain(&r.origin)
        .chain([&r.tt])
        .copied()
        .chain(ranges)
        .map(f64::to_bits)
        .collect()
}

/// The scalar path (`push`, `p = m = 1`) promises the general path's arithmetic in the
/// same order: the statistics, the peaks that trigger a recompute, the column and interval
/// rings and the region must agree bit for bit after every sample, through warm-up, a
/// burst that leaves the window (a recompute by the peak check) and periodic refreshes,
/// for both input integrals, both intercept models and every loop model whose shape takes
/// the scalar path.
#[test]
fn the_scalar_push_is_the_general_push_bit_for_bit() {
    let cases = [InputIntegral::Trapezoidal, InputIntegral::ZeroOrderHold]
        .into_iter()
        .flat_map(|i| [(i, Model::Affine), (i, Model::ThroughOrigin)]);
    for (integral, model) in cases {
        for order in LoopModel::ALL.into_iter().filter(|o| o.fast_path(1, 1) == FastPath::Scalar) {
            let mut cfg = RegressionConfig::new(1, 1, 20, 3, 1e-4);
            (cfg.model, cfg.order) = (model, order);
            cfg.refresh_period = 17;
            cfg.input_integral = integral;
            let (mut scalar, mut general) =
                (SlidingRegression::new(cfg).unwrap(), SlidingRegression::new(cfg).unwrap());
            let mut x = 0.3f64;
            for k in 0..400 {
                x = 3.9 * x * (1.0 - x);
                let burst = if (100..104).contains(&k) { 1e5 } else { 1.0 };
                let (t, y, u) = (0.01 * k as f64 + 1e-3 * x, burst * (x - 0.5) + 40.0, 0.7 - x);
                scalar.push(t, &[y], &[u]).unwrap();
                general.push_dims(t, &[y], &[u], 1, 1).unwrap();
                assert_eq!(bits(&scalar), bits(&general), "sample {k}, {integral:?}, {model:?}");
                assert_eq!(scalar.columns(), general.columns());
            }
        }
    }
}

proptest::proptest! {
    /// For every loop model the sliding regression takes: the per-sample path its shape selects (`push`) leaves the
    /// general path's state bit for bit after every sample, on random irregular samples.
    #[test]
    fn every_models_fast_path_is_its_general_path(
        steps in proptest::collection::vec((0.001f64..0.05, -5.0f64..5.0, -5.0f64..5.0), 30..120),
        affine in proptest::bool::ANY,
    ) {
        // The sliding regression's models (order n has its own streaming path, checked
        // against its direct rows in `order_n`).
        for order in LoopModel::ALL.into_iter().filter(|o| o.is_first_order()) {
            let mut cfg = RegressionConfig::new(1, 1, 12, 2, 1e-4);
            cfg.order = order;
            cfg.model = if affine { Model::Affine } else { Model::ThroughOrigin };
            let (mut fast, mut general) =
                (SlidingRegression::new(cfg).unwrap(), SlidingRegression::new(cfg).unwrap());
            let mut t = 0.0;
            for &(dt, y, u) in &steps {
                t += dt;
                fast.push(t, &[y], &[u]).unwrap();
                general.push_dims(t, &[y], &[u], 1, 1).unwrap();
                proptest::prop_assert_eq!(bits(&fast), bits(&general));
            }
        }
    }
}

/// The scalar refresh forms the sums in locals; they must equal, bit for bit, the outer
/// products added in window order (oldest first) as the general path adds them.
#[test]
fn the_scalar_refresh_is_the_ordered_sum() {
    let mut reg = SlidingRegression::new(RegressionConfig::new(1, 1, 40, 3, 1e-4))
        .expect("valid configuration");
    let mut state = 0.3_f64;
    for k in 0..517 {
        state = 0.9 * state + ((k * 7919) % 101) as f64 / 101.0 - 0.5;
        let u = if (k / 13) % 2 == 0 { 1.0 } else { -1.0 };
        reg.push(k as f64 * 0.01, &[state], &[u]).expect("finite sample");
    }
    reg.refresh();
    let mm = reg.cfg.window;
    let start = (reg.col_next + mm - reg.col_len) % mm;
    let (mut g, mut c, mut s) = ([0.0f64; 4], [0.0f64; 2], 0.0f64);
    for k in 0..reg.col_len {
        let q = (start + k) % mm;
        let (z0, z1, dy) = (reg.col_z[2 * q], reg.col_z[2 * q + 1], reg.col_dy[q]);
        g[0] += z0 * z0;
        g[1] += z0 * z1;
        g[3] += z1 * z1;
        c[0] += dy * z0;
        c[1] += dy * z1;
        s += dy * dy;
    }
    for (a, b) in [(reg.g[0], g[0]), (reg.g[1], g[1]), (reg.g[3], g[3])] {
        assert_eq!(a.to_bits(), b.to_bits());
    }
    assert_eq!((reg.c[0].to_bits(), reg.c[1].to_bits()), (c[0].to_bits(), c[1].to_bits()));
    assert_eq!(reg.s[0].to_bits(), s.to_bits());
}
