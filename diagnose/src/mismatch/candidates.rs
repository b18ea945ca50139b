//! The candidate library: for every effect id, the parameters that model it, the evidence it
//! needs in a capture set, and its maximum-likelihood fit (all other parameters held).
//!
//! Fits: 1-D parameters by a grid scan then Brent's method on the log-likelihood (on a square
//! root scale for non-negative spreads and rates, so that small values are resolved);
//! parameters that enter the photo-electron rates linearly (relative-illumination
//! polynomial, veiling glare, IR leakage) by Gauss–Newton steps on the frame means with a
//! step check on the exact likelihood; the others coordinate-wise.
use super::effects::Effect;
use super::like::{Ctx, Rates, RowSel};
use super::model::{ModelState, RateSpec};
use super::num::{median, minimize_1d, minimize_1d_local};
use camsim_sensor::{ColumnFpn, Crosstalk, HotPixels, Nonlinearity};
use rayon::prelude::*;
use std::sync::Arc;

/// Result of fitting one candidate.
#[derive(Debug, Clone)]
pub(crate) enum FitOutcome {
    /// The capture set holds no evidence for this effect.
    NotTestable(String),
    /// Maximum-likelihood fit.
    Fitted {
        state: ModelState,
        /// −log L on the fit rows.
        neg_ll: f64,
        /// Parameters fitted.
        k: usize,
    },
}

/// What the data set offers (computed once).
#[derive(Debug, Clone)]
pub(crate) struct Evidence {
    pub light: bool,
    pub structured_light: bool,
    pub uniform_light: bool,
    pub exposed: bool,
    pub channels: usize,
    pub column_rows: bool,
    /// Most photo-electrons any pixel collects in the believed model.
    pub max_photo_e: f64,
    /// The believed well capacity.
    pub well_e: f64,
    /// A shot with two or more frames.
    pub repeats: bool,
    /// Exposed shots at two or more sensor temperatures.
    pub temperatures: bool,
}

impl Evidence {
    pub fn new(ctx: &Ctx, believed: &ModelState) -> Self {
        let d = ctx.data;
        let max_photo_e = ctx
            .rates(believed)
            .map(|r| {
                d.shots
                    .iter()
                    .zip(&r)
                    .filter(|(s, _)| s.target.is_light())
                    .map(|(s, r)| {
                        r.iter().fold(0f64, |m, &x| m.max(x as f64))
                            * s.exposure_s
                            * believed.exposure_factor
                    })
                    .fold(0.0, f64::max)
            })
            .unwrap_or(f64::INFINITY);
        Evidence {
            max_photo_e,
            well_e: believed.sensor.well_capacity_e,
            light: d
                .shots
                .iter()
                .any(|s| s.target.is_light() && s.exposure_s > 0.0),
            structured_light: d
                .shots
                .iter()
                .any(|s| s.target.is_structured() && s.exposure_s > 0.0),
            uniform_light: d
                .shots
                .iter()
                .any(|s| s.target == super::data::TargetClass::Uniform && s.exposure_s > 0.0),
            exposed: d.shots.iter().any(|s| s.exposure_s > 0.0),
            channels: d.channels(),
            column_rows: ctx.column_term(RowSel::Fit),
            repeats: d.shots.iter().any(|s| s.has_variance()),
            temperatures: {
                let mut t: Vec<f64> = d
                    .shots
                    .iter()
                    .filter(|s| s.exposure_s > 0.0)
                    .filter_map(|s| s.temperature_c)
                    .collect();
                t.sort_by(|a, b| a.total_cmp(b));
                t.dedup();
                t.len() >= 2
            },
        }
    }

    /// Why `e` cannot be tested on this set, if so.
    pub fn missing(&self, e: Effect) -> Option<String> {
        use Effect::*;
        let need_light = "no shot has light (every target is dark)";
        match e {
            ExposureScale | ConversionGain | Prnu | Nonlinearity | FullWell
            | RelativeIllumination | VeilingGlare | Crosstalk | IrLeakage | QeShift
                if !self.light =>
            {
                Some(need_light.into())
            }
            Defocus | Distortion if !self.structured_light => Some(
                "no shot has a structured target (edge, patches, image) whose geometry or sharpness could show it"
                    .into(),
            ),
            LateralColor if !self.structured_light || self.channels < 2 => Some(
                "needs a structured target seen by two or more colour channels".into(),
            ),
            FullWell if self.max_photo_e < 0.5 * self.well_e => Some(format!(
                "the brightest pixels collect about {:.0} e-, under half the believed well of {:.0} e-: saturation never shows",
                self.max_photo_e, self.well_e
            )),
            DarkCurrent | HotPixels if !self.exposed => {
                Some("every shot has zero exposure time".into())
            }
            RowNoise | Rtn | BlackLevelDrift if !self.repeats => {
                Some("no shot has two or more frames: frame-to-frame noise cannot show".into())
            }
            DarkTemperature if !self.temperatures => Some(
                "fewer than two sensor temperatures among the exposed shots (captures.json temperature_c)"
                    .into(),
            ),
            ColumnFpn if !self.column_rows => Some(format!(
                "fewer than {} rows: column offsets cannot be told from pixel offsets",
                super::like::MIN_COLUMN_ROWS
            )),
            _ => None,
        }
    }
}

/// Data-derived scales that set the search ranges.
#[derive(Debug, Clone, Copy)]
struct Scales {
    /// DN per pixel volt (largest over shots).
    k: f64,
    /// RMS residual of the frame means in the darkest shots (DN).
    rms_dark: f64,
    /// Mean residual of the darkest shots (DN).
    mean_dark: f64,
    /// Largest temporal variance (data, DN²).
    var_max: f64,
    /// Largest mean signal above the pedestal in light shots (DN).
    signal_max: f64,
    /// Largest relative RMS residual of light shots.
    rel_rms_light: f64,
    /// Photo-signal per shot: (exposure, mean residual, model mean above pedestal, k) of
    /// dark shots (for the dark-current range).
    dark_rate_est: f64,
}

fn scales(ctx: &Ctx, state: &ModelState) -> Result<Scales, String> {
    let ev = ctx.evaluate(state, RowSel::Fit)?;
    let d = ctx.data;
    let nch = d.channels();
    let consts = ctx.consts(state);
    let mut k: f64 = 0.0;
    let (mut r2, mut n_d, mut rs) = (0.0, 0.0, 0.0);
    let mut var_max: f64 = 0.0;
    let mut signal_max: f64 = 0.0;
    let mut rel: f64 = 0.0;
    let mut dark_rate: f64 = 0.0;
    // darkest = the shots with the smallest model mean above the pedestal
    let mut sig: Vec<(f64, usize)> = Vec::new();
    for (s, sh) in d.shots.iter().enumerate() {
        k = k.max(consts[s].k);
        let (mut n, mut sm, mut sr, mut sr2, mut sv) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for c in 0..nch {
            let x = &ev.per_sc[s * nch + c];
            n += x.n;
            sm += x.sum_model;
            sr += x.sum_resid;
            sr2 += x.sum_r2;
            sv += x.sum_data_var;
        }
        if n < 1.0 {
            continue;
        }
        let signal = sm / n - consts[s].base_dn;
        if sh.has_variance() {
            var_max = var_max.max(sv / n);
        }
        sig.push((signal, s));
        if sh.target.is_light() {
            signal_max = signal_max.max(signal);
            if signal > 0.0 {
                rel = rel.max((sr2 / n).sqrt() / signal);
            }
        } else if sh.exposure_s > 0.0 {
            dark_rate = dark_rate.max((sr / n) / (consts[s].k * sh.exposure_s));
        }
        let _ = sh;
    }
    sig.sort_by(|a, b| a.0.total_cmp(&b.0));
    let low = sig.first().map_or(0.0, |x| x.0);
    for &(signal, s) in &sig {
        if signal > low + 0.2 * (low.abs() + 1.0) + 5.0 {
            break;
        }
        for c in 0..nch {
            let x = &ev.per_sc[s * nch + c];
            r2 += x.sum_r2;
            rs += x.sum_resid;
            n_d += x.n;
        }
    }
    Ok(Scales {
        k: k.max(1e-12),
        rms_dark: (r2 / n_d.max(1.0)).sqrt(),
        mean_dark: rs / n_d.max(1.0),
        var_max,
        signal_max,
        rel_rms_light: rel,
        dark_rate_est: dark_rate,
    })
}

/// −log L on the fit rows with rates from `base` transformed by the state.
fn neg_ll_base(ctx: &Ctx, st: &ModelState, base: &[Arc<Vec<f32>>]) -> f64 {
    let rates = ctx.transform_fit(base, st);
    let v = -ctx.logl_with(st, &rates, RowSel::Fit);
    if v.is_finite() {
        v
    } else {
        f64::INFINITY
    }
}

/// 1-D maximum-likelihood fit of a parameter set by `set` over [lo, hi] (in the search
/// variable x); keeps the current state when nothing is better.
#[allow(clippy::too_many_arguments)]
fn fit_1d(
    eval: &dyn Fn(&ModelState) -> f64,
    state: &ModelState,
    current_neg_ll: f64,
    set: &dyn Fn(&mut ModelState, f64),
    lo: f64,
    hi: f64,
    grid: usize,
    xtol: f64,
) -> (ModelState, f64) {
    fit_1d_by(eval, state, current_neg_ll, set, &|f| {
        minimize_1d(f, lo, hi, grid, xtol)
    })
}

/// [`fit_1d`] with the 1-D minimiser `search` (given the objective of x, returns (x, f(x))).
fn fit_1d_by(
    eval: &dyn Fn(&ModelState) -> f64,
    state: &ModelState,
    current_neg_ll: f64,
    set: &dyn Fn(&mut ModelState, f64),
    search: &dyn Fn(&dyn Fn(f64) -> f64) -> (f64, f64),
) -> (ModelState, f64) {
    let f = |x: f64| {
        let mut st = state.clone();
        set(&mut st, x);
        eval(&st)
    };
    let (x, fx) = search(&f);
    if fx < current_neg_ll {
        let mut st = state.clone();
        set(&mut st, x);
        (st, fx)
    } else {
        (state.clone(), current_neg_ll)
    }
}

/// One coordinate of [`cyclic_fit_1d`]: how a trial value enters the state, and the search
/// interval around the state's current value.
type Coordinate<'a> = (
    &'a dyn Fn(&mut ModelState, f64),
    &'a dyn Fn(&ModelState) -> (f64, f64),
);

/// Cyclic coordinate descent: `rounds` passes of [`fit_1d`] (7-point grid, tolerance 1e-3)
/// over `coords` in order, each from the state the previous one left.
fn cyclic_fit_1d(
    eval: &dyn Fn(&ModelState) -> f64,
    state: ModelState,
    neg_ll: f64,
    rounds: usize,
    coords: &[Coordinate],
) -> (ModelState, f64) {
    let (mut st, mut f) = (state, neg_ll);
    for _ in 0..rounds {
        for (set, range) in coords {
            let (lo, hi) = range(&st);
            (st, f) = fit_1d(eval, &st, f, *set, lo, hi, 7, 1e-3);
        }
    }
    (st, f)
}

/// `f` of every pixel of the rows a fit-row evaluation reads ([`Ctx::calc_rows`]; every
/// pixel when the fit uses all rows), 0 elsewhere: the candidates' rate algebra touches only
/// what the fit looks at (instead of full 1 MP images per likelihood evaluation).
fn on_calc_rows(ctx: &Ctx, n: usize, f: &(dyn Fn(usize) -> f32 + Sync)) -> Vec<f32> {
    if ctx.calc_rows.is_empty() {
        return (0..n).into_par_iter().map(f).collect();
    }
    let cols = ctx.data.cols;
    let rows: Vec<(usize, Vec<f32>)> = ctx
        .calc_rows
        .par_iter()
        .map(|&r| (r, (r * cols..(r + 1) * cols).map(f).collect()))
        .collect();
    let mut v = vec![0f32; n];
    for (r, row) in rows {
        v[r * cols..(r + 1) * cols].copy_from_slice(&row);
    }
    v
}

/// Per-shot sum of a base rate set and weighted basis sets (shared images stay shared), on
/// the rows of fit-row evaluations.
fn combine(ctx: &Ctx, base0: &Rates, basis: &[Rates], theta: &[f64]) -> Rates {
    let mut out: Rates = Vec::with_capacity(base0.len());
    for s in 0..base0.len() {
        if let Some(j) = (0..s).find(|&j| Arc::ptr_eq(&base0[j], &base0[s])) {
            out.push(out[j].clone());
            continue;
        }
        let b0 = &base0[s];
        let v = on_calc_rows(ctx, b0.len(), &|i| {
            let mut x = b0[i] as f64;
            for (k, t) in theta.iter().enumerate() {
                x += t * basis[k][s][i] as f64;
            }
            x.max(0.0) as f32
        });
        out.push(Arc::new(v));
    }
    out
}

/// `a − b` per shot (shared images stay shared), on the rows of fit-row evaluations.
fn difference(ctx: &Ctx, a: &Rates, b: &Rates) -> Rates {
    let mut out: Rates = Vec::with_capacity(a.len());
    for s in 0..a.len() {
        if let Some(j) = (0..s).find(|&j| Arc::ptr_eq(&b[j], &b[s]) && Arc::ptr_eq(&a[j], &a[s])) {
            out.push(out[j].clone());
            continue;
        }
        let (x, y) = (&a[s], &b[s]);
        let v = on_calc_rows(ctx, x.len(), &|i| x[i] - y[i]);
        out.push(Arc::new(v));
    }
    out
}

fn max_abs(r: &Rates) -> f64 {
    r.iter()
        .map(|v| v.iter().fold(0f64, |m, &x| m.max((x as f64).abs())))
        .fold(0.0, f64::max)
}

/// Gauss–Newton fit of parameters entering the base rates linearly:
/// rates(θ) = base0 + Σ θ_k basis_k. Each step solves the weighted normal equations of the
/// frame means and is kept only if the exact likelihood improves (halving otherwise).
#[allow(clippy::too_many_arguments)]
fn gauss_newton(
    ctx: &Ctx,
    state: &ModelState,
    base0: &Rates,
    basis: &[Rates],
    theta0: &[f64],
    lower: Option<f64>,
    set: &dyn Fn(&mut ModelState, &[f64]),
) -> (Vec<f64>, f64, ModelState) {
    let make = |th: &[f64]| {
        let mut st = state.clone();
        set(&mut st, th);
        st
    };
    let clampv = |th: &mut Vec<f64>| {
        if let Some(l) = lower {
            th.iter_mut().for_each(|x| *x = x.max(l));
        }
    };
    let mut theta = theta0.to_vec();
    clampv(&mut theta);
    let mut st = make(&theta);
    let mut f = neg_ll_base(ctx, &st, &combine(ctx, base0, basis, &theta));
    let kk = basis.len();
    for _ in 0..10 {
        let rates = ctx.transform_fit(&combine(ctx, base0, basis, &theta), &st);
        let tb: Vec<Rates> = basis.iter().map(|b| ctx.transform_fit(b, &st)).collect();
        let (a, b) = ctx.normal_equations(&st, &rates, &tb, RowSel::Fit);
        let mut m = nalgebra::DMatrix::from_row_slice(kk, kk, &a);
        for k in 0..kk {
            m[(k, k)] *= 1.0 + 1e-9;
            m[(k, k)] += 1e-30;
        }
        let Some(step) = m.lu().solve(&nalgebra::DVector::from_row_slice(&b)) else {
            break;
        };
        let mut improved = false;
        let mut scale = 1.0;
        for _ in 0..6 {
            let mut th: Vec<f64> = theta
                .iter()
                .zip(step.iter())
                .map(|(t, s)| t + scale * s)
                .collect();
            clampv(&mut th);
            let s2 = make(&th);
            let f2 = neg_ll_base(ctx, &s2, &combine(ctx, base0, basis, &th));
            if f2 < f - 1e-9 {
                let gain = f - f2;
                theta = th;
                st = s2;
                f = f2;
                improved = gain > 1e-3;
                break;
            }
            scale *= 0.5;
        }
        if !improved {
            break;
        }
    }
    (theta, f, st)
}

/// Weighted sum Σ w_k basis_k per shot (shared images stay shared; no clamp: a derivative
/// image), on the rows of fit-row evaluations.
fn weighted(ctx: &Ctx, basis: &[Rates], w: &[f64]) -> Rates {
    let b0 = &basis[0];
    let mut out: Rates = Vec::with_capacity(b0.len());
    for s in 0..b0.len() {
        if let Some(j) = (0..s).find(|&j| basis.iter().all(|b| Arc::ptr_eq(&b[j], &b[s]))) {
            out.push(out[j].clone());
            continue;
        }
        let v = on_calc_rows(ctx, b0[s].len(), &|i| {
            let mut x = 0.0;
            for (k, t) in w.iter().enumerate() {
                x += t * basis[k][s][i] as f64;
            }
            x as f32
        });
        out.push(Arc::new(v));
    }
    out
}

/// Lagrange interpolation weights at `x` of the nodes `xs` other than node `c` (whose weight
/// is 1 − their sum: the rates are written rc + Σ_k l_k(x)(r_k − rc)), and their derivatives.
fn lagrange(xs: &[f64], c: usize, x: f64) -> (Vec<f64>, Vec<f64>) {
    let n = xs.len();
    let mut w = Vec::new();
    let mut dw = Vec::new();
    for k in (0..n).filter(|&k| k != c) {
        let mut den = 1.0;
        for m in (0..n).filter(|&m| m != k) {
            den *= xs[k] - xs[m];
        }
        // l_k(x) = Π_{m≠k}(x − x_m)/den; l_k'(x) = Σ_j Π_{m≠k,j}(x − x_m)/den
        let mut num = 1.0;
        let mut dnum = 0.0;
        for m in (0..n).filter(|&m| m != k) {
            dnum = dnum * (x - xs[m]) + num;
            num *= x - xs[m];
        }
        w.push(num / den);
        dw.push(dnum / den);
    }
    (w, dw)
}

/// Minimises the likelihood of the interpolated forward model
/// `rates(x) = rc + Σ_k l_k(x) basis_k` over [lo, hi] by Gauss–Newton steps in x, starting at
/// `x0`: the derivative image ∂rates/∂x = Σ_k l_k'(x) basis_k gives the weighted least-squares
/// normal equations of the frame means ([`Ctx::normal_equations`], one pass over the
/// pixels), and each step is kept only when the surrogate's likelihood improves (halving
/// otherwise; Nocedal & Wright, *Numerical Optimization*, 2006, §10.3).
#[allow(clippy::too_many_arguments)]
fn newton_surrogate(
    ctx: &Ctx,
    at: &dyn Fn(f64) -> ModelState,
    rc: &Rates,
    basis: &[Rates],
    weights: &dyn Fn(f64) -> (Vec<f64>, Vec<f64>),
    x0: f64,
    lo: f64,
    hi: f64,
    xtol: f64,
) -> (f64, f64) {
    let sur = |x: f64| neg_ll_base(ctx, &at(x), &combine(ctx, rc, basis, &weights(x).0));
    let mut x = x0;
    let mut f = sur(x);
    for _ in 0..12 {
        let st = at(x);
        let (w, dw) = weights(x);
        let rates = ctx.transform_fit(&combine(ctx, rc, basis, &w), &st);
        let deriv = ctx.transform_fit(&weighted(ctx, basis, &dw), &st);
        let (a, b) = ctx.normal_equations(&st, &rates, std::slice::from_ref(&deriv), RowSel::Fit);
        if !(a[0] > 0.0) || !b[0].is_finite() {
            break;
        }
        let step = b[0] / a[0];
        let mut scale = 1.0;
        let mut moved = false;
        for _ in 0..6 {
            let xt = (x + scale * step).clamp(lo, hi);
            if (xt - x).abs() <= xtol {
                break;
            }
            let ft = sur(xt);
            if ft < f - 1e-9 {
                moved = f - ft > 1e-3;
                x = xt;
                f = ft;
                break;
            }
            scale *= 0.5;
        }
        if !moved {
            break;
        }
    }
    (x, f)
}

/// 1-D ML fit of a parameter that enters the forward model nonlinearly (each evaluation of
/// the forward model is expensive), by a linearised forward model confirmed with full runs:
/// one extra forward run at `x0 + step` gives the derivative images (finite difference);
/// the likelihood of the interpolated rates is minimised by Gauss–Newton steps
/// ([`newton_surrogate`]); the minimum is run through the exact forward model, which both
/// confirms it and becomes a node of the interpolation (Lagrange through the three nodes
/// nearest the best value: linear, then quadratic); until the interpolation predicts less
/// than 0.5 in log-likelihood beyond the best confirmed value. Every forward run is used as
/// a node, so a fit costs 2–5 forward runs.
#[allow(clippy::too_many_arguments)]
fn fit_surrogate_1d(
    ctx: &Ctx,
    state: &ModelState,
    f0: f64,
    x0: f64,
    step: f64,
    lo: f64,
    hi: f64,
    set: &dyn Fn(&mut ModelState, f64),
) -> Result<(ModelState, f64), String> {
    let at = |x: f64| -> ModelState {
        let mut st = state.clone();
        set(&mut st, x);
        st
    };
    let rates_at = |x: f64| -> Result<Arc<Rates>, String> { ctx.base_rates(&at(x).rates) };
    let x0 = x0.clamp(lo, hi);
    // Node 0 is the state itself (x0 is its value; an unset block and its zero value, e.g.
    // no lateral colour and 0 µm of it, are one forward run).
    let r0 = ctx.base_rates(&state.rates)?;
    // (x, rates, exact −lnL)
    let mut nodes: Vec<(f64, Arc<Rates>, f64)> = vec![(x0, r0, f0)];
    let x1 = if x0 + step <= hi {
        x0 + step
    } else {
        x0 - step
    };
    match rates_at(x1) {
        Ok(r1) => {
            let f1 = neg_ll_base(ctx, &at(x1), &r1);
            nodes.push((x1, r1, f1));
        }
        // A parameter value the forward model rejects (e.g. a distortion that folds the
        // image over) ends the search with the best value so far.
        Err(_) => return Ok((state.clone(), f0)),
    }
    let mut best = (state.clone(), f0, x0);
    if nodes[1].2 < f0 {
        best = (at(x1), nodes[1].2, x1);
    }
    for _ in 0..6 {
        // the three nodes nearest the best value, the best one the centre
        nodes.sort_by(|a, b| (a.0 - best.2).abs().total_cmp(&(b.0 - best.2).abs()));
        nodes.truncate(3);
        let c = 0;
        let xs: Vec<f64> = nodes.iter().map(|n| n.0).collect();
        let rc = nodes[c].1.clone();
        let basis: Vec<Rates> = (1..nodes.len())
            .map(|k| difference(ctx, &nodes[k].1, &rc))
            .collect();
        let span = xs
            .iter()
            .fold(0f64, |m, &x| m.max((x - xs[c]).abs()))
            .max(step);
        let (a, b) = ((xs[c] - 3.0 * span).max(lo), (xs[c] + 3.0 * span).min(hi));
        let (x_star, f_sur) = newton_surrogate(
            ctx,
            &at,
            &rc,
            &basis,
            &|x| lagrange(&xs, c, x),
            xs[c],
            a,
            b,
            1e-4 * step,
        );
        // Not worth an exact evaluation when the interpolated improvement is negligible.
        if best.1 - f_sur < 0.5 || xs.iter().any(|&x| (x - x_star).abs() <= 1e-4 * step) {
            break;
        }
        let st = at(x_star);
        let Ok(rates) = ctx.base_rates(&st.rates) else {
            break;
        };
        let f = neg_ll_base(ctx, &st, &rates);
        if f < best.1 {
            best = (st, f, x_star);
        }
        nodes.push((x_star, rates, f));
    }
    Ok((best.0, best.1))
}

/// Fits `effect` starting from `state` (all other parameters held).
pub(crate) fn fit_effect(
    ctx: &Ctx,
    evidence: &Evidence,
    effect: Effect,
    state: &ModelState,
) -> Result<FitOutcome, String> {
    fit_effect_warm(ctx, evidence, effect, state, &Warm::default())
}

/// A warm start of a candidate's 1-D fit (issue 23): the search variable's optimum of the
/// same candidate in the previous selection round (`prev`), and where this fit's search
/// ended (`found`, for the next round).
#[derive(Debug, Default)]
pub(crate) struct Warm {
    /// The previous round's optimum of the search variable (None: a cold start, the grid).
    pub prev: Option<f64>,
    /// The optimum of this fit's search (set by the 1-D fits).
    pub found: std::cell::Cell<Option<f64>>,
}

/// [`fit_1d`] from a warm start: with `warm.prev` inside [lo, hi], a local search from it
/// ([`minimize_1d_local`]: a downhill walk in steps of the grid spacing, doubling, then
/// Brent's method in the bracket, to the same tolerance) instead of the grid scan; the grid
/// scan otherwise. Records the search's optimum in `warm.found`.
#[allow(clippy::too_many_arguments)]
fn fit_1d_w(
    warm: &Warm,
    eval: &dyn Fn(&ModelState) -> f64,
    state: &ModelState,
    current_neg_ll: f64,
    set: &dyn Fn(&mut ModelState, f64),
    lo: f64,
    hi: f64,
    grid: usize,
    xtol: f64,
) -> (ModelState, f64) {
    fit_1d_by(eval, state, current_neg_ll, set, &|f| {
        let r = match warm.prev {
            Some(x0) if x0 >= lo && x0 <= hi => {
                // a start where the likelihood is undefined all around cannot walk downhill:
                // scan the grid as a cold fit would
                let r = minimize_1d_local(f, lo, hi, grid, xtol, x0);
                if r.1.is_finite() {
                    r
                } else {
                    minimize_1d(f, lo, hi, grid, xtol)
                }
            }
            _ => minimize_1d(f, lo, hi, grid, xtol),
        };
        warm.found.set(Some(r.0));
        r
    })
}

/// [`fit_effect`] with a warm start for the candidates fitted by one 1-D search
/// ([`fit_1d_w`]); the others ignore `warm`.
pub(crate) fn fit_effect_warm(
    ctx: &Ctx,
    evidence: &Evidence,
    effect: Effect,
    state: &ModelState,
    warm: &Warm,
) -> Result<FitOutcome, String> {
    if let Some(why) = evidence.missing(effect) {
        return Ok(FitOutcome::NotTestable(why));
    }
    let base = ctx.base_rates(&state.rates)?;
    let eval_base = |st: &ModelState| neg_ll_base(ctx, st, &base);
    // (= eval_base(state); shared by every candidate of a round and by `scales`)
    let f0 = {
        let v = -ctx.evaluate(state, RowSel::Fit)?.logl;
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    let sc = scales(ctx, state)?;
    let s0 = &state.sensor;
    let out = |st: ModelState, f: f64, k: usize| {
        Ok(FitOutcome::Fitted {
            state: st,
            neg_ll: f,
            k,
        })
    };
    let sq = |x: f64| x * x;
    match effect {
        Effect::ExposureScale => {
            let x0 = state.exposure_factor.ln();
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.exposure_factor = x.exp(),
                x0 - 1.0,
                x0 + 1.0,
                11,
                1e-6,
            );
            out(st, f, 1)
        }
        Effect::ConversionGain => {
            let g0 = s0.conversion_gain_v_per_e;
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.conversion_gain_v_per_e = g0 * x.exp(),
                -1.0,
                1.0,
                11,
                1e-6,
            );
            out(st, f, 1)
        }
        Effect::BlackLevel => {
            let b0 = s0.black_level_dn;
            let c = sc.mean_dark;
            let w = (4.0 * c.abs()).max(4.0 * sc.rms_dark).max(8.0);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.black_level_dn = b0 + x,
                c - w,
                c + w,
                17,
                1e-4,
            );
            out(st, f, 1)
        }
        Effect::DarkCurrent => {
            let v0 = s0.dark_voltage_v_per_s;
            let hi = (4.0 * v0).max(4.0 * (v0 + sc.dark_rate_est)).max(1e-7);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.dark_voltage_v_per_s = x * x,
                0.0,
                hi.sqrt(),
                17,
                1e-7 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::ReadNoise => {
            let r0 = s0.read_noise_v;
            let hi = (4.0 * r0)
                .max(2.0 * sc.var_max.sqrt() / sc.k)
                .max(2.0 * sc.rms_dark / sc.k);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.read_noise_v = x * x,
                0.0,
                hi.max(1e-9).sqrt(),
                17,
                1e-6 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::Dsnu => {
            let d0 = s0.dsnu_sigma_v;
            let hi = (4.0 * d0).max(3.0 * sc.rms_dark / sc.k).max(1e-7);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.dsnu_sigma_v = x * x,
                0.0,
                hi.sqrt(),
                17,
                1e-6 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::Prnu => {
            let p0 = s0.prnu_sigma_percent;
            let hi = (4.0 * p0).max(300.0 * sc.rel_rms_light).max(0.05);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.prnu_sigma_percent = x * x,
                0.0,
                hi.sqrt(),
                17,
                1e-6 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::ColumnFpn => {
            let c0 = s0.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
            let hi = (4.0 * c0).max(3.0 * sc.rms_dark / sc.k).max(1e-7);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| {
                    st.sensor.column_fpn = Some(ColumnFpn {
                        offset_sigma_v: x * x,
                    })
                },
                0.0,
                hi.sqrt(),
                17,
                1e-6 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::HotPixels => fit_hot(ctx, state, &base, f0),
        Effect::Nonlinearity => {
            let a0 = match s0.effects.nonlinearity {
                Some(Nonlinearity::Quadratic { coefficient_per_v }) => coefficient_per_v,
                _ => 0.0,
            };
            let v_max = (sc.signal_max / sc.k).max(1e-6);
            let hi = (4.0 * a0).max(1.0 / v_max);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| {
                    st.sensor.effects.nonlinearity = Some(Nonlinearity::Quadratic {
                        coefficient_per_v: x * x,
                    })
                },
                0.0,
                hi.sqrt(),
                17,
                1e-6 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::FullWell => {
            let w0 = s0.well_capacity_e.ln();
            // A well whose charge the ADC clips first in every shot never enters the
            // prediction (ShotConst::adc_first): all such wells have one likelihood, computed
            // once (about 40 % of the grid on a sensor whose well fills the ADC range).
            let adc_value = std::sync::Mutex::new(None::<f64>);
            let eval_well = |st: &ModelState| {
                if !ctx.consts(st).iter().all(|c| c.adc_first) {
                    return eval_base(st);
                }
                let mut v = adc_value.lock().expect("adc value");
                *v.get_or_insert_with(|| eval_base(st))
            };
            let (st, f) = fit_1d(
                &eval_well,
                state,
                f0,
                &|st, x| st.sensor.well_capacity_e = x.exp(),
                w0 - 1.6,
                w0 + 1.1,
                // A hard well makes the likelihood sharply peaked (pixels switch between
                // clipped, with no temporal noise, and not): ~2 % steps resolve the valley.
                // (A coarse-then-fine search of this grid, every third point first, missed
                // the valley on both full-well sets of the effect matrix: it is narrower
                // than three grid steps. Issue 23, branch diagsel.)
                121,
                1e-5,
            );
            out(st, f, 1)
        }
        Effect::Crosstalk => {
            let c0 = s0.effects.crosstalk.map_or(0.0, |c| c.total());
            let hi = (2.0 * c0).max(0.3);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| st.sensor.effects.crosstalk = Some(Crosstalk::symmetric(x * x)),
                0.0,
                hi.sqrt(),
                13,
                1e-5,
            );
            out(st, f, 1)
        }
        Effect::RelativeIllumination => fit_falloff(ctx, state),
        Effect::VeilingGlare => {
            let mut s_zero = state.rates.clone();
            s_zero.glare_fraction = Some(0.0);
            let mut s_one = state.rates.clone();
            s_one.glare_fraction = Some(1.0);
            let b0 = ctx.base_rates(&s_zero)?;
            let b1 = difference(ctx, &*ctx.base_rates(&s_one)?, &b0);
            let g0 = state.rates.glare_fraction.unwrap_or(0.0);
            let eval = |st: &ModelState| {
                let g = st.rates.glare_fraction.unwrap_or(0.0);
                neg_ll_base(ctx, st, &combine(ctx, &b0, std::slice::from_ref(&b1), &[g]))
            };
            let hi = (2.0 * g0).max(0.3);
            let (st, f) = fit_1d_w(
                warm,
                &eval,
                state,
                f0,
                &|st, x| st.rates.glare_fraction = Some(x * x),
                0.0,
                hi.sqrt(),
                13,
                1e-6,
            );
            out(st, f, 1)
        }
        Effect::IrLeakage => fit_ir(ctx, state, f0),
        Effect::RowNoise => {
            let r0 = s0.effects.row_noise.map_or(0.0, |r| r.sigma_v);
            let hi = (4.0 * r0).max(2.0 * sc.var_max.sqrt() / sc.k).max(1e-7);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| {
                    st.sensor.effects.row_noise = Some(camsim_sensor::RowNoise { sigma_v: x * x })
                },
                0.0,
                hi.sqrt(),
                17,
                1e-6 * hi.sqrt(),
            );
            out(st, f, 1)
        }
        Effect::BlackLevelDrift => {
            let r0 = s0.effects.black_level_drift.map_or(0.0, |d| d.dn_per_frame);
            let n = (state.frames_in_set.max(2) - 1) as f64;
            let w = (4.0 * r0.abs()).max((4.0 * (sc.mean_dark.abs() + sc.rms_dark) + 8.0) / n);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| {
                    st.sensor.effects.black_level_drift =
                        Some(camsim_sensor::BlackLevelDrift { dn_per_frame: x })
                },
                r0 - w,
                r0 + w,
                21,
                1e-6 * w,
            );
            out(st, f, 1)
        }
        Effect::DarkTemperature => {
            // variable: 1/T_d (0 = no temperature dependence), T_d ≥ 2 °C; the reference is
            // the believed law's, else the mean temperature of the shots that give one.
            let temps: Vec<f64> = ctx
                .data
                .shots
                .iter()
                .filter_map(|s| s.temperature_c)
                .collect();
            let t_ref = s0
                .effects
                .dark_temperature
                .map_or(temps.iter().sum::<f64>() / temps.len().max(1) as f64, |d| {
                    d.reference_temperature_c
                });
            let x0 = s0
                .effects
                .dark_temperature
                .map_or(0.0, |d| 1.0 / d.doubling_temperature_c);
            let (st, f) = fit_1d_w(
                warm,
                &eval_base,
                state,
                f0,
                &|st, x| {
                    st.sensor.effects.dark_temperature =
                        (x > 1e-9).then_some(camsim_sensor::DarkTemperature {
                            reference_temperature_c: t_ref,
                            doubling_temperature_c: 1.0 / x,
                        })
                },
                0.0,
                (2.0 * x0).max(0.5),
                21,
                1e-5,
            );
            out(st, f, 1)
        }
        Effect::Rtn => fit_rtn(ctx, state, &base, f0),
        Effect::Defocus => {
            // variable: σ² (the blur's effect on the pixels is nearly linear in it)
            let p_um = s0.pixel_pitch_m * 1e6;
            let s_cur = state.rates.defocus_sigma_um.unwrap_or(0.0);
            let hi = sq((2.0 * s_cur).max(3.0 * p_um));
            let (st, f) = fit_surrogate_1d(
                ctx,
                state,
                f0,
                sq(s_cur),
                (0.25 * sq(p_um)).max(0.3 * sq(s_cur)),
                0.0,
                hi,
                &|st, x| st.rates.defocus_sigma_um = Some(x.max(0.0).sqrt()),
            )?;
            out(st, f, 1)
        }
        Effect::LateralColor => {
            let p_um = s0.pixel_pitch_m * 1e6;
            let d0 = state.rates.lateral_color_um.unwrap_or(0.0);
            let w = (2.0 * d0.abs()).max(4.0 * p_um);
            let (st, f) =
                fit_surrogate_1d(ctx, state, f0, d0, 0.5 * p_um, d0 - w, d0 + w, &|st, x| {
                    st.rates.lateral_color_um = Some(x)
                })?;
            out(st, f, 1)
        }
        Effect::Distortion => {
            let [k10, k20] = state.rates.distortion.unwrap_or([0.0, 0.0]);
            let mut st = state.clone();
            let mut f = f0;
            for coef in [0usize, 1, 0] {
                let cur = st.rates.distortion.unwrap_or([k10, k20]);
                let (s2, f2) = fit_surrogate_1d(
                    ctx,
                    &st,
                    f,
                    cur[coef],
                    0.01,
                    cur[coef] - 0.3,
                    cur[coef] + 0.3,
                    &|s, x| {
                        let mut d = s.rates.distortion.unwrap_or([k10, k20]);
                        d[coef] = x;
                        s.rates.distortion = Some(d);
                    },
                )?;
                st = s2;
                f = f2;
            }
            out(st, f, 2)
        }
        Effect::QeShift => {
            let nch = ctx.data.channels();
            let mut st = state.clone();
            let mut f = f0;
            let mut k = 0;
            for c in 0..nch {
                if !ctx.data.channel.contains(&(c as u8)) {
                    continue;
                }
                k += 1;
                let cur = st
                    .rates
                    .qe_shift_nm
                    .as_ref()
                    .map_or(0.0, |v| v.get(c).copied().unwrap_or(0.0));
                let (s2, f2) =
                    fit_surrogate_1d(ctx, &st, f, cur, 4.0, cur - 40.0, cur + 40.0, &|s, x| {
                        let mut v = s.rates.qe_shift_nm.clone().unwrap_or(vec![0.0; nch]);
                        v[c] = x;
                        s.rates.qe_shift_nm = Some(v);
                    })?;
                st = s2;
                f = f2;
            }
            out(st, f, k.max(1))
        }
    }
    .map(|o| {
        let _ = sq;
        o
    })
}

/// Hot pixels: start from the pixels whose residuals a per-pixel extra dark rate explains
/// beyond 6σ, then coordinate-wise ML of (fraction, median rate, log-spread).
fn fit_hot(
    ctx: &Ctx,
    state: &ModelState,
    base: &Arc<Rates>,
    f0: f64,
) -> Result<FitOutcome, String> {
    let rates = ctx.transform_fit(base, state);
    let eval = |st: &ModelState| neg_ll_base(ctx, st, base);
    let (fr0, v0, ls0) = match state.sensor.effects.hot_pixels {
        Some(h) if h.fraction > 0.0 && h.dark_voltage_v_per_s > 0.0 => {
            (h.fraction, h.dark_voltage_v_per_s, h.log_sigma)
        }
        _ => {
            // Start values from the fit rows (the fit's own data).
            let mut scan = ctx.hot_scan(state, &rates, 6.0, RowSel::Fit, false);
            if scan.is_empty() {
                // Every informative pixel-shot censored (e.g. black-clipped darks): the
                // censored shots with no frame at a rail still show their level.
                scan = ctx.hot_scan(state, &rates, 6.0, RowSel::Fit, true);
            }
            if scan.is_empty() {
                return Ok(FitOutcome::Fitted {
                    state: state.clone(),
                    neg_ll: f0,
                    k: 2,
                });
            }
            let n = (ctx.fit_rows.len() * ctx.data.cols) as f64;
            let lv: Vec<f64> = scan.iter().map(|x| x.1.max(1e-30).ln()).collect();
            let med = median(&lv);
            let spread = super::num::robust_sigma(&lv);
            (
                (scan.len() as f64 / n).min(0.2),
                med.exp(),
                spread.clamp(0.05, 1.5),
            )
        }
    };
    let set_h = |st: &mut ModelState, f: f64, v: f64, s: f64| {
        st.sensor.effects.hot_pixels = Some(HotPixels {
            fraction: f,
            dark_voltage_v_per_s: v,
            log_sigma: s,
        })
    };
    let mut st = state.clone();
    set_h(&mut st, fr0, v0, ls0);
    let f = eval(&st);
    let hot = |s: &ModelState| s.sensor.effects.hot_pixels.expect("set");
    let (st, f) = cyclic_fit_1d(
        &eval,
        st,
        f,
        2,
        &[
            (
                &|s, x| {
                    let h = hot(s);
                    set_h(s, x.exp(), h.dark_voltage_v_per_s, h.log_sigma)
                },
                &|s| {
                    let l = hot(s).fraction.ln();
                    (l - 1.5, (l + 1.5).min(0.5f64.ln()))
                },
            ),
            (
                &|s, x| {
                    let h = hot(s);
                    set_h(s, h.fraction, x.exp(), h.log_sigma)
                },
                &|s| {
                    let l = hot(s).dark_voltage_v_per_s.ln();
                    (l - 1.0, l + 1.0)
                },
            ),
            (
                &|s, x| {
                    let h = hot(s);
                    set_h(s, h.fraction, h.dark_voltage_v_per_s, x)
                },
                &|s| (0.0, (2.0 * hot(s).log_sigma).max(1.5)),
            ),
        ],
    );
    if f < f0 {
        Ok(FitOutcome::Fitted {
            state: st,
            neg_ll: f,
            k: 3,
        })
    } else {
        Ok(FitOutcome::Fitted {
            state: state.clone(),
            neg_ll: f0,
            k: 3,
        })
    }
}

/// RTN pixels: start from the pixels whose temporal variance exceeds the model's fourfold in
/// most of their shots with repeats (step A from the median excess, `A²p(1−p)` with
/// p = 1/2), then coordinate-wise ML of (fraction, amplitude); the fitted form switches with
/// probability 1/2 per frame each way (independent states, p = 1/2).
fn fit_rtn(
    ctx: &Ctx,
    state: &ModelState,
    base: &Arc<Rates>,
    f0: f64,
) -> Result<FitOutcome, String> {
    let eval = |st: &ModelState| neg_ll_base(ctx, st, base);
    let set = |st: &mut ModelState, f: f64, a: f64| {
        st.sensor.effects.rtn = Some(camsim_sensor::Rtn {
            fraction: f,
            amplitude_v: a,
            log_sigma: 0.0,
            p_up: 0.5,
            p_down: 0.5,
        })
    };
    let (fr0, a0) = match state.sensor.effects.rtn {
        Some(r) if r.fraction > 0.0 && r.amplitude_v > 0.0 => (r.fraction, r.amplitude_v),
        _ => {
            let d = ctx.data;
            let rates = ctx.transform_fit(base, state);
            let consts = ctx.consts(state);
            // the dark shots with repeats (where the temporal noise is the floor), else all
            let rep_all: Vec<usize> = (0..d.shots.len())
                .filter(|&s| d.shots[s].has_variance())
                .collect();
            let rep_dark: Vec<usize> = rep_all
                .iter()
                .copied()
                .filter(|&s| !d.shots[s].target.is_light())
                .collect();
            let rep = if rep_dark.is_empty() {
                rep_all
            } else {
                rep_dark
            };
            let mut excess_v2: Vec<f64> = Vec::new();
            for &r in &ctx.fit_rows {
                for j in 0..d.cols {
                    let i = r * d.cols + j;
                    let mut hits = 0;
                    let mut ex: Vec<f64> = Vec::new();
                    for &s in &rep {
                        let sh = &d.shots[s];
                        if sh.censored[i] {
                            continue;
                        }
                        let c = &consts[s];
                        let p = c.predict(rates[s][i] as f64 * c.t, 0.0);
                        let v = sh.var_dn[i] as f64;
                        if v > 4.0 * p.var_t {
                            hits += 1;
                        }
                        ex.push(((v - p.var_t) / (p.u * p.u).max(1e-30)).max(0.0));
                    }
                    if !ex.is_empty() && 5 * hits >= 3 * ex.len() {
                        excess_v2.push(median(&ex));
                    }
                }
            }
            if excess_v2.is_empty() {
                return Ok(FitOutcome::Fitted {
                    state: state.clone(),
                    neg_ll: f0,
                    k: 2,
                });
            }
            let n = (ctx.fit_rows.len() * d.cols) as f64;
            // A²/4 = median excess (V²)
            (
                (excess_v2.len() as f64 / n).min(0.2),
                2.0 * median(&excess_v2).sqrt(),
            )
        }
    };
    let mut st = state.clone();
    set(&mut st, fr0, a0);
    let f = eval(&st);
    let rtn = |s: &ModelState| s.sensor.effects.rtn.expect("set");
    let (st, f) = cyclic_fit_1d(
        &eval,
        st,
        f,
        2,
        &[
            (
                &|s, x| {
                    let a = rtn(s).amplitude_v;
                    set(s, x.exp(), a)
                },
                &|s| {
                    let l = rtn(s).fraction.ln();
                    (l - 1.5, (l + 1.5).min(0.5f64.ln()))
                },
            ),
            (
                &|s, x| {
                    let fr = rtn(s).fraction;
                    set(s, fr, x.exp())
                },
                &|s| {
                    let l = rtn(s).amplitude_v.ln();
                    (l - 1.0, l + 1.0)
                },
            ),
        ],
    );
    if f < f0 {
        Ok(FitOutcome::Fitted {
            state: st,
            neg_ll: f,
            k: 2,
        })
    } else {
        Ok(FitOutcome::Fitted {
            state: state.clone(),
            neg_ll: f0,
            k: 2,
        })
    }
}

/// Relative illumination: polynomial fall-off 1 + a1 h² + … + a_K h^(2K); the order K is
/// chosen by BIC among 1–`FALLOFF_MAX_ORDER` (a vignetted pupil falls off nearly linearly
/// in h from the centre, which low even orders cannot follow).
fn fit_falloff(ctx: &Ctx, state: &ModelState) -> Result<FitOutcome, String> {
    let spec_with = |c: Vec<f64>| RateSpec {
        falloff: Some(c),
        ..state.rates.clone()
    };
    const FALLOFF_MAX_ORDER: usize = 6;
    let b0 = ctx.base_rates(&spec_with(vec![0.0; FALLOFF_MAX_ORDER]))?;
    let mut basis: Vec<Rates> = Vec::new();
    for k in 0..FALLOFF_MAX_ORDER {
        let mut c = vec![0.0; FALLOFF_MAX_ORDER];
        c[k] = 1.0;
        basis.push(difference(ctx, &*ctx.base_rates(&spec_with(c))?, &b0));
    }
    let n_obs = ctx.data.pixels() as f64 * ctx.data.shots.len() as f64;
    let cur = state.rates.falloff.clone().unwrap_or_default();
    let set = |s: &mut ModelState, th: &[f64]| {
        let mut c = th.to_vec();
        c.resize(FALLOFF_MAX_ORDER, 0.0);
        while c.len() > 1 && c.last() == Some(&0.0) {
            c.pop();
        }
        s.rates.falloff = Some(c);
    };
    let mut best: Option<(f64, Vec<f64>, f64, ModelState, usize)> = None;
    for order in 1..=FALLOFF_MAX_ORDER {
        let th0: Vec<f64> = (0..order)
            .map(|k| cur.get(k).copied().unwrap_or(0.0))
            .collect();
        let (th, f, st) = gauss_newton(ctx, state, &b0, &basis[..order], &th0, None, &set);
        let crit = 2.0 * f + order as f64 * n_obs.ln();
        if best.as_ref().is_none_or(|b| crit < b.0) {
            best = Some((crit, th, f, st, order));
        }
    }
    let (_, _, f, st, order) = best.expect("every order tried");
    Ok(FitOutcome::Fitted {
        state: st,
        neg_ll: f,
        k: order,
    })
}

/// IR leakage: a constant added QE on 700–1000 nm per channel (≥ 0), linear in the rates.
fn fit_ir(ctx: &Ctx, state: &ModelState, f0: f64) -> Result<FitOutcome, String> {
    let nch = ctx.data.channels();
    let cur = state.rates.ir_leakage.clone().unwrap_or(vec![0.0; nch]);
    let spec_with = |c: Vec<f64>| RateSpec {
        ir_leakage: Some(c),
        ..state.rates.clone()
    };
    let b0 = ctx.base_rates(&spec_with(vec![0.0; nch]))?;
    let mut basis: Vec<Rates> = Vec::new();
    let mut chans = Vec::new();
    for c in 0..nch {
        let mut v = vec![0.0; nch];
        v[c] = 1.0;
        let b = difference(ctx, &*ctx.base_rates(&spec_with(v))?, &b0);
        if max_abs(&b) > 0.0 {
            basis.push(b);
            chans.push(c);
        }
    }
    if basis.is_empty() {
        return Ok(FitOutcome::NotTestable(
            "no shot has light beyond 700 nm (the targets' radiance ends at or before 700 nm)"
                .into(),
        ));
    }
    let th0: Vec<f64> = chans.iter().map(|&c| cur[c]).collect();
    let (_, f, st) = gauss_newton(ctx, state, &b0, &basis, &th0, Some(0.0), &|s, th| {
        let mut v = vec![0.0; nch];
        for (k, &c) in chans.iter().enumerate() {
            v[c] = th[k];
        }
        s.rates.ir_leakage = Some(v);
    });
    if f < f0 {
        Ok(FitOutcome::Fitted {
            state: st,
            neg_ll: f,
            k: chans.len(),
        })
    } else {
        Ok(FitOutcome::Fitted {
            state: state.clone(),
            neg_ll: f0,
            k: chans.len(),
        })
    }
}

/// The magnitude of an effect in a fitted state (effects.md units).
pub fn magnitude(effect: Effect, st: &ModelState, believed: &ModelState) -> f64 {
    let s = &st.sensor;
    let b = &believed.sensor;
    match effect {
        Effect::ExposureScale => st.exposure_factor / believed.exposure_factor,
        Effect::ConversionGain => s.conversion_gain_v_per_e / b.conversion_gain_v_per_e,
        Effect::BlackLevel => s.black_level_dn - b.black_level_dn,
        Effect::DarkCurrent => s.dark_voltage_v_per_s,
        Effect::ReadNoise => s.read_noise_v,
        Effect::Dsnu => s.dsnu_sigma_v,
        Effect::Prnu => s.prnu_sigma_percent,
        Effect::ColumnFpn => s.column_fpn.map_or(0.0, |c| c.offset_sigma_v),
        Effect::HotPixels => s.effects.hot_pixels.map_or(0.0, |h| h.fraction),
        Effect::Nonlinearity => camsim_sensor::nonlinearity_magnitude(s, s.analog_gain),
        Effect::FullWell => s.well_capacity_e,
        Effect::RelativeIllumination => -st
            .rates
            .falloff
            .as_ref()
            .map_or(0.0, |c| c.iter().sum::<f64>()),
        Effect::VeilingGlare => st.rates.glare_fraction.unwrap_or(0.0),
        Effect::Defocus => st.rates.defocus_sigma_um.unwrap_or(0.0),
        Effect::Crosstalk => s.effects.crosstalk.map_or(0.0, |c| c.total()),
        Effect::IrLeakage => st
            .rates
            .ir_leakage
            .as_ref()
            .map_or(0.0, |v| v.iter().copied().fold(0.0, f64::max)),
        Effect::QeShift => st.rates.qe_shift_nm.as_ref().map_or(0.0, |v| {
            v.iter()
                .copied()
                .fold(0.0, |m, x| if x.abs() > f64::abs(m) { x } else { m })
        }),
        Effect::Distortion => st.rates.distortion.map_or(0.0, |[a, b]| a + b),
        Effect::LateralColor => st.rates.lateral_color_um.unwrap_or(0.0),
        Effect::RowNoise => s.effects.row_noise.map_or(0.0, |r| r.sigma_v),
        Effect::Rtn => s.effects.rtn.map_or(0.0, |r| r.fraction),
        Effect::BlackLevelDrift => s
            .effects
            .black_level_drift
            .map_or(0.0, |d| d.magnitude_dn(st.frames_in_set as usize)),
        Effect::DarkTemperature => s
            .effects
            .dark_temperature
            .map_or(f64::INFINITY, |d| d.doubling_temperature_c),
    }
}

#[cfg(test)]
mod tests {
    use super::lagrange;

    /// The interpolation the linearised fits use is exact for a polynomial of the nodes'
    /// degree: f(x) = fc + Σ l_k(x)(f_k − fc) and f'(x) = Σ l_k'(x)(f_k − fc), for a line
    /// through two nodes and a parabola through three unevenly spaced ones, at and between
    /// and beyond the nodes.
    #[test]
    fn lagrange_weights_reproduce_polynomials_and_their_slopes() {
        let cases: [(&[f64], usize, fn(f64) -> f64, fn(f64) -> f64); 2] = [
            (&[0.3, 1.1], 0, |x| 2.0 - 0.7 * x, |_| -0.7),
            (
                &[0.25, -0.4, 1.3],
                1,
                |x| 3.0 - 2.0 * x + 0.5 * x * x,
                |x| -2.0 + x,
            ),
        ];
        for (xs, c, f, df) in cases {
            for x in [-1.0, -0.4, 0.0, 0.25, 0.7, 1.3, 2.5] {
                let (w, dw) = lagrange(xs, c, x);
                let others: Vec<f64> = (0..xs.len())
                    .filter(|&k| k != c)
                    .map(|k| f(xs[k]) - f(xs[c]))
                    .collect();
                let v = f(xs[c]) + w.iter().zip(&others).map(|(a, b)| a * b).sum::<f64>();
                let d: f64 = dw.iter().zip(&others).map(|(a, b)| a * b).sum();
                assert!((v - f(x)).abs() < 1e-12, "{xs:?} x {x}: {v} vs {}", f(x));
                assert!((d - df(x)).abs() < 1e-12, "{xs:?} x {x}: {d} vs {}", df(x));
            }
        }
    }
}
