//! `streamcert compose`: local rates and coupling bounds in, the network certificate out.

use serde_json::json;
use streamcert_certificate::Sig;
use streamcert_compose::{DenseMethod, Network, SparseOptions, certify_sparse, network_rate};

use crate::CliError;

/// How the gains file is laid out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum GainsFormat {
    /// `N` lines of `N` numbers: entry `(i, j)` is `γ_ij` (how `j` drives `i`); zero diagonal.
    #[default]
    Dense,
    /// Lines `i,j,gamma` (0-based indices), for large sparse networks; an optional header line.
    Triplets,
}

/// Which computation to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Method {
    /// Dense composition up to 2000 subsystems, sparse certificates above.
    Auto,
    /// Dense composition: the rate, weights, symmetric bound and critical scale (Perron
    /// brackets; the eigendecomposition where one does not close, up to 256 subsystems).
    Dense,
    /// Sparse certificates (Collatz–Wielandt, optional Cholesky).
    Sparse,
}

fn numbers(text: &str, file: &str) -> Result<Vec<Vec<f64>>, CliError> {
    let mut rows = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let row = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>().map_err(|_| {
                    CliError::Row(crate::RowError {
                        file: file.into(),
                        line: k as u64 + 1,
                        column: None,
                        message: format!("expected a number, found `{s}`"),
                    })
                })
            })
            .collect::<Result<Vec<f64>, _>>();
        match row {
            Ok(r) => rows.push(r),
            // A header line of a triplet file.
            Err(_) if rows.is_empty() && line.chars().any(char::is_alphabetic) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(rows)
}

/// The coupling bounds of a gains file for `n` subsystems, as edges `(i, j, γ_ij)` (`j`
/// drives `i`): a dense `n × n` matrix or `i,j,gamma` triplets (see [`GainsFormat`]). Zero
/// entries of a dense matrix are dropped; the network's constructor checks the rest (indices
/// in range, gains finite and non-negative, no self-loop).
///
/// # Errors
/// [`CliError::Row`] for a line that is not numbers, [`CliError::Input`] for a wrong shape or
/// a triplet that is not `i,j,gamma` with integer indices.
pub fn gain_edges(
    text: &str,
    name: &str,
    n: usize,
    format: GainsFormat,
) -> Result<Vec<(usize, usize, f64)>, CliError> {
    let rows = numbers(text, name)?;
    let shape = |message: String| CliError::Input { file: name.into(), message };
    match format {
        GainsFormat::Dense => {
            if rows.len() != n || rows.iter().any(|r| r.len() != n) {
                return Err(shape(format!("expected {n} rows of {n} gains (one per subsystem)")));
            }
            Ok((0..n)
                .flat_map(|i| (0..n).map(move |j| (i, j)))
                .filter(|&(i, j)| rows[i][j] != 0.0)
                .map(|(i, j)| (i, j, rows[i][j]))
                .collect())
        }
        GainsFormat::Triplets => rows
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let ok = r.len() == 3
                    && r[0] >= 0.0
                    && r[1] >= 0.0
                    && r[0].fract() == 0.0
                    && r[1].fract() == 0.0;
                if ok {
                    Ok((r[0] as usize, r[1] as usize, r[2]))
                } else {
                    Err(shape(format!(
                        "entry {}: expected `i,j,gamma` with integer indices, found {r:?}",
                        k + 1
                    )))
                }
            })
            .collect(),
    }
}

/// How [`run`] renders its result.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Render {
    /// Lines a person reads. Default.
    #[default]
    Text,
    /// One JSON object (`compose --json`).
    Json,
}

/// Run the composition and render the result (text or JSON).
///
/// # Errors
/// [`CliError::Row`] for a malformed line, [`CliError::Input`] for an invalid network
/// (negative gain, non-finite value, wrong dimensions).
pub fn run(
    rates_text: &str,
    rates_name: &str,
    gains_text: &str,
    gains_name: &str,
    format: GainsFormat,
    method: Method,
    render: Render,
) -> Result<String, CliError> {
    let rates: Vec<f64> = numbers(rates_text, rates_name)?.concat();
    // A rate that is not finite is the rates file's error, not the gains file's.
    if let Some(k) = rates.iter().position(|r| !r.is_finite()) {
        return Err(CliError::Input {
            file: rates_name.into(),
            message: format!("rate {} (subsystem {k}) must be finite, got {}", k + 1, rates[k]),
        });
    }
    let edges = gain_edges(gains_text, gains_name, rates.len(), format)?;
    let invalid = |e: streamcert_compose::ComposeError| CliError::Input {
        file: gains_name.into(),
        message: e.to_string(),
    };
    let net = Network::new(rates.clone(), &edges).map_err(invalid)?;
    let dense = match method {
        Method::Dense => true,
        Method::Sparse => false,
        Method::Auto => net.len() <= 2000,
    };
    let (rate, weights, symmetric, critical, method_name, extra) = if dense {
        let c = network_rate(&net).map_err(invalid)?;
        (
            c.rate,
            c.weights,
            Some(c.symmetric_rate),
            c.critical_scale,
            match c.method {
                DenseMethod::Perron => "dense: Perron brackets (Collatz-Wielandt), Perron weights",
                DenseMethod::Eigendecomposition => "dense: eigendecomposition, Perron weights",
            }
            .to_string(),
            json!({
                "weighted_rate": c.weighted_rate,
                "weight_regularization": c.weight_regularization,
                "rate_upper": c.rate_upper,
                "converged": c.converged,
            }),
        )
    } else {
        let c = certify_sparse(&net, &SparseOptions::default()).map_err(invalid)?;
        let m = format!("sparse certificate ({:?}, {} iterations)", c.method, c.iterations);
        (
            c.rate,
            c.certificate,
            c.symmetric_rate,
            c.critical_scale,
            m,
            json!({"rate_upper_bound": c.metzler_upper}),
        )
    };
    if render == Render::Json {
        let v = json!({
            "subsystems": net.len(), "edges": net.edges(), "rate": rate, "contracting": rate > 0.0,
            "weights": weights, "symmetric_rate": symmetric, "critical_scale": critical,
            "method": method_name, "details": extra,
        });
        return Ok(format!("{v}\n"));
    }
    // For a person: six significant digits (`--json` keeps every digit).
    let mut s = format!("subsystems: {}\ncoupling edges: {}\n", net.len(), net.edges());
    let contracting = if rate > 0.0 { "yes" } else { "no" };
    s += &format!("network rate: {}\ncontracting: {contracting}\n", Sig(rate));
    s += &format!(
        "symmetric (unweighted) bound: {}\n",
        symmetric.map_or("not computed".into(), |v| Sig(v).to_string())
    );
    s += &format!("critical coupling scale: {}\nmethod: {method_name}\n", Sig(critical));
    if weights.len() <= 20 {
        let w: Vec<String> = weights.iter().map(|&v| Sig(v).to_string()).collect();
        s += &format!("weights: [{}]\n", w.join(", "));
    } else {
        s += &format!("weights: {} values (use --json to get them)\n", weights.len());
    }
    Ok(s)
}
