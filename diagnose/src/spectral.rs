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
//!
//! [`fit_spectral_efficiency`] runs the same solver on arbitrary observations (one channel
//! signal against a known spectrum each, e.g. per-patch slopes of a chart photographed
//! through bandpass filters), with cross-validation that leaves out whole groups of
//! observations (all patches seen through one filter) so the chosen smoothness is the one that
//! best predicts a band the fit has not seen.
use crate::fit::nnls;
use crate::stack::moments;
use crate::{Ctx, Outcome, ShotKind};
use camsim_core::{Spectrum, WavelengthGrid};
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
    /// Cross-validated χ² per shot (per observation for [`fit_spectral_efficiency`]) at
    /// the chosen weight: leave-one-shot-out, or leave-one-group-out.
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

/// One row of Appendix B's `C = Sᵀ L` for one channel:
/// `signal = scale · ∫ QE_channel(λ) · radiance(λ) dλ`, measured with standard error `sigma`.
///
/// For a pixel signal in electrons per second, `radiance` is the scene spectral radiance
/// (photons / (s · sr · m² · nm)) times the lens transmittance, and `scale = p² · FF · κ · R`
/// (pixel area, fill factor, the camera equation's π/(4N²), relative illumination).
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralObservation {
    /// Identifies the observation in reports (e.g. "cc-550nm/patch 19/g").
    pub id: String,
    /// Cross-validation group: observations sharing a group are left out together.
    pub group: String,
    /// Channel index (into `channel_names` of [`fit_spectral_efficiency`]).
    pub channel: usize,
    /// The spectrum the channel integrates.
    pub radiance: Spectrum,
    /// Factor between `∫ QE · radiance` and the signal.
    pub scale: f64,
    /// Measured signal.
    pub signal: f64,
    /// Its standard error (> 0).
    pub sigma: f64,
}

/// An observation against the fitted curves.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObservationFit {
    /// The observation's id.
    pub id: String,
    /// Its cross-validation group.
    pub group: String,
    /// Channel name.
    pub channel: String,
    /// Measured signal.
    pub signal: f64,
    /// Its standard error.
    pub sigma: f64,
    /// `scale · ∫ QE_fit · radiance` with the fitted curve.
    pub predicted: f64,
}

impl ObservationFit {
    /// Standardised residual `(signal − predicted) / sigma`.
    pub fn z(&self) -> f64 {
        (self.signal - self.predicted) / self.sigma
    }
}

/// Curves fitted to [`SpectralObservation`]s, and every observation against them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpectralFit {
    /// The curves (with ±1σ and the chosen regularisation per channel).
    pub qe: SpectralQe,
    /// Each observation with its prediction by the fitted curves.
    pub observations: Vec<ObservationFit>,
}

/// The grid of relative regularisation weights searched by cross-validation,
/// 10⁻⁸ … 10² in half decades ([`ChannelQe::alpha`] is one of them).
pub fn regularisation_weights() -> Vec<f64> {
    (0..=20)
        .map(|k| 10f64.powf(-8.0 + 0.5 * k as f64))
        .collect()
}

/// Second-difference operator on `n` grid values.
fn second_difference(n: usize) -> DMatrix<f64> {
    DMatrix::from_fn(n - 2, n, |r, c| match c as i64 - r as i64 {
        0 | 2 => 1.0,
        1 => -2.0,
        _ => 0.0,
    })
}

/// One channel's solution.
struct ChannelSolution {
    qe: Vec<f64>,
    std_error: Vec<f64>,
    alpha: f64,
    cv_chi2_per_row: f64,
    predicted: Vec<f64>,
}

/// Solve one channel: rows `design[r] · q ≈ signal[r] ± sigma[r]`, q ≥ 0, second-difference
/// penalty weighted by cross-validation leaving out each value of `group` in turn.
fn solve_channel(
    design: &[Vec<f64>],
    signal: &[f64],
    sigma: &[f64],
    group: &[usize],
) -> ChannelSolution {
    let ns = design.len();
    let nw = design[0].len();
    let d = second_difference(nw);
    let alphas = regularisation_weights();
    let a = DMatrix::from_fn(ns, nw, |r, j| design[r][j] / sigma[r]);
    let b = DVector::from_iterator(ns, (0..ns).map(|r| signal[r] / sigma[r]));
    let ata = a.transpose() * &a;
    let dtd = d.transpose() * &d;
    let scale = ata.trace() / dtd.trace();
    let mut groups: Vec<usize> = group.to_vec();
    groups.sort_unstable();
    groups.dedup();
    let cv: Vec<f64> = alphas
        .par_iter()
        .map(|&al| {
            groups
                .iter()
                .map(|&g| {
                    let keep: Vec<usize> = (0..ns).filter(|&r| group[r] != g).collect();
                    let ak = a.select_rows(&keep);
                    let bk = DVector::from_iterator(keep.len(), keep.iter().map(|&r| b[r]));
                    let q = solve(&ak, &bk, &d, al * scale);
                    (0..ns)
                        .filter(|&r| group[r] == g)
                        .map(|r| (b[r] - (a.row(r) * &q)[0]).powi(2))
                        .sum::<f64>()
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
    // Inflated by the cross-validated misfit (χ²/shot > 1 means model or systematic error
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
    let predicted = (0..ns)
        .map(|r| (0..nw).map(|j| design[r][j] * q[j]).sum())
        .collect();
    ChannelSolution {
        qe: q.iter().copied().collect(),
        std_error,
        alpha: alphas[best],
        cv_chi2_per_row: cv[best] / ns as f64,
        predicted,
    }
}

/// Appendix B on arbitrary observations: per channel, non-negative curves on `grid`
/// (piecewise linear, hat basis integrated exactly against each radiance) with the
/// second-difference penalty chosen by leave-one-group-out cross-validation; ±1σ bands from
/// the linearised covariance, inflated by √(cross-validated χ²/observation) when above 1.
///
/// Channels need observations in ≥ 2 groups and ≥ 3 observations; channels without are left
/// out (named in the method). `method` is prefixed to the description of the solver.
pub fn fit_spectral_efficiency(
    observations: &[SpectralObservation],
    grid: &WavelengthGrid,
    channel_names: &[String],
    method: &str,
) -> Outcome<SpectralFit> {
    let nw = grid.len();
    if nw < 3 {
        return Outcome::not("channel QE: the wavelength grid needs ≥ 3 wavelengths");
    }
    if let Some(o) = observations.iter().find(|o| {
        !(o.sigma.is_finite() && o.sigma > 0.0 && o.signal.is_finite() && o.scale.is_finite())
            || o.channel >= channel_names.len()
    }) {
        return Outcome::not(format!(
            "channel QE: observation {} has signal {} ± {} and scale {} for channel {} (need finite values, σ > 0 and a known channel)",
            o.id, o.signal, o.sigma, o.scale, o.channel
        ));
    }
    let hats: Vec<Spectrum> = (0..nw).map(|j| grid.hat(j)).collect();
    let mut channels = Vec::new();
    let mut fits = Vec::new();
    let mut missing = Vec::new();
    for (c, name) in channel_names.iter().enumerate() {
        let rows: Vec<&SpectralObservation> =
            observations.iter().filter(|o| o.channel == c).collect();
        let mut group_names: Vec<&str> = rows.iter().map(|o| o.group.as_str()).collect();
        group_names.sort_unstable();
        group_names.dedup();
        if rows.len() < 3 || group_names.len() < 2 {
            missing.push(format!(
                "{name} ({} observations in {} groups)",
                rows.len(),
                group_names.len()
            ));
            continue;
        }
        let design: Vec<Vec<f64>> = rows
            .par_iter()
            .map(|o| {
                hats.iter()
                    .map(|h| o.scale * Spectrum::integrate_product(h, &o.radiance).unwrap_or(0.0))
                    .collect()
            })
            .collect();
        let signal: Vec<f64> = rows.iter().map(|o| o.signal).collect();
        let sigma: Vec<f64> = rows.iter().map(|o| o.sigma).collect();
        let group: Vec<usize> = rows
            .iter()
            .map(|o| group_names.binary_search(&o.group.as_str()).unwrap())
            .collect();
        let sol = solve_channel(&design, &signal, &sigma, &group);
        for (o, p) in rows.iter().zip(&sol.predicted) {
            fits.push(ObservationFit {
                id: o.id.clone(),
                group: o.group.clone(),
                channel: name.clone(),
                signal: o.signal,
                sigma: o.sigma,
                predicted: *p,
            });
        }
        channels.push(ChannelQe {
            name: name.clone(),
            qe: sol.qe,
            std_error: sol.std_error,
            alpha: sol.alpha,
            cv_chi2_per_shot: sol.cv_chi2_per_row,
        });
    }
    if channels.is_empty() {
        return Outcome::not(format!(
            "channel QE: every channel needs ≥ 3 observations in ≥ 2 cross-validation groups; have {}",
            missing.join(", ")
        ));
    }
    let n_groups = {
        let mut g: Vec<&str> = observations.iter().map(|o| o.group.as_str()).collect();
        g.sort_unstable();
        g.dedup();
        g.len()
    };
    let left_out = if missing.is_empty() {
        String::new()
    } else {
        format!("; channels left out: {}", missing.join(", "))
    };
    Outcome::Estimated(SpectralFit {
        qe: SpectralQe {
            wavelength_nm: grid.wavelength_nm.clone(),
            channels,
            n_shots: observations.len(),
            method: format!(
                "{method}: non-negative least squares on the hat basis with a second-difference \
                 Tikhonov penalty, its weight by leave-one-group-out cross-validation over \
                 {n_groups} groups{left_out}"
            ),
        },
        observations: fits,
    })
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
    let ns = used.len();
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
        // Leave-one-shot-out: every shot is its own group.
        let groups: Vec<usize> = (0..ns).collect();
        let sol = solve_channel(&design, &e, &se, &groups);
        channels.push(ChannelQe {
            name: s
                .channel_names
                .get(c)
                .cloned()
                .unwrap_or_else(|| c.to_string()),
            qe: sol.qe,
            std_error: sol.std_error,
            alpha: sol.alpha,
            cv_chi2_per_shot: sol.cv_chi2_per_row,
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
