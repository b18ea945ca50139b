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
//!   levels separate DSNU from PRNU (Woodbury form, [`super::num::Woodbury`]);
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
//!
//! One file per term: `temporal.rs`, `pixel.rs` (the fixed-pattern Woodbury term of a pixel,
//! which folds in the temporal one), `column.rs`, `hot.rs`, `rail.rs` (clipping); `rates.rs`
//! holds the forward-model cache and the exposure/crosstalk transform, `linear.rs` the
//! normal equations of linear rate parameters; `prof.rs` the stage timers.
mod column;
mod frames;
mod hot;
mod linear;
mod pixel;
pub mod prof;
mod rail;
mod rates;
mod temporal;

use super::data::{DataSet, ShotData, TargetClass};
use super::model::{Forward, ModelState, Pred, ShotConst};
use super::num::log_add_exp;
use column::{outlier_pixels, ColView};
use hot::Hot;
#[cfg(test)]
pub(crate) use rail::rail_stats;
use rail::ExpectedDevianceCache;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// The fixed-pattern spreads of a sensor state, as the likelihood uses them: σ_D (DSNU, volts),
/// σ_P (PRNU, relative gain) and σ_c (column offsets, volts); zero where the block is off.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FixedPattern {
    /// DSNU σ_D (V).
    pub dsnu_v: f64,
    /// PRNU σ_P (relative gain, not percent).
    pub prnu_rel: f64,
    /// Column-offset σ_c (V).
    pub column_v: f64,
}

impl FixedPattern {
    /// The spreads of `state`'s sensor.
    pub(crate) fn of(state: &ModelState) -> Self {
        let s = &state.sensor;
        FixedPattern {
            dsnu_v: if s.noise.dsnu { s.dsnu_sigma_v } else { 0.0 },
            prnu_rel: if s.noise.prnu {
                s.prnu_sigma_percent / 100.0
            } else {
                0.0
            },
            column_v: s.column_fpn.map_or(0.0, |c| c.offset_sigma_v),
        }
    }

    /// Marginal variance of a pixel's frame mean (DN²), every term of the module doc's
    /// covariance on the diagonal: temporal/F + excess ([`ShotConst::var_mean`]) +
    /// (σ_D² + σ_c²)·u² + σ_P²·w².
    #[inline]
    pub(crate) fn var_mean(&self, c: &ShotConst, p: &Pred) -> f64 {
        c.var_mean(p)
            + (self.dsnu_v * self.dsnu_v + self.column_v * self.column_v) * p.u * p.u
            + self.prnu_rel * self.prnu_rel * p.w * p.w
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

/// The fit rows are [`fit_bands`] when they are at most this fraction (1/n) of the sensor's
/// rows: a forward model that runs bands of rows by itself then runs a few bands, each with
/// the optics' margin, instead of one per 2-row group (most of the sensor).
pub(crate) const FIT_BAND_SPARSITY: usize = 8;
/// Bands of [`fit_bands`].
pub(crate) const FIT_BANDS: usize = 5;

/// About `n` fit rows of a `rows`-row sensor as [`FIT_BANDS`] contiguous bands of equal even
/// length (at most `n` rows in all, at least 2 per band; CFA phases balanced), spread over the
/// field height from the top row to the bottom one (the corners' field heights included), each
/// starting at an even row. The first and last bands are at the frame's edges; each band
/// between them starts, within its share of the height (± half the even spacing less its own
/// length around the evenly spaced start), where the band's rows hold the most scene structure
/// (`structure`, per row, [`row_structure`]; ties: the start nearest the even one): evenly
/// spaced rows can all fall where a scene has no content — on a colour chart of 4 patch rows
/// the three inner ones land in the grey gaps between patch rows, and the fits could not see
/// the patches' colours. Without structure (all 0, or no entry per row) the bands are evenly
/// spaced.
pub(crate) fn fit_bands(rows: usize, n: usize, structure: &[f64]) -> Vec<usize> {
    let len = (n / FIT_BANDS / 2 * 2).max(2).min(rows / FIT_BANDS / 2 * 2);
    let mut out = Vec::new();
    if len == 0 {
        return out;
    }
    let spacing = (rows - len) / (FIT_BANDS - 1);
    let half = (spacing / 2).saturating_sub(len) / 2 * 2;
    let use_structure = structure.len() == rows && structure.iter().any(|&x| x > 0.0);
    // prefix sums: the structure of rows a..b is prefix[b] − prefix[a]
    let mut prefix = vec![0.0; rows + 1];
    if use_structure {
        for (r, &x) in structure.iter().enumerate() {
            prefix[r + 1] = prefix[r] + x.max(0.0);
        }
    }
    for k in 0..FIT_BANDS {
        let even = (k * (rows - len) / (FIT_BANDS - 1)) / 2 * 2;
        let start = if !use_structure || k == 0 || k == FIT_BANDS - 1 {
            even
        } else {
            let lo = even.saturating_sub(half);
            let hi = (even + half).min(rows - len);
            (lo..=hi)
                .step_by(2)
                .map(|s| (prefix[s + len] - prefix[s], s))
                .max_by(|a, b| {
                    a.0.total_cmp(&b.0)
                        .then_with(|| (b.1.abs_diff(even)).cmp(&a.1.abs_diff(even)))
                        .then_with(|| b.1.cmp(&a.1))
                })
                .map_or(even, |x| x.1)
        };
        out.extend(start..start + len);
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Scene structure of each sensor row, for [`fit_bands`]: over the structured shots (charts,
/// edges, images: neither dark nor uniform), the sum of the variance of the row's per-pixel
/// mean levels (DN) across its columns, per CFA channel. A row through a chart's patches
/// scores high, one through the grey surround between patch rows about its noise; all 0
/// without structured shots.
pub(crate) fn row_structure(data: &DataSet) -> Vec<f64> {
    let shots: Vec<&ShotData> = data
        .shots
        .iter()
        .filter(|s| !matches!(s.target, TargetClass::Dark | TargetClass::Uniform))
        .collect();
    let nch = data.channels();
    let cols = data.cols;
    (0..data.rows)
        .into_par_iter()
        .map(|r| {
            let mut total = 0.0;
            for sh in &shots {
                let mut sum = vec![0.0f64; nch];
                let mut sum2 = vec![0.0f64; nch];
                let mut count = vec![0.0f64; nch];
                for c in 0..cols {
                    let i = r * cols + c;
                    let ch = data.channel[i] as usize;
                    let v = sh.mean_dn[i] as f64;
                    sum[ch] += v;
                    sum2[ch] += v * v;
                    count[ch] += 1.0;
                }
                for ch in 0..nch {
                    if count[ch] > 1.0 {
                        let m = sum[ch] / count[ch];
                        total += (sum2[ch] / count[ch] - m * m).max(0.0);
                    }
                }
            }
            total
        })
        .collect()
}

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
    /// Whether the forward model computes [`Ctx::calc_rows`] alone for less than every row
    /// ([`Forward::row_window`]): the fits then read rate images that hold only those rows
    /// ([`Ctx::base_rates`]).
    pub fit_window: bool,
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
    /// What a likelihood with hot or RTN pixels shares with every other value of their
    /// mixtures' parameters (the hot-pixel and RTN fits change only those).
    hot_base: Mutex<Option<Arc<HotBase>>>,
    /// Per shot and row: the sum of the pixels' temporal variances and whether no pixel is
    /// censored (`frames.rs`; data only, computed on first use).
    frame_pre: std::sync::OnceLock<Vec<(Vec<f64>, Vec<bool>)>>,
    /// The hot or RTN class's per-pixel log-likelihood of the last pass with one of the two
    /// mixtures ([`MixCache`]).
    mix: Mutex<Option<MixCache>>,
}

/// Per pixel of the fit rows (pixel-pass order), the log-likelihood of the hot class (hot
/// pixels alone) or of the RTN class (RTN alone), for a [`HotBase`] and the class's own
/// parameters: the class likelihood does not read the mixture's fraction, so a fit of the
/// fraction (a third of the hot-pixel fit's and half of the RTN fit's evaluations) only
/// mixes the kept values with the normal class's (the same arithmetic on the same values:
/// the same bits).
struct MixCache {
    /// The normal-class parts these values go with (held: compared by pointer).
    base: Arc<HotBase>,
    /// 0 for hot pixels with (ln V_h, σ_h) as bits; 1 for RTN with (A, p) as bits.
    key: [u64; 3],
    /// Class log-likelihood per pixel.
    l: Arc<Vec<f64>>,
}

/// The parts of a fit-row log-likelihood that do not depend on the hot-pixel and RTN
/// mixtures' parameters: the column statistics and term, and every pixel's normal-class
/// log-likelihood. Keyed by the state without its hot and RTN pixels and the rate images.
struct HotBase {
    state: ModelState,
    /// The rate images (held: compared by pointer, then by value).
    rates: Rates,
    sel: RowSel,
    col: Vec<column::ColStat>,
    logl_columns: f64,
    /// Normal-class log-likelihood per pixel, in the pixel pass's order.
    l0: Vec<f64>,
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

impl<'a> Ctx<'a> {
    pub fn new(data: &'a DataSet, forward: &'a dyn Forward, max_fit_pixels: usize) -> Self {
        let all_rows: Vec<usize> = (0..data.rows).collect();
        // The rows the fit-row evaluations must compute: the fit rows and their neighbours
        // (crosstalk); empty when the fit rows are all rows.
        let calc_rows_of = |fit_rows: &[usize]| -> Vec<usize> {
            if fit_rows.len() == data.rows {
                return Vec::new();
            }
            let mut v: Vec<usize> = fit_rows
                .iter()
                .flat_map(|&r| [r.saturating_sub(1), r, (r + 1).min(data.rows - 1)])
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        // (a sensor of fewer than 2 rows has no 2-row group: its rows are the fit rows)
        let fit_rows = if data.pixels() <= max_fit_pixels || data.rows < 2 {
            all_rows.clone()
        } else {
            let keep = (max_fit_pixels / data.cols.max(1)).max(16) / 2;
            let groups = data.rows / 2;
            // Contiguous bands only where the forward model runs them by themselves
            // (`Forward::row_window`): elsewhere they would buy nothing and move the fits.
            let bands = (data.rows >= FIT_BAND_SPARSITY * 2 * keep.min(groups))
                .then(|| fit_bands(data.rows, 2 * keep.min(groups), &row_structure(data)))
                .filter(|b| !b.is_empty() && forward.row_window(&calc_rows_of(b)));
            bands.unwrap_or_else(|| {
                // Whole 2-row groups (CFA phases balanced), evenly spread over the sensor.
                let mut rows = Vec::new();
                for k in 0..keep.min(groups) {
                    let g = k * groups / keep.min(groups);
                    rows.push(2 * g);
                    rows.push(2 * g + 1);
                }
                rows
            })
        };
        let col_excluded = outlier_pixels(data);
        let calc_rows = calc_rows_of(&fit_rows);
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
        let fit_window = !calc_rows.is_empty() && forward.row_window(&calc_rows);
        Ctx {
            fit_window,
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
            hot_base: Mutex::new(None),
            frame_pre: std::sync::OnceLock::new(),
            mix: Mutex::new(None),
        }
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
        let rates = self.rates_for(state, sel)?;
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
            .map(|s| ShotConst::for_shot(&state.sensor, s))
            .collect()
    }

    /// Column-mean statistics of the residuals (per shot, column), shot-major.
    /// With `store`, also every pixel-shot's prediction, at
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
        let fp = FixedPattern::of(state);
        let (sig_d, sig_p, sig_c) = (fp.dsnu_v, fp.prnu_rel, fp.column_v);
        let hot = s
            .effects
            .hot_pixels
            .filter(|h| h.fraction > 0.0 && h.dark_voltage_v_per_s > 0.0)
            .map(|h| Hot {
                fraction: h.fraction.min(0.5),
                ln_rate: h.dark_voltage_v_per_s.ln(),
                log_sigma: h.log_sigma,
            });
        // RTN pixels (effect block): a second mixture over the pixel's class — a trap of
        // step A (V) in its high state with probability p adds u·A·p to every shot's mean and
        // (u·A)²p(1−p) to its temporal variance (u = DN per volt).
        let rtn = s
            .effects
            .rtn
            .filter(|r| r.fraction > 0.0 && r.amplitude_v > 0.0)
            .map(|r| (r.fraction.min(0.5), r.amplitude_v, r.high_probability()));
        let use_cols = self.column_term(sel);
        let rows = self.rows(sel);
        // A likelihood alone with hot pixels or RTN pixels: reuse (or keep) what does not
        // depend on the mixtures' parameters (the column term and every pixel's normal-class
        // log-likelihood: neither reads the hot-pixel or RTN block). Same sums in the same
        // order: the same value either way.
        let hot_key = ((hot.is_some() || rtn.is_some()) && !stats).then(|| {
            let mut st = state.clone();
            st.sensor.effects.hot_pixels = None;
            st.sensor.effects.rtn = None;
            st
        });
        let same_rates = |a: &Rates| {
            a.len() == rates.len()
                && a.iter()
                    .zip(rates)
                    .all(|(x, y)| Arc::ptr_eq(x, y) || x[..] == y[..])
        };
        let hot_base: Option<Arc<HotBase>> = hot_key.as_ref().and_then(|st| {
            let hb = self.hot_base.lock().expect("hot base");
            hb.as_ref()
                .filter(|b| b.sel == sel && &b.state == st && same_rates(&b.rates))
                .cloned()
        });
        let keep_l0 = hot_key.is_some() && hot_base.is_none();
        // The column pass keeps its predictions for the pixel pass (when they fit in
        // PRED_STORE pixel-shots, e.g. the fit rows of a large sensor).
        let n_ps = rows.len() * cols * ns;
        let mut store: Vec<Pred> = Vec::new();
        let use_store = use_cols && n_ps <= PRED_STORE && hot_base.is_none();
        if use_store {
            store = std::mem::take(&mut *self.pred_buf.lock().expect("pred buffer"));
            store.resize(n_ps, Pred::default());
        }
        let col_owned;
        let col: &[column::ColStat] = match &hot_base {
            Some(hb) => &hb.col,
            None => {
                col_owned = if use_cols {
                    self.column_stats_store(
                        rates,
                        &consts,
                        sel,
                        use_store.then_some(&mut store[..]),
                    )
                } else {
                    Vec::new()
                };
                &col_owned
            }
        };
        // The hot or RTN class's per-pixel log-likelihood, kept or reused ([`MixCache`]).
        let mix_key: Option<[u64; 3]> = match (&hot_key, &hot, rtn) {
            (Some(_), Some(h), None) => Some([0, h.ln_rate.to_bits(), h.log_sigma.to_bits()]),
            (Some(_), None, Some((_, a_v, p))) => Some([1, a_v.to_bits(), p.to_bits()]),
            _ => None,
        };
        let mix_hit: Option<Arc<Vec<f64>>> = match (&mix_key, &hot_base) {
            (Some(k), Some(hb)) => self
                .mix
                .lock()
                .expect("mixture cache")
                .as_ref()
                .filter(|m| m.key == *k && Arc::ptr_eq(&m.base, hb))
                .map(|m| m.l.clone()),
            _ => None,
        };
        let keep_mix = mix_key.is_some() && mix_hit.is_none();
        let stored: Option<&[Pred]> = use_store.then_some(&store[..]);
        // Column term: per column, the S-vector of column-mean residuals.
        let logl_columns = match &hot_base {
            Some(hb) => hb.logl_columns,
            None if use_cols => self.column_logl(col, sig_d, sig_p, sig_c),
            None => 0.0,
        };
        // Pixel term (blocks of PIXEL_BLOCK_ROWS rows: enough pieces to balance the threads
        // on a few fit rows).
        #[allow(clippy::type_complexity)]
        let blocks: Vec<(f64, Vec<ScStat>, usize, Vec<f64>, Vec<f64>)> = rows
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
                let mut l0s: Vec<f64> = Vec::new();
                let mut mix_vals: Vec<f64> = Vec::new();
                let mut rtn_buf: Vec<Pred> = Vec::with_capacity(ns);
                for (ri, &r) in blk.iter().enumerate() {
                    for j in 0..cols {
                        let i = r * cols + j;
                        let ch = d.channel[i] as usize;
                        let at = ((bi * PIXEL_BLOCK_ROWS + ri) * cols + j) * ns;
                        if let (Some(lc), Some(hb)) = (&mix_hit, &hot_base) {
                            // the kept class likelihood, mixed as below
                            let l0 = hb.l0[at / ns];
                            let (fr, is_hot) = match (&hot, rtn) {
                                (Some(h), _) => (h.fraction, true),
                                (None, Some((fr, _, _))) => (fr, false),
                                (None, None) => unreachable!("a mixture key needs a mixture"),
                            };
                            let a = (1.0 - fr).ln() + l0;
                            let b = fr.ln() + lc[at / ns];
                            let tot = log_add_exp(a, b);
                            if is_hot && b - tot > -std::f64::consts::LN_2 {
                                n_hot += 1;
                            }
                            ll += tot;
                            continue;
                        }
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
                            stats: col,
                            cols,
                            j,
                        });
                        let l0 = match &hot_base {
                            Some(hb) => hb.l0[at / ns],
                            None => self.pixel_ll(
                                px,
                                preds,
                                &consts,
                                cs,
                                sig_d,
                                sig_p,
                                if use_cols { 0.0 } else { sig_c },
                            ),
                        };
                        if keep_l0 {
                            l0s.push(l0);
                        }
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
                                if keep_mix {
                                    mix_vals.push(lh);
                                }
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
                        let mut rtn_class = false;
                        let li = match rtn {
                            None => li,
                            Some((fr, a_v, p)) => {
                                let base_preds: &[Pred] =
                                    if hot_class { &hot_buf[..] } else { preds };
                                rtn_buf.clear();
                                rtn_buf.extend(base_preds.iter().map(|q| {
                                    let a = q.u * a_v;
                                    Pred {
                                        mean: q.mean + a * p,
                                        var_t: q.var_t + a * a * p * (1.0 - p),
                                        s2_t: q.s2_t + a * a * p * (1.0 - p),
                                        y: q.y + a * p,
                                        ..*q
                                    }
                                }));
                                let lr = self.pixel_ll(
                                    px,
                                    &rtn_buf,
                                    &consts,
                                    cs,
                                    sig_d,
                                    sig_p,
                                    if use_cols { 0.0 } else { sig_c },
                                );
                                if keep_mix {
                                    mix_vals.push(lr);
                                }
                                let a = (1.0 - fr).ln() + li;
                                let b = fr.ln() + lr;
                                let tot = log_add_exp(a, b);
                                rtn_class = b - tot > -std::f64::consts::LN_2;
                                tot
                            }
                        };
                        ll += li;
                        if !stats {
                            continue;
                        }
                        // Reported χ² (marginal per pixel-shot) with the pixel's class.
                        let used = if rtn_class {
                            &rtn_buf[..]
                        } else if hot_class {
                            &hot_buf[..]
                        } else {
                            preds
                        };
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
                            let vm = fp.var_mean(&consts[sidx], p);
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
                (ll, sc, n_hot, l0s, mix_vals)
            })
            .collect();
        // Frame-sequence terms (row noise, black-level drift; `frames.rs`): rows × shots of
        // arithmetic, on every row whatever the selection.
        let mut logl = logl_columns + self.frame_terms_ll(state);
        let mut per_sc = vec![ScStat::default(); ns * nch];
        let mut hot_pixels = 0;
        for (ll, sc, nh, ..) in &blocks {
            logl += ll;
            for (t, x) in per_sc.iter_mut().zip(sc) {
                t.add(x);
            }
            hot_pixels += nh;
        }
        if use_store {
            *self.pred_buf.lock().expect("pred buffer") = store;
        }
        let mut new_base: Option<Arc<HotBase>> = None;
        if keep_l0 {
            if let Some(st) = hot_key {
                let l0: Vec<f64> = blocks.iter().flat_map(|b| b.3.iter().copied()).collect();
                let nb = Arc::new(HotBase {
                    state: st,
                    rates: rates.clone(),
                    sel,
                    col: col.to_vec(),
                    logl_columns,
                    l0,
                });
                *self.hot_base.lock().expect("hot base") = Some(nb.clone());
                new_base = Some(nb);
            }
        }
        if keep_mix {
            if let (Some(key), Some(base)) = (mix_key, hot_base.clone().or(new_base)) {
                let l: Vec<f64> = blocks.iter().flat_map(|b| b.4.iter().copied()).collect();
                *self.mix.lock().expect("mixture cache") = Some(MixCache {
                    base,
                    key,
                    l: Arc::new(l),
                });
            }
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

#[cfg(test)]
pub(crate) mod tests {
    use super::{fit_bands, Ctx, RowSel, FIT_BANDS};
    use crate::mismatch::data::{DataSet, ShotAccumulator, TargetClass};
    use crate::mismatch::model::{Forward, ModelState, RateSpec};
    use std::sync::Arc;

    /// Fixed rate images per shot.
    pub(crate) struct FixedRates(Vec<Arc<Vec<f32>>>);
    impl Forward for FixedRates {
        fn rates(&self, _: &RateSpec) -> Result<Vec<Arc<Vec<f32>>>, String> {
            Ok(self.0.clone())
        }
    }

    /// A 16 × 12 mono set: two darks (3 frames), three flats (2 frames; the last near a
    /// 7 000–9 000 e⁻ well), a structured single-frame shot clipped at both rails; frames
    /// from a fixed pseudo-random sequence around a slope in the rates.
    pub(crate) fn demo() -> (DataSet, FixedRates) {
        let (rows, cols) = (16usize, 12usize);
        let n = rows * cols;
        // (exposure s, rate scale e-/s, frames, target)
        let shots = [
            (0.1, 0.0, 3, TargetClass::Dark),
            (1.0, 0.0, 3, TargetClass::Dark),
            (0.01, 1.0e5, 2, TargetClass::Uniform),
            (0.01, 3.0e5, 2, TargetClass::Uniform),
            (0.01, 7.6e5, 2, TargetClass::Uniform),
            (0.01, 9.0e5, 1, TargetClass::Structured),
        ];
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut noise = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut rates = Vec::new();
        let mut data = Vec::new();
        for (k, (t, scale, frames, target)) in shots.into_iter().enumerate() {
            let r: Vec<f32> = (0..n)
                .map(|i| {
                    let (row, c) = (i / cols, i % cols);
                    let structured = matches!(target, TargetClass::Structured);
                    let f = if structured && (row + c) % 3 == 0 {
                        1.6
                    } else if structured && (row * c) % 5 == 1 {
                        0.0
                    } else {
                        1.0 - 0.01 * row as f64
                    };
                    (scale * f) as f32
                })
                .collect();
            let mut acc = ShotAccumulator::new(rows, cols, 4095);
            for _ in 0..frames {
                let frame: Vec<u16> = r
                    .iter()
                    .map(|&x| {
                        let e = x as f64 * t + 10.0 * t;
                        let dn = 64.0 + 0.4095 * (e + 3.0 * e.sqrt() * noise()) + 8.0 * noise();
                        let dn = if structured_zero(k, x) { -5.0 } else { dn };
                        dn.round().clamp(0.0, 4095.0) as u16
                    })
                    .collect();
                acc.add(&frame).unwrap();
            }
            data.push(acc.finish(format!("s{k}"), target, format!("k{k}"), t, 1.0));
            rates.push(Arc::new(r));
        }
        fn structured_zero(k: usize, x: f32) -> bool {
            k == 5 && x == 0.0
        }
        (
            DataSet {
                rows,
                cols,
                channel: vec![0; n],
                channel_names: vec!["m".into()],
                max_dn: 4095.0,
                shots: data,
            },
            FixedRates(rates),
        )
    }

    /// Reusing the hot or RTN class's per-pixel likelihoods ([`super::MixCache`]) gives the
    /// bits of a pass from scratch, along a sequence that changes each mixture's fraction (the
    /// kept values are reused), its own parameters, a fixed-pattern spread and the well (they
    /// are not), and switches between the two mixtures and to both at once (no reuse).
    #[test]
    fn mixture_reuse_gives_the_bits_of_a_fresh_pass() {
        let (data, fw) = demo();
        let mut sensor = camsim_sensor::SensorModel::mono_test(data.rows, data.cols);
        sensor.well_capacity_e = 9000.0;
        let base = ModelState {
            sensor,
            exposure_factor: 1.0,
            rates: RateSpec::default(),
            frames_in_set: 13,
        };
        let at = |hot: Option<(f64, f64)>, rtn: Option<(f64, f64)>, dsnu_v: f64, well_e: f64| {
            let mut s = base.clone();
            s.sensor.dsnu_sigma_v = dsnu_v;
            s.sensor.well_capacity_e = well_e;
            s.sensor.effects.hot_pixels = hot.map(|(fr, v)| camsim_sensor::HotPixels {
                fraction: fr,
                dark_voltage_v_per_s: v,
                log_sigma: 0.5,
            });
            s.sensor.effects.rtn = rtn.map(|(fr, a)| camsim_sensor::Rtn {
                fraction: fr,
                amplitude_v: a,
                log_sigma: 0.0,
                p_up: 0.5,
                p_down: 0.5,
            });
            s
        };
        let d0 = base.sensor.dsnu_sigma_v;
        // (state, whether the previous step's class likelihoods are kept: reused)
        let seq = [
            (at(Some((0.01, 0.05)), None, d0, 9000.0), false),
            (at(Some((0.02, 0.05)), None, d0, 9000.0), true),
            (at(Some((0.03, 0.05)), None, d0, 9000.0), true),
            (at(Some((0.03, 0.08)), None, d0, 9000.0), false),
            (at(Some((0.01, 0.08)), None, d0, 9000.0), true),
            (at(Some((0.01, 0.08)), None, 2e-3, 9000.0), false),
            (at(None, Some((0.01, 0.01)), d0, 9000.0), false),
            (at(None, Some((0.03, 0.01)), d0, 9000.0), true),
            (at(None, Some((0.03, 0.02)), d0, 9000.0), false),
            (at(None, Some((0.05, 0.02)), d0, 9000.0), true),
            (at(None, Some((0.05, 0.02)), d0, 3000.0), false),
            (at(None, Some((0.02, 0.02)), d0, 3000.0), true),
            (at(Some((0.02, 0.08)), None, d0, 3000.0), false),
            // both mixtures: nothing kept is read, nothing is replaced
            (at(Some((0.02, 0.08)), Some((0.02, 0.02)), d0, 3000.0), true),
            (at(Some((0.03, 0.08)), Some((0.02, 0.02)), d0, 3000.0), true),
        ];
        let ctx = Ctx::new(&data, &fw, usize::MAX);
        let kept = |c: &Ctx| {
            c.mix
                .lock()
                .unwrap()
                .as_ref()
                .map(|m| Arc::as_ptr(&m.l) as usize)
        };
        for (k, (st, reused)) in seq.iter().enumerate() {
            let before = kept(&ctx);
            let r = ctx.rates_for(st, RowSel::Fit).unwrap();
            let a = ctx.logl_with(st, &r, RowSel::Fit);
            let fresh = Ctx::new(&data, &fw, usize::MAX);
            let b = fresh.logl_with(st, &fresh.rates_for(st, RowSel::Fit).unwrap(), RowSel::Fit);
            assert!(a.is_finite(), "step {k}: {a}");
            assert_eq!(a.to_bits(), b.to_bits(), "step {k}: {a} vs fresh {b}");
            let after = kept(&ctx);
            assert_eq!(
                *reused,
                before.is_some() && before == after,
                "step {k}: kept {before:?} -> {after:?}"
            );
        }
    }

    /// The fit bands: FIT_BANDS runs of one even length starting at even rows, at most `n`
    /// rows in all (at least 2 per band), the first at the top, the last ending within one row
    /// of the bottom, sorted and distinct; none on a sensor too short for FIT_BANDS 2-row bands.
    #[test]
    fn fit_bands_are_even_runs_from_top_to_bottom_within_the_budget() {
        for (rows, n) in [
            (3000, 16),
            (3000, 64),
            (1024, 32),
            (480, 50),
            (100, 2),
            (40, 4),
        ] {
            let b = fit_bands(rows, n, &[]);
            assert!(b.windows(2).all(|w| w[0] < w[1]), "{rows} {n}: not sorted");
            let mut runs: Vec<(usize, usize)> = Vec::new();
            for &r in &b {
                match runs.last_mut() {
                    Some(l) if l.1 + 1 == r => l.1 = r,
                    _ => runs.push((r, r)),
                }
            }
            assert_eq!(runs.len(), FIT_BANDS, "{rows} {n}: {runs:?}");
            let len = runs[0].1 - runs[0].0 + 1;
            assert!(len >= 2 && len % 2 == 0, "{rows} {n}: length {len}");
            assert!(
                runs.iter().all(|r| r.1 - r.0 + 1 == len && r.0 % 2 == 0),
                "{rows} {n}: {runs:?}"
            );
            assert!(
                b.len() <= n.max(2 * FIT_BANDS),
                "{rows} {n}: {} rows",
                b.len()
            );
            assert_eq!(runs[0].0, 0);
            assert!(runs[FIT_BANDS - 1].1 + 2 >= rows, "{rows} {n}: {runs:?}");
        }
        assert!(fit_bands(9, 4, &[]).is_empty());
    }

    /// With scene structure, the inner fit bands move into the structured rows of their share
    /// of the height (a chart of 4 patch rows: evenly spaced bands all lie in the gaps), the
    /// outer ones stay at the frame's edges, and without structure nothing moves.
    #[test]
    fn inner_fit_bands_move_onto_the_scene_structure() {
        let rows = 3000;
        // a 4-row chart: patches (structure 1) on 112..637 of each 750-row cell
        let structure: Vec<f64> = (0..rows)
            .map(|r| {
                if (112..637).contains(&(r % 750)) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let even = fit_bands(rows, 10, &[]);
        assert_eq!(fit_bands(rows, 10, &vec![0.0; rows]), even);
        let runs = |b: &[usize]| -> Vec<usize> {
            b.iter()
                .copied()
                .filter(|&r| r == 0 || !b.contains(&(r - 1)))
                .collect()
        };
        let (e, m) = (runs(&even), runs(&fit_bands(rows, 10, &structure)));
        assert_eq!(e.len(), FIT_BANDS);
        assert_eq!(m.len(), FIT_BANDS);
        // the evenly spaced inner bands see no patch; the moved ones only patches
        assert!(
            e[1..FIT_BANDS - 1].iter().all(|&s| structure[s] == 0.0),
            "{e:?}"
        );
        assert!(
            m[1..FIT_BANDS - 1]
                .iter()
                .all(|&s| structure[s] == 1.0 && structure[s + 1] == 1.0),
            "{m:?}"
        );
        assert_eq!((m[0], m[FIT_BANDS - 1]), (e[0], e[FIT_BANDS - 1]));
        assert!(m.iter().all(|&s| s % 2 == 0) && m.windows(2).all(|w| w[0] + 2 <= w[1]));
    }

    /// A forward model that runs row windows and counts its whole-sensor runs per spec.
    struct CountingWindowed {
        rates: Vec<Arc<Vec<f32>>>,
        whole_runs: std::sync::Mutex<std::collections::HashMap<String, usize>>,
    }
    impl Forward for CountingWindowed {
        fn rates(&self, spec: &RateSpec) -> Result<Vec<Arc<Vec<f32>>>, String> {
            *self
                .whole_runs
                .lock()
                .unwrap()
                .entry(spec.key())
                .or_default() += 1;
            Ok(self.rates.clone())
        }
        fn rates_rows(&self, _: &RateSpec, _: &[usize]) -> Result<Vec<Arc<Vec<f32>>>, String> {
            Ok(self.rates.clone())
        }
        fn row_window(&self, _: &[usize]) -> bool {
            true
        }
    }

    #[test]
    fn fit_row_entries_do_not_evict_the_whole_sensor_rates() {
        // 64 × 8 flats, fits on 16 of the 64 rows: the fit rows run as windows.
        let (rows, cols) = (64usize, 8usize);
        let rate = Arc::new(vec![1.0e5f32; rows * cols]);
        let mut shots = Vec::new();
        for k in 0..2 {
            let mut acc = ShotAccumulator::new(rows, cols, 4095);
            for f in 0..2u16 {
                acc.add(&vec![1000 + 10 * k + f; rows * cols]).unwrap();
            }
            shots.push(acc.finish(
                format!("s{k}"),
                TargetClass::Uniform,
                format!("k{k}"),
                0.01,
                1.0,
            ));
        }
        let data = DataSet {
            rows,
            cols,
            channel: vec![0; rows * cols],
            channel_names: vec!["m".into()],
            max_dn: 4095.0,
            shots,
        };
        let fwd = CountingWindowed {
            rates: vec![rate.clone(), rate],
            whole_runs: Default::default(),
        };
        let ctx = Ctx::new(&data, &fwd, 16 * cols);
        assert!(ctx.fit_window && ctx.fit_rows.len() < rows);
        let believed = RateSpec::default();
        ctx.all_base_rates(&believed).unwrap();
        // more fit-row entries than the cache keeps of one kind (at most 4 096)
        for i in 1..=4_200 {
            let spec = RateSpec {
                glare_fraction: Some(1e-3 * i as f64),
                ..RateSpec::default()
            };
            ctx.base_rates(&spec).unwrap();
        }
        ctx.all_base_rates(&believed).unwrap();
        assert_eq!(fwd.whole_runs.lock().unwrap()[&believed.key()], 1);
    }
}
