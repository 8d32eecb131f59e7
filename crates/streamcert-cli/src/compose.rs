//! `streamcert compose`: local rates and coupling bounds in, the network certificate out.

use serde_json::json;
use streamcert_compose::{Network, SparseOptions, certify_sparse, network_rate};

use crate::CliError;

/// How the gains file is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GainsFormat {
    /// `N` lines of `N` numbers: entry `(i, j)` is `γ_ij` (how `j` drives `i`); zero diagonal.
    Dense,
    /// Lines `i,j,gamma` (0-based indices), for large sparse networks; an optional header line.
    Triplets,
}

/// Which computation to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
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
    json_out: bool,
) -> Result<String, CliError> {
    let rates: Vec<f64> = numbers(rates_text, rates_name)?.concat();
    let rows = numbers(gains_text, gains_name)?;
    let invalid = |e: streamcert_compose::ComposeError| CliError::Input {
        file: gains_name.into(),
        message: e.to_string(),
    };
    let net = match format {
        GainsFormat::Dense => {
            let n = rates.len();
            if rows.len() != n || rows.iter().any(|r| r.len() != n) {
                return Err(CliError::Input {
                    file: gains_name.into(),
                    message: format!(
                        "expected {n} rows of {n} gains (one per local rate in {rates_name})"
                    ),
                });
            }
            Network::from_dense(&rates, &rows.concat()).map_err(invalid)?
        }
        GainsFormat::Triplets => {
            let mut edges = Vec::with_capacity(rows.len());
            for (k, r) in rows.iter().enumerate() {
                let ok = r.len() == 3
                    && r[0] >= 0.0
                    && r[1] >= 0.0
                    && r[0].fract() == 0.0
                    && r[1].fract() == 0.0;
                if !ok {
                    return Err(CliError::Input {
                        file: gains_name.into(),
                        message: format!(
                            "entry {}: expected `i,j,gamma` with integer indices, found {r:?}",
                            k + 1
                        ),
                    });
                }
                edges.push((r[0] as usize, r[1] as usize, r[2]));
            }
            Network::new(rates.clone(), &edges).map_err(invalid)?
        }
    };
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
            "dense spectral abscissa (Perron weights)".to_string(),
            json!({"weighted_rate": c.weighted_rate, "weight_regularization": c.weight_regularization}),
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
    if json_out {
        let v = json!({
            "subsystems": net.len(), "edges": net.edges(), "rate": rate, "contracting": rate > 0.0,
            "weights": weights, "symmetric_rate": symmetric, "critical_scale": critical,
            "method": method_name, "details": extra,
        });
        return Ok(format!("{v}\n"));
    }
    let mut s = format!("subsystems: {}\ncoupling edges: {}\n", net.len(), net.edges());
    s += &format!("network rate: {rate}\ncontracting: {}\n", if rate > 0.0 { "yes" } else { "no" });
    s += &format!(
        "symmetric (unweighted) bound: {}\n",
        symmetric.map_or("not computed".into(), |v| v.to_string())
    );
    s += &format!("critical coupling scale: {critical}\nmethod: {method_name}\n");
    if weights.len() <= 20 {
        s += &format!("weights: {weights:?}\n");
    } else {
        s += &format!("weights: {} values (use --json to get them)\n", weights.len());
    }
    Ok(s)
}
