//! Where a look's fits come from: the kept rows and units of an
//! [`OrderNWindow`](streamcert_regression::OrderNWindow) when the window's samples are
//! equally spaced, else the window's samples alone
//! ([`OrderNRecord`](streamcert_regression::OrderNRecord)). Both are the same estimate; the
//! first does not repeat what earlier looks computed.

use streamcert_regression::{
    OrderNConfig, OrderNFit, OrderNRecord, OrderNWindow, RegressionError, RegressorTest, WindowLook,
};

/// A look's fits.
pub(super) enum Fits<'a> {
    /// Boxed: a look's kept state is several times the size of a record's handle.
    Window(Box<WindowLook<'a>>),
    Record(OrderNRecord),
}

impl<'a> Fits<'a> {
    /// The fits of the window `t`, `y`, `u`, whose first sample is the `first`-th since the
    /// start or the last reset.
    pub(super) fn new(
        kept: &'a mut Kept,
        cfg: &OrderNConfig,
        first: u64,
        t: &[f64],
        y: &[f64],
        u: &[f64],
    ) -> Result<Self, RegressionError> {
        if kept.0.is_none() {
            kept.0 = OrderNWindow::new(cfg).ok();
        }
        if let Some(look) = kept.0.as_mut().and_then(|w| w.prepare(first, t, y, u)) {
            return Ok(Self::Window(Box::new(look)));
        }
        OrderNRecord::new(cfg, t, y, u).map(Self::Record)
    }

    /// The window's fit.
    pub(super) fn fit(&mut self) -> Result<OrderNFit, RegressionError> {
        match self {
            Self::Window(look) => look.fit(),
            Self::Record(record) => record.fit(0..record.rows()),
        }
    }

    /// The hidden-dynamics guard's test.
    pub(super) fn past_row_test(&mut self) -> Result<RegressorTest, RegressionError> {
        match self {
            Self::Window(look) => look.past_row_test(),
            Self::Record(record) => record.past_row_test(0..record.rows()),
        }
    }

    /// The nonlinearity guard's test.
    pub(super) fn curvature_test(&mut self) -> Result<RegressorTest, RegressionError> {
        match self {
            Self::Window(look) => look.curvature_test(),
            Self::Record(record) => record.curvature_test(0..record.rows()),
        }
    }
}

/// The rows and units kept across looks. A look's answer does not depend on them (they are
/// functions of the samples they were computed from), so they are not part of a checkpoint
/// and take no part in equality: a restored certificate computes them again from its window.
#[derive(Clone, Default)]
pub(super) struct Kept(pub(super) Option<OrderNWindow>);

impl PartialEq for Kept {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for Kept {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Kept")
    }
}

impl Kept {
    /// Forget everything kept (after a gap: the samples' count starts again).
    pub(super) fn clear(&mut self) {
        if let Some(window) = self.0.as_mut() {
            window.clear();
        }
    }
}
