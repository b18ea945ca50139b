//! Channel spectral efficiency (Appendix B): from narrowband captures of known spectral
//! radiance, solve `C = Sᵀ L` for the QE curves on a wavelength grid with non-negativity and
//! second-difference (Tikhonov) smoothness, the regularisation chosen by leave-one-out
//! cross-validation.
//!
//! Per shot s and channel c, the mean electrons of the central region,
//! `e_sc = (μ_sc − P)/(G g (2^bits−1)/swing) − t Vd / g`, equal
//! `t · p² · FF · κ · ∫ QE_c(λ) L_s(λ) dλ` (κ = irradiance per radiance, the optics' factor),
//! and with QE piecewise linear on the grid (hat basis) `∫ QE_c L_s = Σ_j QE_cj ∫ hat_j L_s`,
//! integrated exactly.
use crate::fit::nnls;
use crate::stack::moments;
use crate::{Ctx, Outcome, ShotKind};
use camsim_core::Spectrum;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

/// The estimated QE curve of one channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelQe {
    /// Channel name.
    pub name: String,
    /// QE (electrons per photon) at each grid wavelength.
    pub qe: Vec<f64>,
    /// Standard error at each grid wavelength (linearised covariance of the regularised
    /// estimate, scaled by √(leave-one-out χ²/shot) when that exceeds 1; ignores the bound).
    pub std_error: Vec<f64>,
    /// Chosen regularisation weight (relative to the data term's scale).
    pub alpha: f64,
    /// Leave-one-out χ² per shot at the chosen weight.
    pub cv_chi2_per_shot: f64,
}

/// Estimated channel QE curves.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpectralQe {
    /// Grid (nm).
    pub wavelength_nm: Vec<f64>,
    /// One curve per channel.
    pub channels: Vec<ChannelQe>,
    /// Narrowband shots used.
    pub n_shots: usize,
    /// How.
    pub method: String,
}

/// Regularised non-negative solution for weighted rows (a, b) with penalty α·‖D q‖².
fn solve(a: &DMatrix<f64>, b: &DVector<f64>, d: &DMatrix<f64>, alpha: f64) -> DVector<f64> {
    let (m, n) = (a.nrows(), a.ncols());
    let k = d.nrows();
    let mut big = DMatrix::zeros(m + k, n);
    big.view_mut((0, 0), (m, n)).copy_from(a);
    big.view_mut((m, 0), (k, n)).copy_from(&(d * alpha.sqrt()));
    let mut rhs = DVector::zeros(m + k);
    rhs.rows_mut(0, m).copy_from(b);
    nnls(&big, &rhs)
}

pub(crate) fn spectral_qe(ctx: &Ctx, pedestal: f64, g: f64, vd: f64) -> Outcome<SpectralQe> {
    let thr = ctx.opts.max_clipped_fraction;
    let mut used = Vec::new();
    let mut clipped = Vec::new();
    for (i, s) in ctx.shots.iter().enumerate() {
        if let ShotKind::Narrowband { radiance } = &s.kind {
            if ctx.stacks[i].worst_clip() <= thr {
                used.push((i, radiance));
            } else {
                clipped.push(s.id.as_str());
            }
        }
    }
    let note = if clipped.is_empty() {
        String::new()
    } else {
        format!(
            "; clipped narrowband shots left out: {}",
            clipped.join(", ")
        )
    };
    let grid = &ctx.opts.spectral_grid;
    let nw = grid.len();
    if used.len() < 3 || nw < 3 {
        return Outcome::not(format!(
            "channel QE: needs ≥ 3 unclipped narrowband shots of known radiance; the set has {}{note}",
            used.len()
        ));
    }
    let (rows, cols) = (ctx.map.rows, ctx.map.cols);
    let f = ctx.opts.spectral_roi_fraction.clamp(0.01, 1.0);
    let (r0, c0) = (
        ((rows as f64 * (1.0 - f) / 2.0).floor() as usize).min(rows - 1),
        ((cols as f64 * (1.0 - f) / 2.0).floor() as usize).min(cols - 1),
    );
    let (r1, c1) = (rows - r0, cols - c0);
    let in_roi = |p: usize| {
        let (r, c) = (p / cols, p % cols);
        r >= r0 && r < r1 && c >= c0 && c < c1
    };
    let s = ctx.sensor;
    let area = s.pixel_pitch_m * s.pixel_pitch_m * s.fill_factor * ctx.opts.irradiance_per_radiance;
    let dn_per_v = s.dn_per_output_v();
    // Design rows (shared by channels): t · p² · FF · κ · ∫ hat_j L_s.
    let design: Vec<Vec<f64>> = used
        .iter()
        .map(|&(i, l)| {
            let t = ctx.shots[i].exposure_s;
            (0..nw)
                .map(|j| t * area * Spectrum::integrate_product(&grid.hat(j), l).unwrap_or(0.0))
                .collect()
        })
        .collect();
    // Second differences.
    let d = DMatrix::from_fn(nw - 2, nw, |r, c| match c as i64 - r as i64 {
        0 | 2 => 1.0,
        1 => -2.0,
        _ => 0.0,
    });
    let ns = used.len();
    let alphas: Vec<f64> = (0..=20)
        .map(|k| 10f64.powf(-8.0 + 0.5 * k as f64))
        .collect();
    let mut channels = Vec::new();
    let ch = &ctx.map.channel;
    let ex = &ctx.excluded;
    for c in 0..ctx.map.n_channels {
        let mut e = Vec::with_capacity(ns);
        let mut se = Vec::with_capacity(ns);
        for &(i, _) in &used {
            let sh = ctx.shots[i];
            let st = &ctx.stacks[i];
            let (n, m, var, _) = moments(
                ctx.n_pix(),
                |p| ch[p] as usize == c && !ex[p] && in_roi(p),
                |p| st.mean[p],
            );
            if n < 2 {
                break;
            }
            let k = sh.analog_gain * g * dn_per_v;
            let ev = (m - pedestal) / k - sh.exposure_s * vd / g;
            e.push(ev);
            se.push(((var / n as f64) / (k * k) + (1e-3 * ev).powi(2) + 1e-6).sqrt());
        }
        if e.len() != ns {
            continue;
        }
        let a = DMatrix::from_fn(ns, nw, |r, j| design[r][j] / se[r]);
        let b = DVector::from_iterator(ns, (0..ns).map(|r| e[r] / se[r]));
        let ata = a.transpose() * &a;
        let dtd = d.transpose() * &d;
        let scale = ata.trace() / dtd.trace();
        let cv: Vec<f64> = alphas
            .par_iter()
            .map(|&al| {
                (0..ns)
                    .map(|out| {
                        let keep: Vec<usize> = (0..ns).filter(|&r| r != out).collect();
                        let ak = a.select_rows(&keep);
                        let bk = DVector::from_iterator(keep.len(), keep.iter().map(|&r| b[r]));
                        let q = solve(&ak, &bk, &d, al * scale);
                        (b[out] - (a.row(out) * &q)[0]).powi(2)
                    })
                    .sum::<f64>()
            })
            .collect();
        let best = (0..alphas.len())
            .min_by(|&x, &y| cv[x].total_cmp(&cv[y]))
            .unwrap();
        let al = alphas[best] * scale;
        let q = solve(&a, &b, &d, al);
        let gm = &ata + &dtd * al;
        // Inflated by the leave-one-out misfit (χ²/shot > 1 means model or systematic error
        // beyond the measurement noise, e.g. structure finer than the grid).
        let inflate = (cv[best] / ns as f64).max(1.0).sqrt();
        let std_error = match gm.try_inverse() {
            Some(gi) => {
                let cov = &gi * &ata * &gi;
                (0..nw)
                    .map(|j| inflate * cov[(j, j)].max(0.0).sqrt())
                    .collect()
            }
            None => vec![f64::NAN; nw],
        };
        channels.push(ChannelQe {
            name: s
                .channel_names
                .get(c)
                .cloned()
                .unwrap_or_else(|| c.to_string()),
            qe: q.iter().copied().collect(),
            std_error,
            alpha: alphas[best],
            cv_chi2_per_shot: cv[best] / ns as f64,
        });
    }
    if channels.is_empty() {
        return Outcome::not("channel QE: no channel has pixels in the central region");
    }
    Outcome::Estimated(SpectralQe {
        wavelength_nm: grid.wavelength_nm.clone(),
        channels,
        n_shots: ns,
        method: format!(
            "Appendix B: mean electrons of the central {:.0} % × {:.0} % region per narrowband shot \
             and channel = t·p²·FF·κ·Σ_j QE_j ∫hat_j L; non-negative least squares with \
             second-difference Tikhonov penalty, weight by leave-one-out cross-validation{note}",
            100.0 * f,
            100.0 * f
        ),
    })
}
