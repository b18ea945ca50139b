//! Rate images: the forward model's results by rate spec (cached), and the exposure factor
//! and crosstalk applied to them.
use super::{prof, Ctx, Rates, RowSel};
use crate::mismatch::model::{crosstalk_image, ModelState, RateSpec};
use rayon::prelude::*;
use std::sync::Arc;

/// Key prefix of the rate cache's fit-row entries ([`Ctx::base_rates`]).
const FIT_ROWS_KEY: &str = "rows|";

impl Ctx<'_> {
    /// Rates of the forward model for `spec` on the rows a fit-row evaluation reads
    /// ([`Ctx::calc_rows`]; every row when the forward model computes them all anyway, see
    /// [`Ctx::fit_window`]); elsewhere possibly 0. Cached (fit-row and whole-sensor entries
    /// each up to ~512 MB, at least 8 entries of each kind).
    pub fn base_rates(&self, spec: &RateSpec) -> Result<Arc<Rates>, String> {
        if !self.fit_window {
            return self.all_base_rates(spec);
        }
        self.cached_rates(format!("{FIT_ROWS_KEY}{}", spec.key()), || {
            self.forward.rates_rows(spec, &self.calc_rows)
        })
    }

    /// Rates of the forward model for `spec` on every row (cached with [`Ctx::base_rates`]).
    pub fn all_base_rates(&self, spec: &RateSpec) -> Result<Arc<Rates>, String> {
        self.cached_rates(spec.key(), || self.forward.rates(spec))
    }

    /// The cache entry `key`, or `compute`d and kept.
    fn cached_rates(
        &self,
        key: String,
        compute: impl FnOnce() -> Result<Rates, String>,
    ) -> Result<Arc<Rates>, String> {
        let next = || {
            self.stamp
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        };
        if let Some(r) = self.cache.lock().expect("cache").get_mut(&key) {
            r.0 = next();
            return Ok(r.1.clone());
        }
        let t0 = std::time::Instant::now();
        let r = compute()?;
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
        // Fit-row entries and whole-sensor entries are evicted each within their own kind:
        // the fits make hundreds of fit-row entries, and the few whole-sensor ones (the
        // believed camera, each acceptance's full-resolution check, which the final fit check
        // repeats) would otherwise be evicted by them and cost a whole forward run again.
        let fit_kind = |k: &str| k.starts_with(FIT_ROWS_KEY);
        let kind = fit_kind(&key);
        let mut c = self.cache.lock().expect("cache");
        while c.keys().filter(|k| fit_kind(k) == kind).count() >= max_entries {
            let oldest = c
                .iter()
                .filter(|(k, _)| fit_kind(k) == kind)
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
        let base = self.all_base_rates(&state.rates)?;
        Ok(self.transform(&base, state))
    }

    /// [`Ctx::rates`] for an evaluation on `sel`'s rows (on the fit rows: from
    /// [`Ctx::base_rates`], right on the fit rows).
    pub fn rates_for(&self, state: &ModelState, sel: RowSel) -> Result<Rates, String> {
        match sel {
            RowSel::All => self.rates(state),
            RowSel::Fit => Ok(self.transform(&*self.base_rates(&state.rates)?, state)),
        }
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
}
