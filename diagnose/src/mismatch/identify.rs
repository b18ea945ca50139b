//! Identifiability of the candidate effects from the Fisher information of the shots.
//!
//! Before the selection, every candidate's parameters are checked against the baseline
//! parameters (exposure, conversion gain, black level): can these shots tell a change of the
//! candidate from a change of the baseline? Per pixel-shot of the fit rows (uncensored), the
//! frame mean m is Gaussian with the model's mean μ and marginal variance Var(m), and the
//! temporal sample variance v of F frames has (F−1)v/σ_t² ~ χ²(F−1). The Fisher information of
//! parameters θ is then (Kay, *Fundamentals of Statistical Signal Processing: Estimation
//! Theory*, 1993, eq. 3.31, the Gaussian Fisher information; pixel-shots independent)
//!
//!   I_kl = Σ ∂μ/∂θ_k · ∂μ/∂θ_l / Var(m) + Σ (F−1)/2 · ∂σ_t²/∂θ_k · ∂σ_t²/∂θ_l / σ_t⁴,
//!
//! i.e. I = ZᵀZ with standardised score columns z_k (derivatives by forward differences of
//! the model at the believed camera). With I partitioned into the candidate block C and the
//! baseline block B, the information the candidate keeps once the baseline is fitted too is
//! the Schur complement S = I_CC − I_CB I_BB⁺ I_BC; the smallest eigenvalue λ of
//! I_CC^(−½) S I_CC^(−½) is 1 − ρ², with ρ the largest canonical correlation between the
//! candidate's and the baseline's scores (Hotelling, "Relations between two sets of variates",
//! Biometrika 28, 1936). 1/λ is the candidate's variance inflation: how much the baseline
//! widens its confidence interval. Above [`MAX_VARIANCE_INFLATION`] the candidate is reported
//! as "cannot tell from these shots", with the shot that would separate it, never as a
//! finding.
//!
//! The colour candidates (QE shift, IR leakage, crosstalk) change the channels' signals, and
//! under one illuminant a spectral change of a channel is a scale of that channel: their
//! baseline also holds the exposure of each channel separately (a channel's overall
//! responsivity, e.g. the height of its QE curve or its filter's transmittance).
use super::candidates::Evidence;
use super::effects::Effect;
use super::like::{prof, Ctx};
use super::model::{ModelState, ShotConst};
use camsim_sensor::{Crosstalk, Nonlinearity};
use nalgebra::{DMatrix, SymmetricEigen};

/// Largest variance inflation 1/(1 − ρ²) of a selectable candidate (ρ² > 0.99: the baseline
/// explains all but 1 % of the candidate's most alike direction). A conventional collinearity
/// limit is 10 (Marquardt, Technometrics 12, 1970); 100 keeps every candidate the shots can
/// fit with some effort and removes only the near-exact degeneracies.
pub const MAX_VARIANCE_INFLATION: f64 = 100.0;

/// The identifiability of one candidate.
#[derive(Debug, Clone)]
pub struct Identifiability {
    /// The candidate.
    pub effect: Effect,
    /// Its parameters with information in these shots.
    pub parameters: usize,
    /// 1/(1 − ρ²) against the baseline (∞ when exactly degenerate).
    pub variance_inflation: f64,
    /// The baseline parameters of the check.
    pub baseline: Vec<String>,
    /// The other candidate whose scores are most alike (largest canonical correlation ρ²),
    /// with ρ² (informational: alike candidates are separated by the selection's ΔBIC margin).
    pub most_alike: Option<(Effect, f64)>,
    /// Not selectable: the shots cannot tell it from the baseline.
    pub cannot_tell: bool,
    /// The shot that would separate it.
    pub would_separate: String,
}

/// The shot that separates `e` from the baseline.
pub fn separating_shot(e: Effect) -> &'static str {
    match e {
        Effect::QeShift | Effect::IrLeakage => {
            "flats or a chart under a second illuminant of a different spectrum (a spectral change of a channel differs between illuminants, a change of the channel's gain does not)"
        }
        Effect::Crosstalk => {
            "a slanted edge or a colour chart (crosstalk mixes neighbouring channels, which a uniform flat under one illuminant shows as a channel gain)"
        }
        Effect::Nonlinearity => "flats at more signal levels, up to near full scale",
        Effect::DarkCurrent => "darks at a second exposure time",
        Effect::RelativeIllumination => "a uniform flat field",
        Effect::VeilingGlare => "a chart or edge with dark regions next to bright ones",
        Effect::Defocus | Effect::Distortion | Effect::LateralColor => {
            "a slanted edge or a chart"
        }
        _ => "more shots of a different kind",
    }
}

/// A parameter of the check: its name and the model with a small step of it.
struct Param {
    name: String,
    state: ModelState,
    step: f64,
    /// Only the pixels of this channel carry the score (per-channel exposure).
    channel: Option<u8>,
}

fn is_colour(e: Effect) -> bool {
    matches!(e, Effect::QeShift | Effect::IrLeakage | Effect::Crosstalk)
}

/// The candidates checked: those whose parameters change the expected frame mean in a way a
/// baseline change might mimic (the noise-only candidates and the well are separated by the
/// variance and clipping terms, which the selection's alike margin already judges).
fn checked(e: Effect) -> bool {
    matches!(
        e,
        Effect::DarkCurrent
            | Effect::Nonlinearity
            | Effect::Crosstalk
            | Effect::RelativeIllumination
            | Effect::VeilingGlare
            | Effect::Defocus
            | Effect::Distortion
            | Effect::LateralColor
            | Effect::IrLeakage
            | Effect::QeShift
    )
}

/// The parameters of `e` stepped from `st`.
fn candidate_params(ctx: &Ctx, e: Effect, st: &ModelState) -> Vec<Param> {
    let nch = ctx.data.channels();
    let present: Vec<usize> = (0..nch)
        .filter(|&c| ctx.data.channel.contains(&(c as u8)))
        .collect();
    let mut out = Vec::new();
    let mut push = |name: String, step: f64, f: &dyn Fn(&mut ModelState)| {
        let mut s = st.clone();
        f(&mut s);
        out.push(Param {
            name,
            state: s,
            step,
            channel: None,
        });
    };
    let p_um = st.sensor.pixel_pitch_m * 1e6;
    match e {
        Effect::DarkCurrent => {
            let h = (0.01 * st.sensor.dark_voltage_v_per_s).max(1e-5);
            push("dark_voltage_v_per_s".into(), h, &|s| {
                s.sensor.dark_voltage_v_per_s += h
            });
        }
        Effect::Nonlinearity => {
            // quadratic coefficient (the fitted form), 1 % at 1 V
            let a0 = match st.sensor.effects.nonlinearity {
                Some(Nonlinearity::Quadratic { coefficient_per_v }) => coefficient_per_v,
                _ => 0.0,
            };
            let h = 0.01;
            push("coefficient_per_v".into(), h, &|s| {
                s.sensor.effects.nonlinearity = Some(Nonlinearity::Quadratic {
                    coefficient_per_v: a0 + h,
                })
            });
        }
        Effect::Crosstalk => {
            let c0 = st.sensor.effects.crosstalk.map_or(0.0, |c| c.total());
            let h = 0.01;
            push("total".into(), h, &|s| {
                s.sensor.effects.crosstalk = Some(Crosstalk::symmetric(c0 + h))
            });
        }
        Effect::RelativeIllumination => {
            let cur = st.rates.falloff.clone().unwrap_or_default();
            for k in 0..2 {
                let h = -0.02;
                push(format!("a{}", k + 1), h, &|s| {
                    let mut c = cur.clone();
                    c.resize(c.len().max(k + 1), 0.0);
                    c[k] += h;
                    s.rates.falloff = Some(c);
                });
            }
        }
        Effect::VeilingGlare => {
            let g0 = st.rates.glare_fraction.unwrap_or(0.0);
            push("fraction".into(), 0.01, &|s| {
                s.rates.glare_fraction = Some(g0 + 0.01)
            });
        }
        Effect::Defocus => {
            // in σ² (as the fit): from the current σ to √(σ² + (p/2)²)
            let s0 = st.rates.defocus_sigma_um.unwrap_or(0.0);
            let h = 0.25 * p_um * p_um;
            push("sigma_um_squared".into(), h, &|s| {
                s.rates.defocus_sigma_um = Some((s0 * s0 + h).sqrt())
            });
        }
        Effect::Distortion => {
            let d0 = st.rates.distortion.unwrap_or([0.0, 0.0]);
            for k in 0..2 {
                push(format!("k{}", k + 1), 0.01, &|s| {
                    let mut d = d0;
                    d[k] += 0.01;
                    s.rates.distortion = Some(d);
                });
            }
        }
        Effect::LateralColor => {
            let d0 = st.rates.lateral_color_um.unwrap_or(0.0);
            let h = 0.5 * p_um;
            push("d_um".into(), h, &|s| {
                s.rates.lateral_color_um = Some(d0 + h)
            });
        }
        Effect::IrLeakage => {
            let cur = st.rates.ir_leakage.clone().unwrap_or(vec![0.0; nch]);
            for &c in &present {
                let name = format!("ir_{}", ctx.data.channel_names[c]);
                push(name, 0.01, &|s| {
                    let mut v = cur.clone();
                    v[c] += 0.01;
                    s.rates.ir_leakage = Some(v);
                });
            }
        }
        Effect::QeShift => {
            let cur = st.rates.qe_shift_nm.clone().unwrap_or(vec![0.0; nch]);
            for &c in &present {
                let name = format!("shift_{}_nm", ctx.data.channel_names[c]);
                push(name, 2.0, &|s| {
                    let mut v = cur.clone();
                    v[c] += 2.0;
                    s.rates.qe_shift_nm = Some(v);
                });
            }
        }
        _ => {}
    }
    out
}

/// The baseline parameters (exposure, conversion gain, black level), stepped from `st`; with
/// `per_channel`, the exposure of each channel instead of the common one.
fn baseline_params(ctx: &Ctx, st: &ModelState, per_channel: bool) -> Vec<Param> {
    let mut out = Vec::new();
    let step = |f: &dyn Fn(&mut ModelState)| {
        let mut s = st.clone();
        f(&mut s);
        s
    };
    let h = 1e-3;
    let exposure = step(&|s| s.exposure_factor *= 1.0 + h);
    if per_channel {
        for c in 0..ctx.data.channels() {
            if ctx.data.channel.contains(&(c as u8)) {
                out.push(Param {
                    name: format!("exposure_scale ({})", ctx.data.channel_names[c]),
                    state: exposure.clone(),
                    step: h,
                    channel: Some(c as u8),
                });
            }
        }
    } else {
        out.push(Param {
            name: "exposure_scale".into(),
            state: exposure,
            step: h,
            channel: None,
        });
    }
    out.push(Param {
        name: "conversion_gain".into(),
        state: step(&|s| s.sensor.conversion_gain_v_per_e *= 1.0 + h),
        step: h,
        channel: None,
    });
    out.push(Param {
        name: "black_level".into(),
        state: step(&|s| s.sensor.black_level_dn += 0.5),
        step: 0.5,
        channel: None,
    });
    out
}

/// Standardised score columns (fit rows, uncensored pixel-shots; mean part then temporal
/// variance part) of `params` at `st`.
fn scores(ctx: &Ctx, st: &ModelState, params: &[Param]) -> Result<Vec<Vec<f64>>, String> {
    let d = ctx.data;
    let (ns, cols) = (d.shots.len(), d.cols);
    let base = ctx.base_rates(&st.rates)?;
    let rates0 = ctx.transform_fit(&base, st);
    let consts0 = ctx.consts(st);
    let s = &st.sensor;
    let sig_d = if s.noise.dsnu { s.dsnu_sigma_v } else { 0.0 };
    let sig_p = if s.noise.prnu {
        s.prnu_sigma_percent / 100.0
    } else {
        0.0
    };
    let sig_c = s.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
    // (pixel, shot) of the terms, with the base prediction's weights
    let mut terms: Vec<(usize, usize, f64, f64, f64, f64)> = Vec::new();
    for &r in &ctx.fit_rows {
        for j in 0..cols {
            let i = r * cols + j;
            for sidx in 0..ns {
                let sh = &d.shots[sidx];
                if sh.censored[i] {
                    continue;
                }
                let c = &consts0[sidx];
                let p = c.predict(rates0[sidx][i] as f64 * c.t, 0.0);
                let vm = c.var_mean(&p)
                    + (sig_d * sig_d + sig_c * sig_c) * p.u * p.u
                    + sig_p * sig_p * p.w * p.w;
                let wv = if sh.has_variance() {
                    ((c.frames - 1.0) / 2.0).sqrt() / p.var_t
                } else {
                    0.0
                };
                terms.push((i, sidx, p.mean, p.var_t, 1.0 / vm.sqrt(), wv));
            }
        }
    }
    let mut out = Vec::with_capacity(params.len());
    for prm in params {
        let b = ctx.base_rates(&prm.state.rates)?;
        let rates = ctx.transform_fit(&b, &prm.state);
        let consts: Vec<ShotConst> = ctx.consts(&prm.state);
        let mut z = Vec::with_capacity(2 * terms.len());
        let mut zv = Vec::with_capacity(terms.len());
        for &(i, sidx, m0, v0, wm, wv) in &terms {
            if prm.channel.is_some_and(|c| d.channel[i] != c) {
                z.push(0.0);
                zv.push(0.0);
                continue;
            }
            let c = &consts[sidx];
            let p = c.predict(rates[sidx][i] as f64 * c.t, 0.0);
            z.push((p.mean - m0) / prm.step * wm);
            zv.push((p.var_t - v0) / prm.step * wv);
        }
        z.extend(zv);
        out.push(z);
    }
    Ok(out)
}

fn gram(a: &[Vec<f64>], b: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(a.len(), b.len(), |k, l| {
        a[k].iter().zip(&b[l]).map(|(x, y)| x * y).sum()
    })
}

/// The candidate's columns with information (a parameter the shots do not see at all, e.g.
/// the QE shift of a channel no shot lights, carries none and is left out).
fn informative(z: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    z.into_iter()
        .filter(|c| c.iter().map(|x| x * x).sum::<f64>() > 0.0)
        .collect()
}

/// 1 − ρ²: the smallest eigenvalue of I_CC^(−½)(I_CC − I_CB I_BB⁺ I_BC) I_CC^(−½).
fn one_minus_rho2(c: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let icc = gram(c, c);
    let icb = gram(c, b);
    let ibb = gram(b, b);
    let Ok(ibb_pinv) = ibb.clone().pseudo_inverse(1e-12 * ibb.norm().max(1e-300)) else {
        return 1.0;
    };
    let s = &icc - &icb * ibb_pinv * icb.transpose();
    // I_CC^(−½) by its eigen-decomposition (I_CC is positive definite on informative columns)
    let eig = SymmetricEigen::new(icc.clone());
    let max_ev = eig.eigenvalues.iter().fold(0.0f64, |m, &x| m.max(x));
    if max_ev <= 0.0 {
        return 1.0;
    }
    let inv_sqrt = DMatrix::from_diagonal(&eig.eigenvalues.map(|x| {
        if x > 1e-12 * max_ev {
            1.0 / x.sqrt()
        } else {
            // a direction the candidate's own parameters cannot tell apart: no information
            0.0
        }
    }));
    let w = &eig.eigenvectors * inv_sqrt * eig.eigenvectors.transpose();
    let m = &w * s * &w;
    let m = 0.5 * (&m + m.transpose());
    let ev = SymmetricEigen::new(m).eigenvalues;
    let kept = eig
        .eigenvalues
        .iter()
        .filter(|&&x| x > 1e-12 * max_ev)
        .count();
    // the zeroed directions give eigenvalues 0 that are not the candidate's: take the
    // smallest of the `kept` largest
    let mut v: Vec<f64> = ev.iter().copied().collect();
    v.sort_by(|a, b| b.total_cmp(a));
    v.get(kept.saturating_sub(1))
        .copied()
        .unwrap_or(1.0)
        .clamp(0.0, 1.0)
}

/// The identifiability of every checked candidate in `effects` that the set can test, at
/// the believed model.
pub(crate) fn identifiability(
    ctx: &Ctx,
    ev: &Evidence,
    believed: &ModelState,
    effects: &[Effect],
) -> Result<Vec<Identifiability>, String> {
    let t0 = std::time::Instant::now();
    let cands: Vec<Effect> = effects
        .iter()
        .copied()
        .filter(|&e| checked(e) && ev.missing(e).is_none())
        .collect();
    if cands.is_empty() {
        return Ok(Vec::new());
    }
    let common = baseline_params(ctx, believed, false);
    let per_ch = baseline_params(ctx, believed, true);
    let z_common = scores(ctx, believed, &common)?;
    let z_per_ch = if cands.iter().any(|&e| is_colour(e)) {
        scores(ctx, believed, &per_ch)?
    } else {
        Vec::new()
    };
    let mut zs: Vec<Vec<Vec<f64>>> = Vec::new();
    for &e in &cands {
        let params = candidate_params(ctx, e, believed);
        // a parameter value the forward model rejects: that candidate is not checked
        let z = scores(ctx, believed, &params).unwrap_or_default();
        zs.push(informative(z));
    }
    let mut out = Vec::new();
    for (k, &e) in cands.iter().enumerate() {
        let z = &zs[k];
        if z.is_empty() {
            continue;
        }
        let (b, names) = if is_colour(e) {
            (&z_per_ch, &per_ch)
        } else {
            (&z_common, &common)
        };
        let lam = one_minus_rho2(z, b);
        let vif = if lam > 0.0 { 1.0 / lam } else { f64::INFINITY };
        let most_alike = cands
            .iter()
            .enumerate()
            .filter(|&(l, _)| l != k && !zs[l].is_empty())
            .map(|(l, &o)| (o, 1.0 - one_minus_rho2(z, &zs[l])))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        out.push(Identifiability {
            effect: e,
            parameters: z.len(),
            variance_inflation: vif,
            baseline: names.iter().map(|p| p.name.clone()).collect(),
            most_alike,
            cannot_tell: !(vif <= MAX_VARIANCE_INFLATION),
            would_separate: separating_shot(e).to_string(),
        });
    }
    prof::add(3, t0);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1 − ρ² against closed forms: a candidate column c = cos θ · b + sin θ · e (b, e
    /// orthonormal) has canonical correlation cos θ with the baseline {b}, so 1 − ρ² = sin² θ;
    /// a column inside the baseline's span gives 0, an orthogonal one 1; with two candidate
    /// columns the most alike direction counts.
    #[test]
    fn one_minus_rho2_is_the_canonical_correlation_closed_form() {
        let n = 64;
        // orthogonal ±1 patterns (Walsh functions)
        let walsh = |k: usize| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    if (i & k).count_ones() % 2 == 0 {
                        1.0
                    } else {
                        -1.0
                    }
                })
                .collect()
        };
        let (b, e, f) = (walsh(1), walsh(2), walsh(4));
        for theta in [0.0f64, 0.1, 0.5, 1.0, 1.5707963267948966] {
            let c: Vec<f64> = b
                .iter()
                .zip(&e)
                .map(|(x, y)| theta.cos() * x + theta.sin() * y)
                .collect();
            let got = one_minus_rho2(&[c.clone()], &[b.clone()]);
            let want = theta.sin().powi(2);
            assert!((got - want).abs() < 1e-12, "θ {theta}: {got} vs {want}");
            // scaling a column changes nothing
            let c3: Vec<f64> = c.iter().map(|x| 3.0 * x).collect();
            let got3 = one_minus_rho2(&[c3], &[b.clone(), f.clone()]);
            assert!((got3 - want).abs() < 1e-12, "θ {theta}: {got3} vs {want}");
        }
        // two candidate columns, one inside the baseline's span: 0
        let mixed: Vec<f64> = b.iter().zip(&f).map(|(x, y)| 2.0 * x - y).collect();
        let got = one_minus_rho2(&[e.clone(), mixed], &[b.clone(), f.clone()]);
        assert!(got.abs() < 1e-12, "{got}");
    }
}
