//! The likelihood of the reduced recording under a [`ModelState`], and the fit statistic.
//!
//! Per pixel i, shot s with F frames: frame mean m, temporal sample variance v, rail counts.
//! With the model's per-frame mean μ and temporal variance σ_t² ([`ShotConst::predict`]):
//!
//! * **temporal**: (F−1)·v/σ_t² ~ χ²(F−1) (a Gamma density in v);
//! * **fixed pattern**: the residual vector r_s = m_s − μ_s of a pixel over all its shots is
//!   Gaussian with covariance diag(σ_t²/F) + σ_D² u uᵀ + σ_P² w wᵀ: DSNU (u = DN per volt)
//!   and PRNU (w = DN per unit gain error) are the same random offsets/gains in every shot,
//!   so repeated frames separate temporal noise from fixed pattern and the shots' signal
//!   levels separate DSNU from PRNU (Woodbury form, [`Woodbury`]);
//! * **columns**: the residuals are split into per-column means (one "super-pixel" per
//!   column, whose covariance adds the column-offset variance σ_c² u uᵀ) and the deviations
//!   from them (within-column part), the exact decomposition of a Gaussian random-effects
//!   model with equal pixel variances;
//! * **hot pixels**: a two-component mixture per pixel: normal, or an extra dark rate V whose
//!   logarithm is N(ln V_h, σ_h²) across hot pixels, integrated by Laplace's method (by
//!   Gauss–Hermite quadrature over that prior when every shot of the pixel is censored);
//! * **clipping**: a pixel-shot with any frame at 0 DN or at the ADC maximum contributes the
//!   multinomial probability of its rail counts instead of its mean and variance.
//!
//! The reported χ²/dof sums, per pixel-shot, r²/Var(m) (marginal variance of the frame mean:
//! temporal/F + every fixed-pattern term) + (F−1)v/σ_t² (F degrees of freedom), or the
//! Pearson χ² of the rail counts (1 degree of freedom): close to 1 when the model explains
//! the recording.
use super::data::DataSet;
use super::model::{crosstalk_image, Forward, ModelState, Pred, RateSpec, ShotConst};
use super::num::{log_add_exp, Woodbury};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Stage timers for `CAMSIM_PROFILE` (nanoseconds, calls): fit-row and all-row evaluations,
/// forward-model calls.
pub mod prof {
    use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
    /// (nanoseconds, calls) per stage.
    pub static T: [AtomicU64; 6] = [const { AtomicU64::new(0) }; 6];
    /// Adds the time since `t0` to timer `k` and counts a call.
    pub fn add(k: usize, t0: std::time::Instant) {
        T[2 * k].fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
        T[2 * k + 1].fetch_add(1, Relaxed);
    }
    /// Likelihood evaluations so far (fit and all rows).
    pub fn calls() -> u64 {
        T[1].load(Relaxed) + T[3].load(Relaxed)
    }
    /// One line: time and calls per stage.
    pub fn summary() -> String {
        let names = [
            "likelihood, fit rows",
            "likelihood, all rows",
            "forward model",
        ];
        names
            .iter()
            .enumerate()
            .map(|(k, n)| {
                format!(
                    "{n}: {:.2} s / {} calls",
                    T[2 * k].load(Relaxed) as f64 * 1e-9,
                    T[2 * k + 1].load(Relaxed)
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// Rows per work block (fixed, so sums do not depend on the thread count).
const BLOCK_ROWS: usize = 8;
/// Rows per work block of the pixel pass (fixed, as [`BLOCK_ROWS`]).
const PIXEL_BLOCK_ROWS: usize = 2;
/// Most pixel-shot predictions the column pass keeps for the pixel pass (80 bytes each).
const PRED_STORE: usize = 1 << 20;
/// Fewest rows for the column decomposition.
pub(crate) const MIN_COLUMN_ROWS: usize = 8;

/// Per-shot rate images.
pub(crate) type Rates = Vec<Arc<Vec<f32>>>;

/// Shared state of a diagnosis: the data, the forward model, the rows used and caches.
pub(crate) struct Ctx<'a> {
    pub data: &'a DataSet,
    pub forward: &'a dyn Forward,
    /// Rows used while fitting (all rows of small sensors, a subset of large ones).
    pub fit_rows: Vec<usize>,
    /// All rows.
    pub all_rows: Vec<usize>,
    /// Pixels left out of the column means (isolated outliers found in the data alone).
    pub col_excluded: Vec<bool>,
    /// The fit rows and their neighbours above and below: the rows a rate image must hold
    /// for a fit-row evaluation (crosstalk reads the neighbours). Empty when the fit rows are
    /// all rows.
    pub calc_rows: Vec<usize>,
    /// The data of the fit rows, pixel-major: ((row position in `fit_rows`)·cols + column)·
    /// shots + shot.
    fit_pix: Vec<PixShot>,
    /// Forward-model results by rate spec, with their insertion stamp (oldest evicted first).
    cache: Mutex<HashMap<String, (u64, Arc<Rates>)>>,
    stamp: std::sync::atomic::AtomicU64,
    /// The last evaluations of whole states (the selection and every candidate of a round
    /// start from the same state; the final fit check repeats the last acceptance's).
    memo: Mutex<Vec<(ModelState, RowSel, Arc<Eval>)>>,
    /// Reused buffer of the column pass's predictions.
    pred_buf: Mutex<Vec<Pred>>,
}

/// Evaluations kept in [`Ctx`]'s memo.
const MEMO_EVALS: usize = 4;

/// One pixel's data in one shot, stored pixel-major for the fit rows ([`Ctx::fit_pix`]): the
/// pixel pass reads every shot of a pixel together, which from the per-shot arrays is one
/// cache miss per shot and field.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct PixShot {
    mean: f32,
    var: f32,
    n_lo: u16,
    n_hi: u16,
    censored: bool,
    /// Censored only because of its own rail frames ([`super::data::ShotData::rail_only`]).
    rail_only: bool,
}

/// Which rows an evaluation covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RowSel {
    Fit,
    All,
}

/// χ² and moments of one (shot, channel).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ScStat {
    /// Σ χ² contributions.
    pub chi2: f64,
    /// Degrees of freedom.
    pub dof: f64,
    /// Pixels (uncensored).
    pub n: f64,
    /// Σ residual of the frame mean (DN).
    pub sum_resid: f64,
    /// Σ model mean (DN).
    pub sum_model: f64,
    /// Σ data mean (DN).
    pub sum_data: f64,
    /// Σ model temporal variance (DN²).
    pub sum_model_var: f64,
    /// Σ data temporal variance (DN²) (shots with ≥ 2 frames).
    pub sum_data_var: f64,
    /// Σ marginal variance of the frame mean (DN²).
    pub sum_var_mean: f64,
    /// Σ r² (DN²).
    pub sum_r2: f64,
    /// Pixel-shots with rail frames.
    pub censored: f64,
}

impl ScStat {
    fn add(&mut self, o: &ScStat) {
        self.chi2 += o.chi2;
        self.dof += o.dof;
        self.n += o.n;
        self.sum_resid += o.sum_resid;
        self.sum_model += o.sum_model;
        self.sum_data += o.sum_data;
        self.sum_model_var += o.sum_model_var;
        self.sum_data_var += o.sum_data_var;
        self.sum_var_mean += o.sum_var_mean;
        self.sum_r2 += o.sum_r2;
        self.censored += o.censored;
    }
}

/// Result of one evaluation.
#[derive(Debug, Clone)]
pub struct Eval {
    /// Log-likelihood (constants dropped).
    pub logl: f64,
    /// Σ χ².
    pub chi2: f64,
    /// Σ degrees of freedom (before subtracting parameters).
    pub dof: f64,
    /// Per (shot, channel), shot-major.
    pub per_sc: Vec<ScStat>,
    /// Pixels classified as hot (posterior > 1/2).
    pub hot_pixels: usize,
    /// Column-term share of the log-likelihood.
    pub logl_columns: f64,
}

#[derive(Debug, Clone, Copy, Default)]
struct ColAcc {
    n: f64,
    sr: f64,
    sa: f64,
    su: f64,
    sw2: f64,
}

/// Per-(shot, column) column-mean statistics.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ColStat {
    pub n: f64,
    pub c_hat: f64,
    pub var_diag: f64,
    pub u_bar: f64,
    pub w_rms: f64,
    /// 1 − 1/n: the variance share a pixel keeps once its column mean is removed.
    pub kappa: f64,
    /// √kappa.
    pub sqrt_kappa: f64,
}

/// One column's [`ColStat`]s (shot-major table, column `j`); a shot's entry counts when the
/// column has at least two pixels in it.
#[derive(Clone, Copy)]
struct ColView<'c> {
    stats: &'c [ColStat],
    cols: usize,
    j: usize,
}

impl<'c> ColView<'c> {
    #[inline]
    fn get(&self, shot: usize) -> Option<&'c ColStat> {
        let x = &self.stats[shot * self.cols + self.j];
        (x.n >= 2.0).then_some(x)
    }
}

/// Hot-pixel mixture parameters.
#[derive(Debug, Clone, Copy)]
struct Hot {
    fraction: f64,
    ln_rate: f64,
    log_sigma: f64,
}

impl<'a> Ctx<'a> {
    pub fn new(data: &'a DataSet, forward: &'a dyn Forward, max_fit_pixels: usize) -> Self {
        let all_rows: Vec<usize> = (0..data.rows).collect();
        let fit_rows = if data.pixels() <= max_fit_pixels {
            all_rows.clone()
        } else {
            // Whole 2-row groups (CFA phases balanced), evenly spread over the sensor.
            let keep = (max_fit_pixels / data.cols.max(1)).max(16) / 2;
            let groups = data.rows / 2;
            let mut rows = Vec::new();
            for k in 0..keep.min(groups) {
                let g = k * groups / keep.min(groups);
                rows.push(2 * g);
                rows.push(2 * g + 1);
            }
            rows
        };
        let col_excluded = outlier_pixels(data);
        let calc_rows = if fit_rows.len() == data.rows {
            Vec::new()
        } else {
            let mut v: Vec<usize> = fit_rows
                .iter()
                .flat_map(|&r| [r.saturating_sub(1), r, (r + 1).min(data.rows - 1)])
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        let ns = data.shots.len();
        let mut fit_pix = vec![PixShot::default(); fit_rows.len() * data.cols * ns];
        fit_pix
            .par_chunks_mut(data.cols * ns)
            .zip(fit_rows.par_iter())
            .for_each(|(row, &r)| {
                for j in 0..data.cols {
                    gather_pixel(data, r * data.cols + j, &mut row[j * ns..(j + 1) * ns]);
                }
            });
        Ctx {
            calc_rows,
            fit_pix,
            data,
            forward,
            fit_rows,
            all_rows,
            col_excluded,
            cache: Mutex::new(HashMap::new()),
            stamp: std::sync::atomic::AtomicU64::new(0),
            memo: Mutex::new(Vec::new()),
            pred_buf: Mutex::new(Vec::new()),
        }
    }

    /// Rates of the forward model for `spec` (cached; the cache holds up to ~512 MB).
    pub fn base_rates(&self, spec: &RateSpec) -> Result<Arc<Rates>, String> {
        let key = spec.key();
        let next = || {
            self.stamp
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        };
        if let Some(r) = self.cache.lock().expect("cache").get_mut(&key) {
            r.0 = next();
            return Ok(r.1.clone());
        }
        let t0 = std::time::Instant::now();
        let r = self.forward.rates(spec)?;
        prof::add(2, t0);
        if r.len() != self.data.shots.len() {
            return Err(format!(
                "forward model returned {} rate images for {} shots",
                r.len(),
                self.data.shots.len()
            ));
        }
        for x in &r {
            if x.len() != self.data.pixels() {
                return Err("forward model returned a rate image of the wrong size".into());
            }
        }
        let unique = (0..r.len())
            .filter(|&i| !(0..i).any(|j| Arc::ptr_eq(&r[i], &r[j])))
            .count()
            .max(1);
        let entry_bytes = unique * self.data.pixels() * 4;
        let max_entries = ((512usize << 20) / entry_bytes.max(1)).clamp(8, 4096);
        let r = Arc::new(r);
        let mut c = self.cache.lock().expect("cache");
        while c.len() >= max_entries {
            let oldest = c
                .iter()
                .min_by_key(|(_, v)| v.0)
                .map(|(k, _)| k.clone())
                .expect("non-empty");
            c.remove(&oldest);
        }
        c.insert(key, (next(), r.clone()));
        Ok(r)
    }

    /// Rates with the state's exposure factor and crosstalk applied.
    pub fn rates(&self, state: &ModelState) -> Result<Rates, String> {
        let base = self.base_rates(&state.rates)?;
        Ok(self.transform(&base, state))
    }

    /// Exposure factor and crosstalk applied to base rates (shots sharing an image share the
    /// result).
    pub fn transform(&self, base: &[Arc<Vec<f32>>], state: &ModelState) -> Rates {
        let ct = state.sensor.effects.crosstalk;
        let f = state.exposure_factor;
        if f == 1.0 && ct.is_none() {
            return base.to_vec();
        }
        let mut out: Vec<Arc<Vec<f32>>> = Vec::with_capacity(base.len());
        for (i, b) in base.iter().enumerate() {
            if let Some(j) = (0..i).find(|&j| Arc::ptr_eq(&base[j], b)) {
                out.push(out[j].clone());
                continue;
            }
            let mut v: Vec<f32> = if f == 1.0 {
                b.to_vec()
            } else {
                b.par_iter().map(|&x| (x as f64 * f) as f32).collect()
            };
            if let Some(ct) = &ct {
                v = crosstalk_image(ct, self.data.rows, self.data.cols, &v);
            }
            out.push(Arc::new(v));
        }
        out
    }

    /// [`Ctx::transform`] on the fit rows only (elsewhere 0): for fit-row evaluations of rate
    /// images that hold [`Ctx::calc_rows`]. Same values on the fit rows (the same scaling and
    /// crosstalk rule, camsim_sensor::apply_crosstalk).
    pub fn transform_fit(&self, base: &[Arc<Vec<f32>>], state: &ModelState) -> Rates {
        let ct = state.sensor.effects.crosstalk;
        let f = state.exposure_factor;
        if self.calc_rows.is_empty() || (f == 1.0 && ct.is_none()) {
            return self.transform(base, state);
        }
        let (rows, cols) = (self.data.rows, self.data.cols);
        let mut out: Vec<Arc<Vec<f32>>> = Vec::with_capacity(base.len());
        for (i, b) in base.iter().enumerate() {
            if let Some(j) = (0..i).find(|&j| Arc::ptr_eq(&base[j], b)) {
                out.push(out[j].clone());
                continue;
            }
            // the scaled image (f32, as transform stores it) at (r, c)
            let at = |r: usize, c: usize| -> f64 {
                let x = b[r * cols + c];
                (if f == 1.0 { x } else { (x as f64 * f) as f32 }) as f64
            };
            let fit_rows: Vec<(usize, Vec<f32>)> = self
                .fit_rows
                .par_iter()
                .map(|&r| {
                    let row: Vec<f32> = (0..cols)
                        .map(|c| match &ct {
                            None => at(r, c) as f32,
                            Some(ct) => camsim_sensor::effects::crosstalk_at(
                                ct,
                                1.0 - ct.total(),
                                rows,
                                cols,
                                r,
                                c,
                                &at,
                            ) as f32,
                        })
                        .collect();
                    (r, row)
                })
                .collect();
            let mut v = vec![0f32; rows * cols];
            for (r, row) in fit_rows {
                v[r * cols..(r + 1) * cols].copy_from_slice(&row);
            }
            out.push(Arc::new(v));
        }
        out
    }

    fn rows(&self, sel: RowSel) -> &[usize] {
        match sel {
            RowSel::Fit => &self.fit_rows,
            RowSel::All => &self.all_rows,
        }
    }

    /// Whether the column decomposition is used for this row selection.
    pub fn column_term(&self, sel: RowSel) -> bool {
        self.rows(sel).len() >= MIN_COLUMN_ROWS
    }

    /// Log-likelihood and χ² of the state.
    pub fn evaluate(&self, state: &ModelState, sel: RowSel) -> Result<Eval, String> {
        if let Some(e) = self.memo_get(state, sel) {
            return Ok(e);
        }
        let rates = self.rates(state)?;
        Ok(self.evaluate_memo(state, &rates, sel))
    }

    fn memo_get(&self, state: &ModelState, sel: RowSel) -> Option<Eval> {
        let m = self.memo.lock().expect("memo");
        m.iter()
            .find(|(st, s, _)| *s == sel && st == state)
            .map(|x| (*x.2).clone())
    }

    /// [`Ctx::evaluate_with`] for `rates` = [`Ctx::rates`] of `state`, remembered.
    pub(crate) fn evaluate_memo(&self, state: &ModelState, rates: &Rates, sel: RowSel) -> Eval {
        if let Some(e) = self.memo_get(state, sel) {
            return e;
        }
        let e = self.evaluate_with(state, rates, sel);
        let mut m = self.memo.lock().expect("memo");
        if m.len() >= MEMO_EVALS {
            m.remove(0);
        }
        m.push((state.clone(), sel, Arc::new(e.clone())));
        e
    }

    /// Per-shot chain constants.
    pub fn consts(&self, state: &ModelState) -> Vec<ShotConst> {
        self.data
            .shots
            .iter()
            .map(|s| ShotConst::new(&state.sensor, s.exposure_s, s.analog_gain, s.frames))
            .collect()
    }

    /// Column-mean statistics of the residuals (per shot, column), shot-major.
    /// With `store`, also every pixel-shot's prediction, at
    /// ((row position in the selection)·cols + column)·shots + shot, for the pixel pass.
    fn column_stats_store(
        &self,
        rates: &Rates,
        consts: &[ShotConst],
        sel: RowSel,
        store: Option<&mut [Pred]>,
    ) -> Vec<ColStat> {
        let d = self.data;
        let (ns, cols) = (d.shots.len(), d.cols);
        let rows = self.rows(sel);
        let per_block = BLOCK_ROWS * cols * ns;
        let mut dummy: Vec<Pred> = Vec::new();
        let (stored, buf): (bool, &mut [Pred]) = match store {
            Some(b) => (true, b),
            None => (false, &mut dummy[..]),
        };
        let n_blocks = rows.len().div_ceil(BLOCK_ROWS);
        let mut bufs: Vec<&mut [Pred]> = if stored {
            buf.chunks_mut(per_block).collect()
        } else {
            (0..n_blocks).map(|_| &mut [][..]).collect()
        };
        // Pixel-major data of these rows (the fit rows, or all rows when they are the same).
        let pix = (sel == RowSel::Fit || self.calc_rows.is_empty()).then_some(&self.fit_pix[..]);
        let blocks: Vec<Vec<ColAcc>> = rows
            .par_chunks(BLOCK_ROWS)
            .zip(bufs.par_iter_mut())
            .enumerate()
            .map(|(bi, (blk, pb))| {
                let mut acc = vec![ColAcc::default(); ns * cols];
                match (stored, pix) {
                    (true, Some(pix)) => {
                        // pixel-major: the predictions are written in the order the pixel
                        // pass reads them (the same sums per (shot, column) as below)
                        for (ri, &r) in blk.iter().enumerate() {
                            for j in 0..cols {
                                let i = r * cols + j;
                                let at = (ri * cols + j) * ns;
                                let px = &pix[((bi * BLOCK_ROWS + ri) * cols + j) * ns..][..ns];
                                for s in 0..ns {
                                    let c = &consts[s];
                                    let p = c.predict(rates[s][i] as f64 * c.t, 0.0);
                                    pb[at + s] = p;
                                    if self.col_excluded[i] || px[s].censored {
                                        continue;
                                    }
                                    let a = &mut acc[s * cols + j];
                                    a.n += 1.0;
                                    a.sr += px[s].mean as f64 - p.mean;
                                    a.sa += c.var_mean(&p);
                                    a.su += p.u;
                                    a.sw2 += p.w * p.w;
                                }
                            }
                        }
                    }
                    _ => {
                        for (ri, &r) in blk.iter().enumerate() {
                            for (s, sh) in d.shots.iter().enumerate() {
                                let c = &consts[s];
                                let rate = &rates[s];
                                for j in 0..cols {
                                    let i = r * cols + j;
                                    let skip = self.col_excluded[i] || sh.censored[i];
                                    if skip && !stored {
                                        continue;
                                    }
                                    let p = c.predict(rate[i] as f64 * c.t, 0.0);
                                    if stored {
                                        pb[(ri * cols + j) * ns + s] = p;
                                    }
                                    if skip {
                                        continue;
                                    }
                                    let a = &mut acc[s * cols + j];
                                    a.n += 1.0;
                                    a.sr += sh.mean_dn[i] as f64 - p.mean;
                                    a.sa += c.var_mean(&p);
                                    a.su += p.u;
                                    a.sw2 += p.w * p.w;
                                }
                            }
                        }
                    }
                }
                acc
            })
            .collect();
        let mut tot = vec![ColAcc::default(); ns * cols];
        for b in &blocks {
            for (t, x) in tot.iter_mut().zip(b) {
                t.n += x.n;
                t.sr += x.sr;
                t.sa += x.sa;
                t.su += x.su;
                t.sw2 += x.sw2;
            }
        }
        tot.iter()
            .map(|a| {
                if a.n < 1.0 {
                    ColStat::default()
                } else {
                    ColStat {
                        n: a.n,
                        c_hat: a.sr / a.n,
                        var_diag: a.sa / (a.n * a.n),
                        u_bar: a.su / a.n,
                        w_rms: (a.sw2 / a.n).sqrt(),
                        kappa: 1.0 - 1.0 / a.n,
                        sqrt_kappa: (1.0 - 1.0 / a.n).sqrt(),
                    }
                }
            })
            .collect()
    }

    /// Evaluation with given (transformed) rates.
    pub fn evaluate_with(&self, state: &ModelState, rates: &Rates, sel: RowSel) -> Eval {
        let t0 = std::time::Instant::now();
        let e = self.evaluate_inner(state, rates, sel, true);
        prof::add(if sel == RowSel::Fit { 0 } else { 1 }, t0);
        e
    }

    /// The log-likelihood alone (what the fits maximise): [`Ctx::evaluate_with`] without the
    /// χ² and moment sums.
    pub fn logl_with(&self, state: &ModelState, rates: &Rates, sel: RowSel) -> f64 {
        let t0 = std::time::Instant::now();
        let e = self.evaluate_inner(state, rates, sel, false);
        prof::add(if sel == RowSel::Fit { 0 } else { 1 }, t0);
        e.logl
    }

    fn evaluate_inner(&self, state: &ModelState, rates: &Rates, sel: RowSel, stats: bool) -> Eval {
        let d = self.data;
        let (ns, cols, nch) = (d.shots.len(), d.cols, d.channels());
        let consts = self.consts(state);
        let s = &state.sensor;
        let sig_d = if s.noise.dsnu { s.dsnu_sigma_v } else { 0.0 };
        let sig_p = if s.noise.prnu {
            s.prnu_sigma_percent / 100.0
        } else {
            0.0
        };
        let sig_c = s.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
        let hot = s
            .effects
            .hot_pixels
            .filter(|h| h.fraction > 0.0 && h.dark_voltage_v_per_s > 0.0)
            .map(|h| Hot {
                fraction: h.fraction.min(0.5),
                ln_rate: h.dark_voltage_v_per_s.ln(),
                log_sigma: h.log_sigma,
            });
        let use_cols = self.column_term(sel);
        let rows = self.rows(sel);
        // The column pass keeps its predictions for the pixel pass (when they fit in
        // PRED_STORE pixel-shots, e.g. the fit rows of a large sensor).
        let n_ps = rows.len() * cols * ns;
        let mut store: Vec<Pred> = Vec::new();
        let use_store = use_cols && n_ps <= PRED_STORE;
        if use_store {
            store = std::mem::take(&mut *self.pred_buf.lock().expect("pred buffer"));
            store.resize(n_ps, Pred::default());
        }
        let col = if use_cols {
            self.column_stats_store(rates, &consts, sel, use_store.then_some(&mut store[..]))
        } else {
            Vec::new()
        };
        let stored: Option<&[Pred]> = use_store.then_some(&store[..]);
        // Column term: per column, the S-vector of column-mean residuals.
        let mut logl_columns = 0.0;
        if use_cols {
            let terms: Vec<f64> = (0..cols)
                .into_par_iter()
                .map(|j| {
                    let mut wb = Woodbury::default();
                    let n_max = (0..ns).map(|s| col[s * cols + j].n).fold(0.0, f64::max);
                    if n_max < 2.0 {
                        return 0.0;
                    }
                    let b1 = (sig_d * sig_d / n_max + sig_c * sig_c).sqrt();
                    let b2 = sig_p / n_max.sqrt();
                    for s in 0..ns {
                        let c = &col[s * cols + j];
                        if c.n < 2.0 || c.var_diag <= 0.0 {
                            continue;
                        }
                        wb.add(c.c_hat, c.var_diag, [b1 * c.u_bar, b2 * c.w_rms]);
                    }
                    if wb.is_empty() {
                        0.0
                    } else {
                        wb.log_likelihood()
                    }
                })
                .collect();
            logl_columns = terms.iter().sum();
        }
        // Pixel term (blocks of PIXEL_BLOCK_ROWS rows: enough pieces to balance the threads
        // on a few fit rows).
        let blocks: Vec<(f64, Vec<ScStat>, usize)> = rows
            .par_chunks(PIXEL_BLOCK_ROWS)
            .enumerate()
            .map(|(bi, blk)| {
                let mut ll = 0.0;
                let mut sc = vec![ScStat::default(); ns * nch];
                let mut n_hot = 0usize;
                let mut preds_buf: Vec<Pred> = vec![Pred::default(); ns];
                let mut es: Vec<f64> = vec![0.0; ns];
                let mut hot_buf: Vec<Pred> = vec![Pred::default(); ns];
                let mut pxbuf: Vec<PixShot> = vec![PixShot::default(); ns];
                let mut edev = ExpectedDevianceCache::default();
                // Hot-class likelihoods of pixels censored in every shot: they depend on the
                // pixel's expected electrons and rail counts alone (the rail likelihood reads
                // neither the column nor the fixed-pattern terms), which most pixels of a
                // uniform shot share.
                let mut hot_memo: HashMap<Vec<(u64, u16, u16)>, (f64, Vec<Pred>)> = HashMap::new();
                for (ri, &r) in blk.iter().enumerate() {
                    for j in 0..cols {
                        let i = r * cols + j;
                        let ch = d.channel[i] as usize;
                        let at = ((bi * PIXEL_BLOCK_ROWS + ri) * cols + j) * ns;
                        let px: &[PixShot] = if sel == RowSel::Fit || self.calc_rows.is_empty() {
                            &self.fit_pix[at..at + ns]
                        } else {
                            gather_pixel(d, i, &mut pxbuf);
                            &pxbuf
                        };
                        // the column pass's predictions, or computed here
                        let preds: &[Pred] = match stored {
                            Some(st) => &st[at..at + ns],
                            None => {
                                for (sidx, c) in consts.iter().enumerate() {
                                    preds_buf[sidx] = c.predict(rates[sidx][i] as f64 * c.t, 0.0);
                                }
                                &preds_buf
                            }
                        };
                        let cs = use_cols.then_some(ColView {
                            stats: &col,
                            cols,
                            j,
                        });
                        let l0 = self.pixel_ll(
                            px,
                            preds,
                            &consts,
                            cs,
                            sig_d,
                            sig_p,
                            if use_cols { 0.0 } else { sig_c },
                        );
                        let mut hot_class = false;
                        let li = match &hot {
                            None => l0,
                            Some(h) => {
                                for (sidx, c) in consts.iter().enumerate() {
                                    es[sidx] = rates[sidx][i] as f64 * c.t;
                                }
                                let key: Option<Vec<(u64, u16, u16)>> =
                                    px.iter().all(|x| x.censored).then(|| {
                                        px.iter()
                                            .zip(&es)
                                            .map(|(x, e)| (e.to_bits(), x.n_lo, x.n_hi))
                                            .collect()
                                    });
                                let memo = key.as_ref().and_then(|k| hot_memo.get(k));
                                let lh = if let Some((l, hpm)) = memo {
                                    hot_buf.copy_from_slice(hpm);
                                    *l
                                } else {
                                    let lh = self.hot_ll(
                                        px,
                                        preds,
                                        &es,
                                        &consts,
                                        cs,
                                        sig_d,
                                        sig_p,
                                        sig_c,
                                        use_cols,
                                        h,
                                        &mut hot_buf,
                                    );
                                    if let Some(k) = key {
                                        hot_memo.insert(k, (lh, hot_buf.clone()));
                                    }
                                    lh
                                };
                                let a = (1.0 - h.fraction).ln() + l0;
                                let b = h.fraction.ln() + lh;
                                let tot = log_add_exp(a, b);
                                // posterior of the hot class > 1/2
                                if b - tot > -std::f64::consts::LN_2 {
                                    n_hot += 1;
                                    hot_class = true;
                                }
                                tot
                            }
                        };
                        ll += li;
                        if !stats {
                            continue;
                        }
                        // Reported χ² (marginal per pixel-shot) with the pixel's class.
                        let used = if hot_class { &hot_buf[..] } else { preds };
                        for sidx in 0..ns {
                            let sh = &d.shots[sidx];
                            let x = &px[sidx];
                            let p = &used[sidx];
                            let st = &mut sc[sidx * nch + ch];
                            let f = consts[sidx].frames;
                            let (nlo, nhi) = (x.n_lo as f64, x.n_hi as f64);
                            if x.censored {
                                // Deviance (likelihood-ratio G²) of the rail counts:
                                // 2·(lnL of the saturated multinomial − lnL of the model), the
                                // same likelihood the fit maximises. (Pearson's (n−m)²/var is
                                // not: one rail frame where the model expects 10⁻⁴ adds 10⁴
                                // to it but only ≈ 9 to −lnL, so a fit that improves lnL could
                                // make χ² explode, as on the Flea3 8-bit darks.) Every censored
                                // term is kept, and its dof is the deviance the model itself
                                // expects, E[G²] (exact sum over the rail-count outcomes): for
                                // sparse counts E[G²] is far from 1 (≈ 2Fp·ln(1/p) for a rare
                                // rail), so counting 1 per term, or leaving out the terms
                                // whose rail frames the model does not expect, made χ²/dof
                                // and the likelihood disagree (a lnL gain could raise χ²/dof).
                                // With a model-independent saturated term a lnL gain of Δ
                                // lowers Σ G² by 2Δ, and Σ G² / Σ E[G²] ≈ 1 under the model.
                                let (g2, e_g2) = edev.term(p, f, nlo, nhi, x.rail_only);
                                st.censored += 1.0;
                                st.chi2 += g2;
                                st.dof += e_g2;
                                continue;
                            }
                            let m = x.mean as f64;
                            let rr = m - p.mean;
                            let vm = consts[sidx].var_mean(p)
                                + (sig_d * sig_d + sig_c * sig_c) * p.u * p.u
                                + sig_p * sig_p * p.w * p.w;
                            st.chi2 += rr * rr / vm;
                            st.dof += 1.0;
                            st.n += 1.0;
                            st.sum_resid += rr;
                            st.sum_model += p.mean;
                            st.sum_data += m;
                            st.sum_model_var += p.var_t;
                            st.sum_var_mean += vm;
                            st.sum_r2 += rr * rr;
                            if sh.has_variance() {
                                let v = x.var as f64;
                                st.chi2 += (f - 1.0) * v / p.var_t;
                                st.dof += f - 1.0;
                                st.sum_data_var += v;
                            }
                        }
                    }
                }
                (ll, sc, n_hot)
            })
            .collect();
        let mut logl = logl_columns;
        let mut per_sc = vec![ScStat::default(); ns * nch];
        let mut hot_pixels = 0;
        for (ll, sc, nh) in &blocks {
            logl += ll;
            for (t, x) in per_sc.iter_mut().zip(sc) {
                t.add(x);
            }
            hot_pixels += nh;
        }
        if use_store {
            *self.pred_buf.lock().expect("pred buffer") = store;
        }
        let chi2 = per_sc.iter().map(|x| x.chi2).sum();
        let dof = per_sc.iter().map(|x| x.dof).sum();
        Eval {
            logl,
            chi2,
            dof,
            per_sc,
            hot_pixels,
            logl_columns,
        }
    }

    /// Log-likelihood of one pixel over all shots (normal component).
    #[allow(clippy::too_many_arguments)]
    fn pixel_ll<'c>(
        &self,
        px: &[PixShot],
        preds: &[Pred],
        consts: &[ShotConst],
        col: Option<ColView<'c>>,
        sig_d: f64,
        sig_p: f64,
        sig_c_pixel: f64,
    ) -> f64 {
        let d = self.data;
        let mut wb = Woodbury::default();
        let mut ll = 0.0;
        let sig_u = (sig_d * sig_d + sig_c_pixel * sig_c_pixel).sqrt();
        for (sidx, (sh, x)) in d.shots.iter().zip(px).enumerate() {
            let p = &preds[sidx];
            let f = consts[sidx].frames;
            let (nlo, nhi) = (x.n_lo as f64, x.n_hi as f64);
            if x.censored {
                ll += rail_stats(p, f, nlo, nhi).ll;
                continue;
            }
            let mut r = x.mean as f64 - p.mean;
            let (mut kappa, mut sk) = (1.0, 1.0);
            if let Some(c) = col.and_then(|v| v.get(sidx)) {
                r -= c.c_hat;
                kappa = c.kappa;
                sk = c.sqrt_kappa;
            }
            let a = kappa * consts[sidx].var_mean(p);
            wb.add(r, a, [sk * sig_u * p.u, sk * sig_p * p.w]);
            if sh.has_variance() {
                // temporal_ll, with its −(F−1)/2 · ln σ² folded into the determinant
                let k = f as u32 - 1;
                if f == (k + 1) as f64 && k <= 64 {
                    ll += -0.5 * (f - 1.0) * (x.var as f64 / p.var_t);
                    wb.mul_det_pow(p.var_t, k);
                } else {
                    ll += temporal_ll(x.var as f64, p.var_t, f);
                }
            }
        }
        if !wb.is_empty() {
            ll += wb.log_likelihood();
        }
        ll
    }

    /// Log-likelihood of one pixel as a hot pixel (Laplace integral over its rate, or
    /// quadrature over the rate's prior when every shot is censored: the Laplace step's
    /// linearised rate uses uncensored shots only); its predictions at the most probable
    /// rate go to `hp`.
    #[allow(clippy::too_many_arguments)]
    fn hot_ll<'c>(
        &self,
        px: &[PixShot],
        preds: &[Pred],
        es: &[f64],
        consts: &[ShotConst],
        col: Option<ColView<'c>>,
        sig_d: f64,
        sig_p: f64,
        sig_c: f64,
        use_cols: bool,
        h: &Hot,
        hp: &mut [Pred],
    ) -> f64 {
        // Linearised response to an extra dark rate V: h_s = c_s V, c_s = DN/e · t/g.
        let (mut srr, mut scc) = (0.0, 0.0);
        for (sidx, x) in px.iter().enumerate() {
            if x.censored {
                continue;
            }
            let p = &preds[sidx];
            let c = &consts[sidx];
            let cs = p.dn_per_e * c.t / c.g;
            let mut r = x.mean as f64 - p.mean;
            if let Some(x) = col.and_then(|v| v.get(sidx)) {
                r -= x.c_hat;
            }
            let a = c.var_mean(p);
            srr += r * cs / a;
            scc += cs * cs / a;
        }
        let mu = h.ln_rate;
        // The pixel's predictions with an extra dark rate v (V/s), and its likelihood then.
        let predict_at = |v: f64, hp: &mut [Pred]| {
            for ((o, c), &e) in hp.iter_mut().zip(consts).zip(es) {
                *o = c.predict(e, c.t * v / c.g);
            }
        };
        let ll_at = |v: f64, hp: &mut [Pred]| -> f64 {
            predict_at(v, hp);
            let sig_c_pixel = if use_cols { 0.0 } else { sig_c };
            self.pixel_ll(px, hp, consts, col, sig_d, sig_p, sig_c_pixel)
        };
        if h.log_sigma > 1e-6 && scc == 0.0 {
            // Every shot censored: the rail counts alone carry the rate; the Laplace step
            // has no data curvature to work with, so integrate over the prior of ln V
            // (Gauss–Hermite) with the full (rail) likelihood.
            let gh = super::num::gauss_hermite_24();
            let mut terms = [0.0f64; 24];
            let (mut best, mut v_best) = (f64::NEG_INFINITY, mu.exp());
            for (k, &(z, w)) in gh.iter().enumerate() {
                let v = (mu + h.log_sigma * z).exp();
                terms[k] = ll_at(v, hp) + w.ln();
                if terms[k] > best {
                    best = terms[k];
                    v_best = v;
                }
            }
            let sum: f64 = terms.iter().map(|t| (t - best).exp()).sum();
            predict_at(v_best, hp);
            return best + sum.ln();
        }
        let (x_star, log_prior_term) = if h.log_sigma > 1e-6 && scc > 0.0 {
            let v_hat = srr / scc;
            let s2 = h.log_sigma * h.log_sigma;
            // Newton on x = ln V of  −½ I (e^x − V̂)² − (x − μ)²/(2σ²).
            let mut x = mu;
            for _ in 0..30 {
                let ex = x.exp();
                let g = -scc * (ex - v_hat) * ex - (x - mu) / s2;
                let hh = -scc * (2.0 * ex * ex - v_hat * ex) - 1.0 / s2;
                let step = if hh < 0.0 { -g / hh } else { g.signum() * 0.5 };
                let step = step.clamp(-2.0, 2.0);
                x += step;
                if step.abs() < 1e-8 {
                    break;
                }
            }
            let ex = x.exp();
            let curv = scc * ex * ex + 1.0 / s2;
            let lp = -0.5 * (x - mu) * (x - mu) / s2 - 0.5 * (2.0 * std::f64::consts::PI * s2).ln()
                + 0.5 * (2.0 * std::f64::consts::PI / curv).ln();
            (x, lp)
        } else {
            (mu, 0.0)
        };
        ll_at(x_star.exp(), hp) + log_prior_term
    }
}

/// The data of pixel `i` in every shot.
fn gather_pixel(d: &DataSet, i: usize, out: &mut [PixShot]) {
    for (o, sh) in out.iter_mut().zip(&d.shots) {
        *o = PixShot {
            mean: sh.mean_dn[i],
            var: if sh.has_variance() { sh.var_dn[i] } else { 0.0 },
            n_lo: sh.n_low[i],
            n_hi: sh.n_high[i],
            censored: sh.censored[i],
            rail_only: sh.rail_only[i],
        };
    }
}

/// Gamma log-density (constants dropped) of a sample variance v with F frames and true
/// variance σ²: (F−1)v/σ² ~ χ²(F−1).
#[inline]
pub(crate) fn temporal_ll(v: f64, var: f64, f: f64) -> f64 {
    -0.5 * (f - 1.0) * (v / var + var.ln())
}

/// The rail counts of a censored pixel-shot under the model: log-likelihood and the mean
/// number of frames at a rail.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RailStat {
    pub ll: f64,
    /// (Read by the tests only since the χ² summary stopped using it.)
    #[allow(dead_code)]
    pub mean: f64,
}

/// Per-frame rail probabilities of a pixel-shot at the nodes of the fixed-pattern mixture
/// (z ~ N(0, s_f²), 24-point Gauss–Hermite; one node without fixed pattern): weight w,
/// p_lo(z) = Φ((0.5 − y − z)/s_t), p_hi(z) = 1 − Φ((M − 0.5 − y − z)/s_t).
struct RailNodes {
    n: usize,
    w: [f64; 24],
    plo: [f64; 24],
    phi: [f64; 24],
}

impl RailNodes {
    /// (w, p_lo, p_hi) of each node.
    fn iter(&self) -> impl Iterator<Item = (f64, f64, f64)> + '_ {
        (0..self.n).map(|k| (self.w[k], self.plo[k], self.phi[k]))
    }
}

fn rail_nodes(p: &Pred) -> RailNodes {
    use super::num::{gauss_hermite_24, norm_cdf};
    let (s_t, s_f) = (p.s2_t.sqrt(), p.s2_f.sqrt());
    let one = [(0.0, 1.0)];
    let nodes: &[(f64, f64)] = if s_f > 1e-9 * s_t.max(1e-300) {
        gauss_hermite_24()
    } else {
        &one
    };
    let st = s_t.max(1e-9);
    let mut r = RailNodes {
        n: nodes.len(),
        w: [0.0; 24],
        plo: [0.0; 24],
        phi: [0.0; 24],
    };
    for (k, &(z, w)) in nodes.iter().enumerate() {
        let y = p.y + s_f * z;
        r.w[k] = w;
        r.plo[k] = norm_cdf((0.5 - y) / st);
        r.phi[k] = 1.0 - norm_cdf((p.hi - 0.5 - y) / st);
    }
    r
}

/// The frames of a pixel share its fixed pattern, so its rail counts are a mixture over the
/// pixel's fixed offset z ~ N(0, s_f²) of multinomials with per-frame probabilities
/// p_lo(z) = Φ((0.5 − y − z)/s_t), p_hi(z) = 1 − Φ((M − 0.5 − y − z)/s_t) (24-point
/// Gauss–Hermite quadrature over z).
pub(crate) fn rail_stats(p: &Pred, f: f64, nlo: f64, nhi: f64) -> RailStat {
    let nmid = f - nlo - nhi;
    let nodes = rail_nodes(p);
    let mut lmax = f64::NEG_INFINITY;
    let mut terms = [(0.0f64, 0.0f64, 0.0f64); 24];
    let mut m1 = 0.0;
    for (k, (w, plo, phi)) in nodes.iter().enumerate() {
        let pm = (1.0 - plo - phi).max(0.0);
        let mut l = 0.0;
        if nlo > 0.0 {
            l += nlo * plo.max(1e-300).ln();
        }
        if nhi > 0.0 {
            l += nhi * phi.max(1e-300).ln();
        }
        if nmid > 0.0 {
            l += nmid * pm.max(1e-300).ln();
        }
        let l = l + w.ln();
        lmax = lmax.max(l);
        terms[k] = (l, 0.0, 0.0);
        let pr = (plo + phi).min(1.0);
        m1 += w * pr;
    }
    let sum: f64 = terms[..nodes.n].iter().map(|t| (t.0 - lmax).exp()).sum();
    RailStat {
        ll: lmax + sum.ln(),
        mean: f * m1,
    }
}

/// Deviance of a pixel-shot's rail counts (frames at the low rail, at the high rail, between):
/// G² = 2·(Σ_k n_k ln(n_k/F) − lnL_model) ≥ 0, since the model (a mixture of multinomials) is
/// never more likely than the saturated multinomial with the observed frequencies.
pub(crate) fn rail_deviance(rs: &RailStat, f: f64, nlo: f64, nhi: f64) -> f64 {
    let nmid = f - nlo - nhi;
    let sat: f64 = [nlo, nhi, nmid]
        .iter()
        .filter(|&&n| n > 0.0)
        .map(|&n| n * (n / f).ln())
        .sum();
    (2.0 * (sat - rs.ll)).max(0.0)
}

/// Expected deviance E[G²] of a censored pixel-shot's rail counts under the model (the dof
/// of its χ² term): Σ over the outcomes (n_lo, n_hi), n_lo + n_hi ≤ F, of P(n_lo, n_hi) ·
/// G²(n_lo, n_hi), with P the model's own distribution — the same Gauss–Hermite mixture of
/// multinomials as [`rail_stats`] times the multinomial coefficient — and G² as
/// [`rail_deviance`]. Exact for that model (no large-count approximation); a rail the model
/// reaches in under 10⁻¹⁵ frames at every fixed-pattern node is left out of the sum (its
/// share of E[G²] is below ≈ 10⁻¹³). `given_rail`: the pixel-shot is censored only because
/// one of its own frames hit a rail ([`super::data::ShotData::rail_only`]), so it is seen
/// only with n_lo + n_hi ≥ 1 and the expectation is conditional on that. Costs
/// (F + 1)·24 exponentials near one rail, (F + 1)(F + 2)/2·24 near both.
pub(crate) fn rail_expected_deviance(p: &Pred, f: f64, given_rail: bool) -> f64 {
    let nf = f.round().max(0.0) as usize;
    if nf == 0 {
        return 0.0;
    }
    let nodes = rail_nodes(p);
    let mut ln_node = [(0.0f64, 0.0f64, 0.0f64, 0.0f64); 24];
    let (mut max_lo, mut max_hi) = (0.0f64, 0.0f64);
    for (k, (w, plo, phi)) in nodes.iter().enumerate() {
        let pm = (1.0 - plo - phi).max(0.0);
        ln_node[k] = (
            w.ln(),
            plo.max(1e-300).ln(),
            phi.max(1e-300).ln(),
            pm.max(1e-300).ln(),
        );
        max_lo = max_lo.max(plo);
        max_hi = max_hi.max(phi);
    }
    let ln_node = &ln_node[..nodes.n];
    let mut lo_on = max_lo * f >= 1e-15;
    let mut hi_on = max_hi * f >= 1e-15;
    if given_rail && !lo_on && !hi_on {
        // Conditional on a rail frame the model all but excludes: keep the likelier rail.
        if max_lo >= max_hi {
            lo_on = true;
        } else {
            hi_on = true;
        }
    }
    let lo_max = if lo_on { nf } else { 0 };
    let hi_max = if hi_on { nf } else { 0 };
    let mut ln_fact = Vec::with_capacity(nf + 1);
    ln_fact.push(0.0f64);
    for k in 1..=nf {
        ln_fact.push(ln_fact[k - 1] + (k as f64).ln());
    }
    // (ln P, G²) of each outcome; normalised at the end (log domain: P can underflow).
    let mut out: Vec<(f64, f64)> = Vec::with_capacity((lo_max + 1) * (hi_max + 1));
    let mut terms = [0.0f64; 24];
    for a in 0..=lo_max {
        for b in 0..=hi_max.min(nf - a) {
            if given_rail && a + b == 0 {
                continue;
            }
            let c = nf - a - b;
            let (af, bf, cf) = (a as f64, b as f64, c as f64);
            let mut lmax = f64::NEG_INFINITY;
            for (k, &(lw, llo, lhi, lmid)) in ln_node.iter().enumerate() {
                let mut l = lw;
                if a > 0 {
                    l += af * llo;
                }
                if b > 0 {
                    l += bf * lhi;
                }
                if c > 0 {
                    l += cf * lmid;
                }
                terms[k] = l;
                lmax = lmax.max(l);
            }
            let sum: f64 = terms[..ln_node.len()]
                .iter()
                .map(|&l| (l - lmax).exp())
                .sum();
            let ll = lmax + sum.ln();
            let sat: f64 = [af, bf, cf]
                .iter()
                .filter(|&&n| n > 0.0)
                .map(|&n| n * (n / f).ln())
                .sum();
            let g2 = (2.0 * (sat - ll)).max(0.0);
            let ln_p = ln_fact[nf] - ln_fact[a] - ln_fact[b] - ln_fact[c] + ll;
            out.push((ln_p, g2));
        }
    }
    let m = out.iter().fold(f64::NEG_INFINITY, |a, x| a.max(x.0));
    if !m.is_finite() {
        return 0.0;
    }
    let (mut sp, mut sg) = (0.0, 0.0);
    for &(lp, g2) in &out {
        let w = (lp - m).exp();
        sp += w;
        sg += w * g2;
    }
    sg / sp
}

/// Memo of [`rail_expected_deviance`] within one block of an evaluation: the pixel-shots of a
/// uniform (e.g. dark) shot share their prediction, so most lookups hit.
#[derive(Default)]
pub(crate) struct ExpectedDevianceCache {
    map: HashMap<[u64; 6], f64>,
}

impl ExpectedDevianceCache {
    /// Entries kept before the memo is cleared (a textured scene has a prediction per pixel).
    const MAX: usize = 1 << 14;

    fn get(&mut self, p: &Pred, f: f64, given_rail: bool) -> f64 {
        let key = [
            p.y.to_bits(),
            p.s2_t.to_bits(),
            p.s2_f.to_bits(),
            p.hi.to_bits(),
            f.to_bits(),
            given_rail as u64,
        ];
        if let Some(&v) = self.map.get(&key) {
            return v;
        }
        if self.map.len() >= Self::MAX {
            self.map.clear();
        }
        let v = rail_expected_deviance(p, f, given_rail);
        self.map.insert(key, v);
        v
    }

    /// The χ² summary's (χ², dof) of a censored pixel-shot: (G², E[G²]).
    pub(crate) fn term(
        &mut self,
        p: &Pred,
        f: f64,
        nlo: f64,
        nhi: f64,
        given_rail: bool,
    ) -> (f64, f64) {
        let rs = rail_stats(p, f, nlo, nhi);
        (rail_deviance(&rs, f, nlo, nhi), self.get(p, f, given_rail))
    }
}

/// Pixels that stand out from their same-channel neighbours in the same column (±2, ±4
/// rows) by more than 8 robust σ in some shot: excluded from the column means so that a few
/// hot or dead pixels do not masquerade as column offsets. Depends on the data only.
fn outlier_pixels(d: &DataSet) -> Vec<bool> {
    let (rows, cols) = (d.rows, d.cols);
    let mut out = vec![false; rows * cols];
    if rows < 9 {
        return out;
    }
    for sh in &d.shots {
        let dev: Vec<f32> = (0..rows * cols)
            .into_par_iter()
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                let mut nb = [0f32; 4];
                let mut k = 0;
                for dr in [-4i64, -2, 2, 4] {
                    let rr = r as i64 + dr;
                    if rr >= 0 && (rr as usize) < rows {
                        nb[k] = sh.mean_dn[rr as usize * cols + c];
                        k += 1;
                    }
                }
                let nb = &mut nb[..k];
                nb.sort_by(|a, b| a.total_cmp(b));
                let med = if k % 2 == 1 {
                    nb[k / 2]
                } else {
                    0.5 * (nb[k / 2 - 1] + nb[k / 2])
                };
                sh.mean_dn[i] - med
            })
            .collect();
        // robust σ from a strided sample
        let step = (dev.len() / 20000).max(1);
        let sample: Vec<f64> = dev.iter().step_by(step).map(|&x| x as f64).collect();
        let sigma = super::num::robust_sigma(&sample).max(1e-3);
        let med = super::num::median(&sample);
        for (o, &x) in out.iter_mut().zip(&dev) {
            if (x as f64 - med).abs() > 8.0 * sigma {
                *o = true;
            }
        }
    }
    out
}

/// Weighted least-squares normal equations of the frame means for small changes of linear
/// rate parameters: `d_k = ∂μ/∂θ_k = DN/e · t · basis_k`, weights 1/Var(m) (marginal),
/// residuals r = m − μ. Returns (A, b) with A = Σ w d dᵀ (K×K, row-major), b = Σ w d r.
impl Ctx<'_> {
    pub(crate) fn normal_equations(
        &self,
        state: &ModelState,
        rates: &Rates,
        basis: &[Rates],
        sel: RowSel,
    ) -> (Vec<f64>, Vec<f64>) {
        let d = self.data;
        let (ns, cols) = (d.shots.len(), d.cols);
        let kk = basis.len();
        let consts = self.consts(state);
        let s = &state.sensor;
        let sig_d = if s.noise.dsnu { s.dsnu_sigma_v } else { 0.0 };
        let sig_p = if s.noise.prnu {
            s.prnu_sigma_percent / 100.0
        } else {
            0.0
        };
        let sig_c = s.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
        let blocks: Vec<(Vec<f64>, Vec<f64>)> = self
            .rows(sel)
            .par_chunks(BLOCK_ROWS)
            .map(|blk| {
                let mut a = vec![0.0; kk * kk];
                let mut b = vec![0.0; kk];
                let mut dv = vec![0.0; kk];
                for &r in blk {
                    for j in 0..cols {
                        let i = r * cols + j;
                        for sidx in 0..ns {
                            let sh = &d.shots[sidx];
                            if sh.censored[i] {
                                continue;
                            }
                            let c = &consts[sidx];
                            let p = c.predict(rates[sidx][i] as f64 * c.t, 0.0);
                            let vm = c.var_mean(&p)
                                + (sig_d * sig_d + sig_c * sig_c) * p.u * p.u
                                + sig_p * sig_p * p.w * p.w;
                            let w = 1.0 / vm;
                            let rr = sh.mean_dn[i] as f64 - p.mean;
                            for k in 0..kk {
                                dv[k] = p.dn_per_e * c.t * basis[k][sidx][i] as f64;
                            }
                            for k in 0..kk {
                                b[k] += w * dv[k] * rr;
                                for l in 0..kk {
                                    a[k * kk + l] += w * dv[k] * dv[l];
                                }
                            }
                        }
                    }
                }
                (a, b)
            })
            .collect();
        let mut a = vec![0.0; kk * kk];
        let mut b = vec![0.0; kk];
        for (ba, bb) in &blocks {
            a.iter_mut().zip(ba).for_each(|(x, y)| *x += y);
            b.iter_mut().zip(bb).for_each(|(x, y)| *x += y);
        }
        (a, b)
    }

    /// Pixels whose residuals over the shots are best explained by an extra dark rate: per
    /// pixel the least-squares rate V̂ and its significance z = V̂·√I (I: Fisher information);
    /// returns (pixel, V̂, z) for z > `z_min`. With `rail_free`, censored pixel-shots with no
    /// frame at a rail (censored by their neighbourhood only) count too: start values for
    /// data censored everywhere (the frame mean is then biased near a rail, which a start
    /// value tolerates).
    pub(crate) fn hot_scan(
        &self,
        state: &ModelState,
        rates: &Rates,
        z_min: f64,
        sel: RowSel,
        rail_free: bool,
    ) -> Vec<(usize, f64, f64)> {
        let d = self.data;
        let (ns, cols) = (d.shots.len(), d.cols);
        let consts = self.consts(state);
        let blocks: Vec<Vec<(usize, f64, f64)>> = self
            .rows(sel)
            .par_chunks(BLOCK_ROWS)
            .map(|blk| {
                let mut out = Vec::new();
                for &r in blk {
                    for j in 0..cols {
                        let i = r * cols + j;
                        let (mut srr, mut scc) = (0.0, 0.0);
                        for sidx in 0..ns {
                            let sh = &d.shots[sidx];
                            if sh.censored[i]
                                && !(rail_free && sh.n_low[i] == 0 && sh.n_high[i] == 0)
                            {
                                continue;
                            }
                            let c = &consts[sidx];
                            let p = c.predict(rates[sidx][i] as f64 * c.t, 0.0);
                            let cs = p.dn_per_e * c.t / c.g;
                            let a = c.var_mean(&p) + (state.sensor.dsnu_sigma_v * p.u).powi(2);
                            srr += (sh.mean_dn[i] as f64 - p.mean) * cs / a;
                            scc += cs * cs / a;
                        }
                        if scc > 0.0 {
                            let v = srr / scc;
                            let z = v * scc.sqrt();
                            if z > z_min {
                                out.push((i, v, z));
                            }
                        }
                    }
                }
                out
            })
            .collect();
        blocks.into_iter().flatten().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mismatch::num::norm_cdf;

    /// Without fixed pattern the rail counts are multinomial: the deviance must equal the
    /// closed-form binomial deviance 2[n ln(n/(Fp)) + (F−n) ln((F−n)/(F(1−p)))] with
    /// p = Φ((0.5 − y)/σ), and stay of order ln(1/(Fp)) for a rare rail frame, where
    /// Pearson's (n − Fp)²/(Fp(1−p)) explodes (the issue-6 χ² inconsistency).
    #[test]
    fn rail_deviance_is_binomial_deviance_and_bounded_for_rare_events() {
        let f = 16.0;
        for &(y, n) in &[(0.3, 5.0), (2.0, 1.0), (4.5, 1.0), (1.0, 16.0), (0.0, 0.0)] {
            let p = Pred {
                y,
                s2_t: 1.0,
                s2_f: 0.0,
                hi: 255.0,
                ..Default::default()
            };
            let rs = rail_stats(&p, f, n, 0.0);
            let q = norm_cdf(0.5 - y);
            let term = |k: f64, pr: f64| {
                if k > 0.0 {
                    k * (k / (f * pr)).ln()
                } else {
                    0.0
                }
            };
            let want = 2.0 * (term(n, q) + term(f - n, 1.0 - q));
            let got = rail_deviance(&rs, f, n, 0.0);
            assert!(
                (got - want).abs() < 1e-6 * want.max(1.0),
                "y {y} n {n}: deviance {got} vs closed form {want}"
            );
            assert!(got >= 0.0);
            if y == 4.5 {
                let pearson = (n - f * q).powi(2) / (f * q * (1.0 - q));
                assert!(pearson > 100.0 * got, "pearson {pearson} deviance {got}");
            }
        }
    }

    /// SplitMix64: a fixed-seed generator for the simulations below.
    struct Rng(u64);

    impl Rng {
        fn u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn unif(&mut self) -> f64 {
            ((self.u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.unif(), self.unif());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// A dark prediction whose per-frame probability of the low rail is `p_lo` at zero fixed
    /// offset (temporal σ 1 DN, fixed-pattern σ `s_f`).
    fn dark_pred(p_lo: f64, s_f: f64) -> Pred {
        use statrs::distribution::{ContinuousCDF, Normal};
        let q = Normal::new(0.0, 1.0).unwrap().inverse_cdf(p_lo);
        Pred {
            y: 0.5 - q,
            s2_t: 1.0,
            s2_f: s_f * s_f,
            hi: 255.0,
            ..Default::default()
        }
    }

    /// Rail counts of one pixel-shot drawn from the model: a fixed offset z ~ N(0, s_f²) per
    /// pixel-shot, then F independent frames.
    fn draw(rng: &mut Rng, p: &Pred, f: usize) -> (f64, f64) {
        let (s_t, s_f) = (p.s2_t.sqrt(), p.s2_f.sqrt());
        let y = p.y + s_f * rng.normal();
        let plo = norm_cdf((0.5 - y) / s_t);
        let phi = 1.0 - norm_cdf((p.hi - 0.5 - y) / s_t);
        let (mut lo, mut hi) = (0.0, 0.0);
        for _ in 0..f {
            let u = rng.unif();
            if u < plo {
                lo += 1.0;
            } else if u > 1.0 - phi {
                hi += 1.0;
            }
        }
        (lo, hi)
    }

    /// Without fixed pattern E[G²] is the binomial sum Σ_n C(F,n) pⁿ(1−p)^(F−n) G²(n).
    #[test]
    fn rail_expected_deviance_is_the_binomial_expectation() {
        for &f in &[1usize, 2, 4, 8, 16] {
            for &p in &[1e-9, 1e-3, 0.02, 0.3, 0.5, 0.9, 0.999] {
                let ff = f as f64;
                let g2 = |n: f64| {
                    let t = |k: f64, pr: f64| {
                        if k > 0.0 {
                            k * (k / (ff * pr)).ln()
                        } else {
                            0.0
                        }
                    };
                    2.0 * (t(n, p) + t(ff - n, 1.0 - p))
                };
                let mut want = 0.0;
                let mut want_given = (0.0, 0.0);
                let mut c = 1.0;
                for n in 0..=f {
                    if n > 0 {
                        c *= (f - n + 1) as f64 / n as f64;
                    }
                    let pr = c * p.powi(n as i32) * (1.0 - p).powi((f - n) as i32);
                    want += pr * g2(n as f64);
                    if n > 0 {
                        want_given.0 += pr * g2(n as f64);
                        want_given.1 += pr;
                    }
                }
                let want_given = want_given.0 / want_given.1;
                let pred = dark_pred(p, 0.0);
                let got = rail_expected_deviance(&pred, ff, false);
                let got_given = rail_expected_deviance(&pred, ff, true);
                let tol = |w: f64| 1e-7 * w.max(1e-6) + 1e-12;
                assert!(
                    (got - want).abs() < tol(want),
                    "F {f} p {p}: E[G²] {got} vs {want}"
                );
                assert!(
                    (got_given - want_given).abs() < tol(want_given),
                    "F {f} p {p}: E[G² | rail] {got_given} vs {want_given}"
                );
            }
        }
    }

    /// E[G²] (including the fixed-pattern mixture and the conditional form) agrees with the
    /// Monte-Carlo mean of G² over counts drawn from the model.
    #[test]
    fn rail_expected_deviance_matches_monte_carlo() {
        let mut rng = Rng(0x5EED_0006);
        let n = 200_000;
        for &(p_lo, s_f, f, given) in &[
            (0.01, 0.0, 2usize, false),
            (0.2, 0.0, 4, false),
            (0.05, 0.0, 8, false),
            (0.003, 0.5, 4, false),
            (0.05, 1.0, 8, false),
            (0.3, 2.0, 2, false),
            (0.01, 0.7, 4, true),
        ] {
            let pred = dark_pred(p_lo, s_f);
            let want = rail_expected_deviance(&pred, f as f64, given);
            let mut cache = ExpectedDevianceCache::default();
            let (mut s1, mut s2, mut k) = (0.0, 0.0, 0.0);
            while k < n as f64 {
                let (lo, hi) = draw(&mut rng, &pred, f);
                if given && lo + hi == 0.0 {
                    continue;
                }
                let (g2, e) = cache.term(&pred, f as f64, lo, hi, given);
                assert_eq!(e, want);
                s1 += g2;
                s2 += g2 * g2;
                k += 1.0;
            }
            let mean = s1 / k;
            let se = ((s2 / k - mean * mean) / k).sqrt();
            assert!(
                (mean - want).abs() < 4.0 * se,
                "p {p_lo} s_f {s_f} F {f} given {given}: MC {mean} ± {se} vs E[G²] {want}"
            );
        }
    }

    /// Under the model the summary is calibrated for any sparsity: Σ G² / Σ E[G²] ≈ 1 over
    /// thousands of rail-count terms with per-frame probabilities 10⁻³…0.5 (z-test with the
    /// terms' own scatter).
    #[test]
    fn chi2_per_dof_of_sparse_rail_counts_is_one_under_the_model() {
        let mut rng = Rng(0xF1EA_0003);
        let mut cache = ExpectedDevianceCache::default();
        for &f in &[2usize, 4, 8] {
            for &s_f in &[0.0, 0.8] {
                let (mut chi2, mut dof, mut var) = (0.0, 0.0, 0.0);
                for i in 0..6000 {
                    // log-uniform 10⁻³ … 0.5, on a grid so that the memo is exercised
                    let p = 1e-3 * 500f64.powf((i % 60) as f64 / 59.0);
                    let pred = dark_pred(p, s_f);
                    let (lo, hi) = draw(&mut rng, &pred, f);
                    let (g2, e) = cache.term(&pred, f as f64, lo, hi, false);
                    chi2 += g2;
                    dof += e;
                    var += (g2 - e) * (g2 - e);
                }
                let z = (chi2 - dof) / var.sqrt();
                assert!(
                    z.abs() < 4.0,
                    "F {f} s_f {s_f}: χ²/dof {:.4} (χ² {chi2:.1}, dof {dof:.1}, z {z:.2})",
                    chi2 / dof
                );
            }
        }
    }

    /// The summary of counts drawn from `truth` and compared with the model `truth × k`
    /// (per-frame rail probability): new (χ², dof), −lnL, and the old summary's (χ², dof)
    /// (terms whose minority outcome is expected in under half a frame and not seen skipped,
    /// 1 dof per kept term).
    struct Summary {
        chi2: f64,
        dof: f64,
        nll: f64,
        old_chi2: f64,
        old_dof: f64,
    }

    impl Summary {
        fn r(&self) -> f64 {
            self.chi2 / self.dof
        }
        fn old_r(&self) -> f64 {
            self.old_chi2 / self.old_dof
        }
    }

    fn summarise(k: f64, f: usize, seed: u64) -> Summary {
        let mut rng = Rng(seed);
        let mut cache = ExpectedDevianceCache::default();
        let ff = f as f64;
        let mut s = Summary {
            chi2: 0.0,
            dof: 0.0,
            nll: 0.0,
            old_chi2: 0.0,
            old_dof: 0.0,
        };
        for i in 0..20_000 {
            let p = 1e-3 * 100f64.powf((i % 40) as f64 / 39.0);
            let (lo, hi) = draw(&mut rng, &dark_pred(p, 0.0), f);
            let model = dark_pred((k * p).min(0.9), 0.0);
            let (g2, e) = cache.term(&model, ff, lo, hi, false);
            s.chi2 += g2;
            s.dof += e;
            s.nll -= rail_stats(&model, ff, lo, hi).ll;
            let mean = ff * norm_cdf(0.5 - model.y);
            let q = mean.min(ff - mean);
            let minority = if mean > 0.5 * ff { ff - lo } else { lo };
            if !(q < 0.5 && minority == 0.0) {
                s.old_chi2 += g2;
                s.old_dof += 1.0;
            }
        }
        s
    }

    /// Issue 6: under a wrong model the summary and the likelihood must agree. Counts drawn
    /// with per-frame rail probabilities 10⁻³…0.1 (F = 2, 4). At the truth χ²/dof ≈ 1 (the
    /// old summary: ≈ 4, it keeps only the sparse terms with a rail frame). A model that
    /// under-predicts the rail frames has χ²/dof ≫ 1, and moving it towards the truth lowers
    /// −lnL and χ²/dof together. One that over-predicts them (the Flea3 direction: the
    /// believed camera expects non-zero frames the data do not have) is off too (below 1 at
    /// F = 2, either side at F = 4); there moving towards the truth lowers χ² by exactly
    /// 2Δ(−lnL) (every term kept, saturated term fixed), while the old summary rose — but
    /// χ²/dof is not monotone on the way, since the model's own E[G²] moves as much as the
    /// misfit for counts this sparse.
    #[test]
    fn chi2_per_dof_moves_with_the_likelihood_under_a_wrong_model() {
        for &f in &[2usize, 4] {
            let seed = 0xBAD0_0000 + f as u64;
            let t = summarise(1.0, f, seed);
            let [a, b, c, d] = [0.2, 0.5, 5.0, 2.0].map(|k| summarise(k, f, seed));
            eprintln!(
                "F {f}: χ²/dof ×0.2 {:.3} ×0.5 {:.3} ×1 {:.3} ×2 {:.3} ×5 {:.3}; old ×5 {:.3} ×2 {:.3} ×1 {:.3}",
                a.r(), b.r(), t.r(), d.r(), c.r(), c.old_r(), d.old_r(), t.old_r()
            );
            let z_true = (t.chi2 - t.dof) / (2.0 * t.dof).sqrt();
            assert!(
                z_true.abs() < 4.0 && (t.r() - 1.0).abs() < 0.05,
                "F {f}: χ²/dof {} at the truth",
                t.r()
            );
            // Under-predicted rail frames.
            assert!(
                a.r() > 1.5,
                "F {f}: χ²/dof {} with rails under-predicted ×5",
                a.r()
            );
            assert!(
                a.nll > b.nll && b.nll > t.nll,
                "F {f}: −lnL {} {} {}",
                a.nll,
                b.nll,
                t.nll
            );
            assert!(
                a.r() > b.r() && b.r() > t.r(),
                "F {f}: χ²/dof {} {} {}",
                a.r(),
                b.r(),
                t.r()
            );
            // Over-predicted rail frames.
            assert!(
                (c.r() - 1.0).abs() > 0.1 && (d.r() - 1.0).abs() > 0.1,
                "F {f}: χ²/dof {} {}",
                c.r(),
                d.r()
            );
            assert!(
                c.nll > d.nll && d.nll > t.nll,
                "F {f}: −lnL {} {} {}",
                c.nll,
                d.nll,
                t.nll
            );
            for (x, y) in [(&c, &d), (&d, &t), (&a, &b), (&b, &t)] {
                let (dchi2, dnll) = (x.chi2 - y.chi2, x.nll - y.nll);
                assert!(
                    (dchi2 - 2.0 * dnll).abs() < 1e-6 * dchi2.abs(),
                    "F {f}: Δχ² {dchi2} vs 2Δ(−lnL) {dnll}"
                );
            }
            // The old summary on the same counts: far from 1 at the truth, and higher there
            // than for the ×5 over-predicting model.
            assert!(
                t.old_r() > 1.5 && c.old_r() < t.old_r(),
                "F {f}: old χ²/dof {} {}",
                c.old_r(),
                t.old_r()
            );
        }
    }
}
