//! The feature library of the nonlinear certificate: named functions of the output with their
//! derivatives and rigorous bounds of the derivatives over an interval.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One feature `φ(y)` of the drift model `ẏ = Σ_k θ_k φ_k(y) + B u`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feature {
    /// `y^k`, `1 <= k <= 8` (written `y`, `y^2`, …).
    Power(u8),
    /// `tanh(y)`.
    Tanh,
    /// `y·tanh(y)` (written `y*tanh(y)`; G5's node 1 has the drift `−x1 tanh x1`).
    YTanh,
}

/// Where `y·tanh(y)` has its extreme slopes: `d/dy (tanh y + y sech² y) = 2 sech² y (1 − y tanh y)`
/// vanishes at `y tanh y = 1`.
const YTANH_TURN: f64 = 1.199_678_640_257_734;

impl Feature {
    /// `φ(y)`.
    #[must_use]
    pub fn value(self, y: f64) -> f64 {
        match self {
            Self::Power(k) => y.powi(i32::from(k)),
            Self::Tanh => y.tanh(),
            Self::YTanh => y * y.tanh(),
        }
    }

    /// `φ'(y)`.
    #[must_use]
    pub fn slope(self, y: f64) -> f64 {
        match self {
            Self::Power(k) => f64::from(k) * y.powi(i32::from(k) - 1),
            Self::Tanh => {
                let t = y.tanh();
                1.0 - t * t
            }
            Self::YTanh => {
                let t = y.tanh();
                t + y * (1.0 - t * t)
            }
        }
    }

    /// Bounds of `φ'` over `[a, b]`: the slope at the ends and at the interior points where it
    /// turns (for `y^k`: `0`; `tanh`: `0`; `y tanh y`: `±1.1997`), so the bounds are exact up
    /// to rounding (each piece between turning points is monotone).
    #[must_use]
    pub fn slope_bounds(self, a: f64, b: f64) -> (f64, f64) {
        let turns: &[f64] = match self {
            Self::Power(_) | Self::Tanh => &[0.0],
            Self::YTanh => &[-YTANH_TURN, 0.0, YTANH_TURN],
        };
        let (mut lo, mut hi) = (self.slope(a).min(self.slope(b)), self.slope(a).max(self.slope(b)));
        for &x in turns {
            if a < x && x < b {
                let s = self.slope(x);
                lo = lo.min(s);
                hi = hi.max(s);
            }
        }
        (lo, hi)
    }

    /// The name used in configuration files.
    #[must_use]
    pub fn name(self) -> String {
        match self {
            Self::Power(1) => "y".into(),
            Self::Power(k) => format!("y^{k}"),
            Self::Tanh => "tanh(y)".into(),
            Self::YTanh => "y*tanh(y)".into(),
        }
    }

    /// Parse a name (`y`, `y^2` … `y^8`, `tanh(y)`, `y*tanh(y)`; spaces ignored).
    #[must_use]
    pub fn parse(name: &str) -> Option<Self> {
        let n: String = name.chars().filter(|c| !c.is_whitespace()).collect();
        match n.as_str() {
            "y" => Some(Self::Power(1)),
            "tanh(y)" => Some(Self::Tanh),
            "y*tanh(y)" => Some(Self::YTanh),
            _ => {
                let k: u8 = n.strip_prefix("y^")?.parse().ok()?;
                (1..=8).contains(&k).then_some(Self::Power(k))
            }
        }
    }
}

/// A feature library: at most [`FeatureSet::CAPACITY`] distinct features, the first of which is
/// `y` (its integral is the regression's own `∫y`). Serialised as the list of names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FeatureSet {
    len: u8,
    items: [Feature; FeatureSet::CAPACITY],
}

impl FeatureSet {
    /// Most features in a library (the bound over a cell visits `2^D` corners).
    pub const CAPACITY: usize = 5;

    /// The polynomial library `y, y², …, y^D` with `D = degree` clamped to
    /// `1..=CAPACITY` ([`NonlinearConfig::validate`](super::NonlinearConfig::validate) refuses a
    /// degree outside it before any library is built).
    #[must_use]
    pub fn polynomial(degree: usize) -> Self {
        let len = degree.clamp(1, Self::CAPACITY);
        let mut items = [Feature::Power(1); Self::CAPACITY];
        // Slots past `len` stay `y`, as in every other library, so that equality is equality
        // of the lists.
        for (k, item) in items.iter_mut().enumerate().take(len) {
            *item = Feature::Power(k as u8 + 1);
        }
        Self { len: len as u8, items }
    }

    /// A library from names; the message says what is valid.
    ///
    /// # Errors
    /// An unknown name, a repeat, more than `CAPACITY` features, or a first feature other
    /// than `y`.
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Result<Self, String> {
        let mut set = Self { len: 0, items: [Feature::Power(1); Self::CAPACITY] };
        for name in names {
            let name = name.as_ref();
            let f = Feature::parse(name).ok_or_else(|| {
                format!("unknown feature `{name}` (known: y, y^2 … y^8, tanh(y), y*tanh(y))")
            })?;
            if set.iter().any(|g| g == f) {
                return Err(format!("feature `{name}` is listed twice"));
            }
            if usize::from(set.len) == Self::CAPACITY {
                return Err(format!("at most {} features", Self::CAPACITY));
            }
            set.items[usize::from(set.len)] = f;
            set.len += 1;
        }
        if set.items[0] != Feature::Power(1) || set.len == 0 {
            return Err("the feature list must start with `y`".into());
        }
        Ok(set)
    }

    /// The number of features.
    #[must_use]
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// `true` for no feature (never for a validated library).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The features in order.
    pub fn iter(&self) -> impl Iterator<Item = Feature> + '_ {
        self.items[..self.len()].iter().copied()
    }

    /// Feature `k`.
    #[must_use]
    pub fn get(&self, k: usize) -> Feature {
        self.items[k]
    }

    /// `true` when the library is `y, y², …, y^D` (the certificate then bounds polynomials).
    #[must_use]
    pub fn is_polynomial(&self) -> bool {
        self.iter().enumerate().all(|(k, f)| f == Feature::Power(k as u8 + 1))
    }
}

impl Serialize for FeatureSet {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(self.iter().map(Feature::name))
    }
}

impl<'de> Deserialize<'de> for FeatureSet {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let names = Vec::<String>::deserialize(deserializer)?;
        Self::from_names(&names).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slopes_match_finite_differences_and_bounds_contain_a_scan() {
        for f in
            [Feature::Power(1), Feature::Power(2), Feature::Power(3), Feature::Tanh, Feature::YTanh]
        {
            for y in [-2.0, -1.2, -0.3, 0.0, 0.7, 1.9] {
                let h = 1e-6;
                let fd = (f.value(y + h) - f.value(y - h)) / (2.0 * h);
                assert!((fd - f.slope(y)).abs() < 1e-6, "{f:?} at {y}");
            }
            for (a, b) in [(-2.0, 2.0), (-1.5, -1.0), (0.3, 0.4), (1.0, 1.4)] {
                let (lo, hi) = f.slope_bounds(a, b);
                for i in 0..=1000 {
                    let s = f.slope(a + (b - a) * f64::from(i) / 1000.0);
                    assert!(s >= lo - 1e-12 && s <= hi + 1e-12, "{f:?} on [{a}, {b}]");
                }
            }
        }
        // The turning point of y tanh y's slope.
        let t = YTANH_TURN;
        assert!((t * t.tanh() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn libraries_parse_and_refuse_what_is_not_valid() {
        let set = FeatureSet::from_names(&["y", "y * tanh(y)"]).unwrap();
        assert_eq!(set.len(), 2);
        assert!(!set.is_polynomial());
        let cubic = FeatureSet::polynomial(3);
        assert!(cubic.is_polynomial() && cubic.len() == 3);
        assert_eq!(cubic, FeatureSet::from_names(&["y", "y^2", "y^3"]).unwrap());
        assert!(FeatureSet::from_names(&["tanh(y)"]).unwrap_err().contains("start with `y`"));
        assert!(FeatureSet::from_names(&["y", "y"]).unwrap_err().contains("twice"));
        assert!(FeatureSet::from_names(&["y", "exp(y)"]).unwrap_err().contains("unknown"));
        let json = serde_json::to_string(&set).unwrap();
        assert_eq!(json, r#"["y","y*tanh(y)"]"#);
        assert_eq!(serde_json::from_str::<FeatureSet>(&json).unwrap(), set);
    }
}
