//! The `[nonlinear]` section: the feature library, the region rule and the settings of the
//! nonlinear certificate.

use serde::Deserialize;
use streamcert_certificate::{FeatureSet, NonlinearConfig, RegionBound, RiskSplit};

/// The feature library of `[nonlinear]`: `"polynomial"` (with `degree`) or a list of named
/// features starting with `"y"`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
enum Features {
    /// `"polynomial"`.
    Library(String),
    /// Named features, for example `["y", "y*tanh(y)"]`.
    Named(Vec<String>),
}

impl Default for Features {
    fn default() -> Self {
        Self::Library("polynomial".into())
    }
}

/// The region rules of `[nonlinear]`: the quantiles of the visited outputs (trimmed by
/// `region_trim`, [`NonlinearConfig::region_trim`]) or their whole range.
#[derive(Debug, Default, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
enum RegionRule {
    #[default]
    Quantiles,
    BoundingBox,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct NonlinearSection {
    #[serde(default)]
    enabled: bool,
    #[serde(default)]
    features: Features,
    #[serde(default)]
    degree: Option<usize>,
    #[serde(default)]
    region: RegionRule,
    #[serde(default)]
    region_trim: Option<f64>,
    #[serde(default)]
    cells: Option<usize>,
    #[serde(default)]
    check_terms: Option<usize>,
    #[serde(default)]
    test_risk: Option<f64>,
    #[serde(default)]
    bound: RegionBound,
    #[serde(default)]
    risk_split: Option<RiskSplit>,
}

impl NonlinearSection {
    /// The region's trim: `region_trim` (default 0.025) for the quantile region, 0 for the
    /// bounding box (where a trim is a contradiction, refused).
    fn region_trim(&self) -> Result<f64, String> {
        match (self.region, self.region_trim) {
            (RegionRule::Quantiles, trim) => {
                Ok(trim.unwrap_or(NonlinearConfig::default().region_trim))
            }
            (RegionRule::BoundingBox, None) => Ok(0.0),
            (RegionRule::BoundingBox, Some(trim)) => Err(format!(
                "[nonlinear] region_trim = {trim} needs region = \"quantiles\" (the bounding box \
                 keeps every visited output)"
            )),
        }
    }

    /// The nonlinear certificate this section configures, if enabled, or what is wrong.
    pub(super) fn config(&self) -> Result<Option<NonlinearConfig>, String> {
        if !self.enabled {
            return Ok(None);
        }
        let d = NonlinearConfig::default();
        let features = match &self.features {
            Features::Library(name) if name == "polynomial" => None,
            Features::Library(name) => {
                return Err(format!(
                    "[nonlinear] features: `{name}` is no library: use \"polynomial\" (with \
                     degree) or a list of features such as [\"y\", \"y*tanh(y)\"]"
                ));
            }
            Features::Named(names) => Some(
                FeatureSet::from_names(names).map_err(|e| format!("[nonlinear] features: {e}"))?,
            ),
        };
        Ok(Some(NonlinearConfig {
            degree: self.degree.unwrap_or(d.degree),
            features,
            cells: self.cells.unwrap_or(d.cells),
            test_risk: self.test_risk,
            check_terms: self.check_terms.unwrap_or(d.check_terms),
            region_trim: self.region_trim()?,
            bound: self.bound,
            risk_split: self.risk_split.unwrap_or(d.risk_split),
        }))
    }
}
