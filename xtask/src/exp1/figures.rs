//! Experiment 1's figures: the certificates and `ε` over time (Fig. 3), the certificate
//! surface (Fig. 4) and the Regime-3 decision (Fig. 5).

use std::path::Path;

use anyhow::Result;
use streamcert_certificate::{Evidence, certificate_surface};
use streamcert_dynamics::Trajectory;

use super::{Decision, IMPULSE, MARGIN};
use crate::plot::{self, BLUE, Figure, GREEN, Heatmap, ORANGE, Panel, RED_};

pub(super) fn figures(
    dir: &Path,
    traj: &Trajectory,
    ev: &[Vec<Evidence>; 2],
    d: &Decision,
) -> Result<()> {
    let series = |i: usize, f: &dyn Fn(&Evidence) -> Option<f64>| -> Vec<(f64, f64)> {
        (0..traj.len()).map(|k| (traj.t[k], f(&ev[i][k]).unwrap_or(f64::NAN))).collect()
    };
    let mut panels = Vec::new();
    for (i, name) in [(1usize, "B (x4, where η enters)"), (0, "A (x1)")] {
        let mut panel = Panel::new(&format!("Subsystem {name}: certificates"), "t [s]", "β_cert")
            .line("Gaussian β_hat − ρ", series(i, &|e| e.gaussian.value), RED_)
            .line("Wasserstein β_hat − ρ(1+2ε)", series(i, &|e| e.wasserstein.value), GREEN);
        panel.hlines.push((MARGIN, "β_margin".into()));
        panel.vlines = vec![10.0, 20.0];
        panels.push(panel);
    }
    let mut eps_panel = Panel::new("Ambiguity radius ε(t)", "t [s]", "ε")
        .line("ε, subsystem B", series(1, &|e| e.eps()), BLUE)
        .line("ε, subsystem A", series(0, &|e| e.eps()), ORANGE);
    eps_panel.vlines = vec![10.0, 20.0];
    panels.push(eps_panel);
    plot::save(
        &Figure { panels, rows: 3, cols: 1, size: (1000, 1050) },
        dir,
        "fig3_exp1_certificates",
    )?;

    // Certificate surface for subsystem B.
    let eps_grid: Vec<f64> = (0..=35).map(|j| 0.01 * f64::from(j)).collect();
    let ny = eps_grid.len();
    let mut z = vec![f64::NAN; traj.len() * ny];
    let mut row = vec![0.0; ny];
    for k in 0..traj.len() {
        if let (Some(b), Some(r)) = (ev[1][k].beta_hat(), ev[1][k].rho()) {
            certificate_surface(b, r, &eps_grid, &mut row);
            z[k * ny..(k + 1) * ny].copy_from_slice(&row);
        }
    }
    let x_edges: Vec<f64> =
        (0..=traj.len()).map(|k| k as f64 * (traj.t[1] - traj.t[0]) - 0.01).collect();
    let y_edges: Vec<f64> = (0..=ny).map(|j| 0.01 * j as f64 - 0.005).collect();
    let scale = z.iter().filter(|v| v.is_finite()).fold(0.0f64, |a, v| a.max(v.abs())).max(1e-9);
    let mut eps_top =
        Panel::new("Subsystem B: ε(t)", "t [s]", "ε").line("ε(t)", series(1, &|e| e.eps()), BLUE);
    eps_top.vlines = vec![10.0, 20.0];
    let mut surface = Panel::new(
        "β_cert(t, ε) (green > 0, red < 0); line: realised ε(t)",
        "t [s]",
        "ε",
    )
    .line("realised ε(t)", series(1, &|e| e.eps()), RGB_BLACK);
    surface.heatmap = Some(Heatmap {
        x_edges,
        y_edges,
        z,
        scale,
        missing: "no estimate yet (window warming up)".into(),
    });
    surface.y_range = Some((0.0, 0.35));
    plot::save(
        &Figure { panels: vec![eps_top, surface], rows: 2, cols: 1, size: (1000, 800) },
        dir,
        "fig4_exp1_surface",
    )?;

    let mut resp = Panel::new(
        &format!("Regime 3 response, impulse {IMPULSE} at t = {:.2} s", d.t_decide + 0.1),
        "t [s]",
        "‖x‖",
    )
    .line("deployed at the Gaussian gate", d.response[0].clone(), RED_)
    .line("deployed at the Wasserstein gate", d.response[1].clone(), GREEN);
    resp.vlines = d.deploy.iter().flatten().flatten().copied().collect();
    let cum = Panel::new("Cumulative cost ∫‖x‖² dt", "t [s]", "cost")
        .line("Gaussian policy", d.cumulative[0].clone(), RED_)
        .line("Wasserstein policy", d.cumulative[1].clone(), GREEN);
    plot::save(
        &Figure { panels: vec![resp, cum], rows: 1, cols: 2, size: (1200, 450) },
        dir,
        "fig5_exp1_response",
    )?;
    Ok(())
}

const RGB_BLACK: plot::RGBColor = plot::RGBColor(0, 0, 0);
