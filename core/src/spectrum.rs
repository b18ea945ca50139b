//! Spectra and wavelength grids.
//!
//! A spectrum is, as ../spec/capture-format.md defines it, a list of strictly increasing
//! wavelengths with values, **linearly interpolated and zero outside the given range**; a bare
//! number is a constant at every wavelength. Products of such functions are integrated exactly
//! (Simpson on the merged breakpoints, exact for the quadratic pieces), so `∫ QE(λ) E(λ) dλ` of
//! the baseline model does not depend on a sampling grid.
use crate::constants::PhysicalConstants;
use crate::error::CoreError;
use serde::{Deserialize, Serialize};

/// A spectral function of wavelength in nm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Spectrum {
    /// `offset + slope_per_nm · λ` at every wavelength (a bare number is `slope_per_nm = 0`).
    Affine {
        /// Value at λ = 0.
        offset: f64,
        /// Slope per nm.
        slope_per_nm: f64,
    },
    /// Piecewise linear through the samples, zero outside `[first, last]`.
    Sampled {
        /// Strictly increasing wavelengths (nm).
        wavelength_nm: Vec<f64>,
        /// One value per wavelength.
        values: Vec<f64>,
    },
}

/// Largest interval (nm) kept linear when a product of spectra is re-sampled.
pub const PRODUCT_MAX_STEP_NM: f64 = 2.0;

/// The longest wavelength a spectrum or grid may name: 1 mm (10⁶ nm), past the far infrared
/// (thermal cameras image 8–14 µm). It bounds the work of a product of spectra, which is
/// refined every [`PRODUCT_MAX_STEP_NM`] over its span: at most 5·10⁵ samples per product.
/// Without it a file naming 1e308 nm made [`Spectrum::multiply`] loop for ever (issue 16).
pub const MAX_WAVELENGTH_NM: f64 = 1e6;

impl Spectrum {
    /// The constant spectrum `value` (a bare number in the file format).
    pub fn constant(value: f64) -> Self {
        Spectrum::Affine {
            offset: value,
            slope_per_nm: 0.0,
        }
    }

    /// A validated sampled spectrum: same lengths, at least one sample, finite numbers,
    /// strictly increasing wavelengths.
    pub fn sampled(wavelength_nm: Vec<f64>, values: Vec<f64>) -> Result<Self, CoreError> {
        if wavelength_nm.len() != values.len() {
            return Err(CoreError::Spectrum(format!(
                "wavelength_nm has {} entries but values has {}",
                wavelength_nm.len(),
                values.len()
            )));
        }
        if wavelength_nm.is_empty() {
            return Err(CoreError::Spectrum("no samples".into()));
        }
        if let Some(i) = wavelength_nm
            .iter()
            .position(|w| !w.is_finite() || *w <= 0.0)
        {
            return Err(CoreError::Spectrum(format!(
                "wavelength_nm[{i}] = {} is not a positive finite number",
                wavelength_nm[i]
            )));
        }
        if let Some(i) = wavelength_nm.iter().position(|w| *w > MAX_WAVELENGTH_NM) {
            return Err(CoreError::Spectrum(format!(
                "wavelength_nm[{i}] = {:e} nm is beyond {MAX_WAVELENGTH_NM:e} nm (1 mm, the \
                 longest wavelength camsim accepts)",
                wavelength_nm[i]
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(CoreError::Spectrum(format!("values[{i}] is not finite")));
        }
        if let Some(i) = wavelength_nm.windows(2).position(|w| w[1] <= w[0]) {
            return Err(CoreError::Spectrum(format!(
                "wavelengths must be strictly increasing: wavelength_nm[{}] = {} follows {}",
                i + 1,
                wavelength_nm[i + 1],
                wavelength_nm[i]
            )));
        }
        Ok(Spectrum::Sampled {
            wavelength_nm,
            values,
        })
    }

    /// Validates a spectrum that came from serde (untagged) input.
    pub fn validated(self) -> Result<Self, CoreError> {
        match self {
            Spectrum::Sampled {
                wavelength_nm,
                values,
            } => Spectrum::sampled(wavelength_nm, values),
            a @ Spectrum::Affine { .. } => {
                if let Spectrum::Affine {
                    offset,
                    slope_per_nm,
                } = a
                {
                    if !offset.is_finite() || !slope_per_nm.is_finite() {
                        return Err(CoreError::Spectrum("constant is not finite".into()));
                    }
                }
                Ok(a)
            }
        }
    }

    /// Value at `wavelength_nm` (linear interpolation, zero outside a sampled range).
    pub fn eval(&self, wavelength_nm: f64) -> f64 {
        match self {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } => offset + slope_per_nm * wavelength_nm,
            Spectrum::Sampled {
                wavelength_nm: w,
                values: v,
            } => {
                let n = w.len();
                if wavelength_nm < w[0] || wavelength_nm > w[n - 1] {
                    return 0.0;
                }
                if n == 1 {
                    return v[0];
                }
                // Binary search for the interval holding the wavelength.
                let i = match w.binary_search_by(|x| x.partial_cmp(&wavelength_nm).unwrap()) {
                    Ok(i) => return v[i],
                    Err(i) => i,
                };
                let (w0, w1) = (w[i - 1], w[i]);
                let t = (wavelength_nm - w0) / (w1 - w0);
                v[i - 1] + t * (v[i] - v[i - 1])
            }
        }
    }

    /// Support `[lo, hi]` of the spectrum (infinite for an affine spectrum).
    pub fn support_nm(&self) -> (f64, f64) {
        match self {
            Spectrum::Affine { .. } => (f64::NEG_INFINITY, f64::INFINITY),
            Spectrum::Sampled { wavelength_nm, .. } => {
                (wavelength_nm[0], wavelength_nm[wavelength_nm.len() - 1])
            }
        }
    }

    fn breakpoints(&self) -> &[f64] {
        match self {
            Spectrum::Affine { .. } => &[],
            Spectrum::Sampled { wavelength_nm, .. } => wavelength_nm,
        }
    }

    /// Merged breakpoints of `a` and `b` inside the intersection of their supports, or None
    /// when the intersection is unbounded (two affine spectra).
    fn merged_breakpoints(a: &Spectrum, b: &Spectrum) -> Option<Vec<f64>> {
        let (a0, a1) = a.support_nm();
        let (b0, b1) = b.support_nm();
        let (lo, hi) = (a0.max(b0), a1.min(b1));
        if !lo.is_finite() || !hi.is_finite() {
            return None;
        }
        if hi <= lo {
            return Some(Vec::new());
        }
        let mut pts: Vec<f64> = a
            .breakpoints()
            .iter()
            .chain(b.breakpoints())
            .copied()
            .filter(|&x| x >= lo && x <= hi)
            .collect();
        pts.push(lo);
        pts.push(hi);
        pts.sort_by(|x, y| x.partial_cmp(y).unwrap());
        pts.dedup();
        Some(pts)
    }

    /// Exact ∫ a(λ) b(λ) dλ (nm) of two piecewise-linear spectra. None when both are affine
    /// (the integral is unbounded).
    pub fn integrate_product(a: &Spectrum, b: &Spectrum) -> Option<f64> {
        let pts = Spectrum::merged_breakpoints(a, b)?;
        let mut sum = 0.0;
        for w in pts.windows(2) {
            let (x0, x1) = (w[0], w[1]);
            // Both functions are linear on [x0, x1]; evaluate just inside the interval so the
            // zero-outside jumps at the support ends are handled as one-sided limits.
            let (fa, fb) = (a.eval_inside(x0, x1, true), a.eval_inside(x0, x1, false));
            let (ga, gb) = (b.eval_inside(x0, x1, true), b.eval_inside(x0, x1, false));
            sum += (x1 - x0) / 6.0 * (2.0 * fa * ga + fa * gb + fb * ga + 2.0 * fb * gb);
        }
        Some(sum)
    }

    /// One-sided value at an end of the interval [x0, x1], which lies inside the support.
    fn eval_inside(&self, x0: f64, x1: f64, left: bool) -> f64 {
        let x = if left { x0 } else { x1 };
        let (lo, hi) = self.support_nm();
        if x0 >= lo && x1 <= hi {
            self.eval(x)
        } else {
            0.0
        }
    }

    /// Exact ∫ a(λ) dλ over its support (None for an affine spectrum).
    pub fn integral(&self) -> Option<f64> {
        match self {
            Spectrum::Affine { .. } => None,
            Spectrum::Sampled {
                wavelength_nm: w,
                values: v,
            } => Some(
                w.windows(2)
                    .zip(v.windows(2))
                    .map(|(w, v)| 0.5 * (w[1] - w[0]) * (v[0] + v[1]))
                    .sum(),
            ),
        }
    }

    /// Pointwise product, re-sampled as a piecewise-linear spectrum on the merged breakpoints
    /// refined to at most [`PRODUCT_MAX_STEP_NM`] (the product of two linear pieces is
    /// quadratic; the refinement keeps the interpolation error below ~1e-5 for smooth data).
    /// At most about 5·10⁵ refined samples plus the breakpoints ([`MAX_WAVELENGTH_NM`]).
    pub fn multiply(a: &Spectrum, b: &Spectrum) -> Spectrum {
        match (a, b) {
            (
                Spectrum::Affine {
                    offset: o1,
                    slope_per_nm: s1,
                },
                Spectrum::Affine {
                    offset: o2,
                    slope_per_nm: s2,
                },
            ) if *s1 == 0.0 || *s2 == 0.0 => {
                // constant × affine stays affine
                let (c, o, s) = if *s1 == 0.0 {
                    (*o1, *o2, *s2)
                } else {
                    (*o2, *o1, *s1)
                };
                Spectrum::Affine {
                    offset: c * o,
                    slope_per_nm: c * s,
                }
            }
            (
                Spectrum::Affine {
                    offset,
                    slope_per_nm,
                },
                s @ Spectrum::Sampled { .. },
            )
            | (
                s @ Spectrum::Sampled { .. },
                Spectrum::Affine {
                    offset,
                    slope_per_nm,
                },
            ) if *slope_per_nm == 0.0 => s.scaled(*offset),
            _ => {
                let pts = Spectrum::merged_breakpoints(a, b)
                    .expect("product of two non-constant affine spectra is not representable");
                // A bounded refinement: validated spectra span at most MAX_WAVELENGTH_NM, so
                // the step is PRODUCT_MAX_STEP_NM; a wider span (a spectrum built without
                // `sampled`) widens the step instead of refining without bound.
                let span = pts.last().zip(pts.first()).map_or(0.0, |(h, l)| h - l);
                let step = PRODUCT_MAX_STEP_NM.max(span * PRODUCT_MAX_STEP_NM / MAX_WAVELENGTH_NM);
                let mut w = Vec::with_capacity(pts.len() * 2);
                for win in pts.windows(2) {
                    let n = ((win[1] - win[0]) / step).ceil().max(1.0) as usize;
                    w.push(win[0]);
                    for k in 1..n {
                        w.push(win[0] + (win[1] - win[0]) * k as f64 / n as f64);
                    }
                }
                if let Some(&last) = pts.last() {
                    w.push(last);
                }
                if w.is_empty() {
                    return Spectrum::Sampled {
                        wavelength_nm: vec![1.0],
                        values: vec![0.0],
                    };
                }
                let v = w.iter().map(|&x| a.eval(x) * b.eval(x)).collect();
                Spectrum::Sampled {
                    wavelength_nm: w,
                    values: v,
                }
            }
        }
    }

    /// The spectrum times a scalar.
    pub fn scaled(&self, k: f64) -> Spectrum {
        match self {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } => Spectrum::Affine {
                offset: offset * k,
                slope_per_nm: slope_per_nm * k,
            },
            Spectrum::Sampled {
                wavelength_nm,
                values,
            } => Spectrum::Sampled {
                wavelength_nm: wavelength_nm.clone(),
                values: values.iter().map(|v| v * k).collect(),
            },
        }
    }

    /// Energy units (W/…/nm) to photon units (photons/s/…/nm): multiply by λ/(hc).
    /// Exact for affine spectra; sampled spectra are refined (≤ 2 nm) first.
    pub fn energy_to_photons(&self, c: &PhysicalConstants) -> Spectrum {
        let k = c.photons_per_joule(1.0); // per nm of wavelength
        match self {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } if *slope_per_nm == 0.0 => Spectrum::Affine {
                offset: 0.0,
                slope_per_nm: offset * k,
            },
            _ => Spectrum::multiply(
                self,
                &Spectrum::Affine {
                    offset: 0.0,
                    slope_per_nm: k,
                },
            ),
        }
    }

    /// Samples on `grid`.
    pub fn sample(&self, grid: &WavelengthGrid) -> Vec<f64> {
        grid.wavelength_nm.iter().map(|&w| self.eval(w)).collect()
    }

    /// True when every value is ≥ 0 (affine: non-negative over 1–100000 nm is not checked;
    /// a constant must be ≥ 0).
    pub fn is_non_negative(&self) -> bool {
        match self {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } => *offset >= 0.0 && *slope_per_nm >= 0.0,
            Spectrum::Sampled { values, .. } => values.iter().all(|v| *v >= 0.0),
        }
    }

    /// The index of the first negative sample, if any.
    pub fn first_negative(&self) -> Option<(f64, f64)> {
        match self {
            Spectrum::Affine { offset, .. } => (*offset < 0.0).then_some((0.0, *offset)),
            Spectrum::Sampled {
                wavelength_nm,
                values,
            } => values
                .iter()
                .position(|v| *v < 0.0)
                .map(|i| (wavelength_nm[i], values[i])),
        }
    }
}

/// Strictly increasing sample wavelengths of a spectral image (nm).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WavelengthGrid {
    /// The wavelengths (nm), strictly increasing.
    pub wavelength_nm: Vec<f64>,
}

/// The most bands a regular grid may have (0.01 nm steps over 300–1300 nm).
pub const MAX_GRID_BANDS: usize = 100_000;

impl WavelengthGrid {
    /// A validated grid.
    pub fn new(wavelength_nm: Vec<f64>) -> Result<Self, CoreError> {
        if wavelength_nm.is_empty() {
            return Err(CoreError::Grid("no wavelengths".into()));
        }
        if let Some(i) = wavelength_nm.windows(2).position(|w| !(w[1] > w[0])) {
            return Err(CoreError::Grid(format!(
                "wavelengths must be strictly increasing: {} follows {}",
                wavelength_nm[i + 1],
                wavelength_nm[i]
            )));
        }
        if wavelength_nm.iter().any(|w| !w.is_finite() || *w <= 0.0) {
            return Err(CoreError::Grid(
                "wavelengths must be positive finite numbers".into(),
            ));
        }
        if let Some(w) = wavelength_nm.iter().find(|w| **w > MAX_WAVELENGTH_NM) {
            return Err(CoreError::Grid(format!(
                "wavelength {w:e} nm is beyond {MAX_WAVELENGTH_NM:e} nm (1 mm, the longest \
                 wavelength camsim accepts)"
            )));
        }
        Ok(WavelengthGrid { wavelength_nm })
    }

    /// `start, start+step, …, stop` (inclusive, within a rounding tolerance).
    /// At most [`MAX_GRID_BANDS`] bands (a finer grid is refused, never allocated).
    pub fn regular(start_nm: f64, stop_nm: f64, step_nm: f64) -> Result<Self, CoreError> {
        if !(step_nm > 0.0) || !(stop_nm >= start_nm) {
            return Err(CoreError::Grid(format!(
                "need start ≤ stop and step > 0, got {start_nm}..{stop_nm} step {step_nm}"
            )));
        }
        let n_f = ((stop_nm - start_nm) / step_nm + 1e-9).floor() + 1.0;
        if !(n_f <= MAX_GRID_BANDS as f64) {
            return Err(CoreError::Grid(format!(
                "{start_nm}..{stop_nm} step {step_nm} nm gives {n_f:.3e} bands; at most \
                 {MAX_GRID_BANDS} are allowed (raise step_nm)"
            )));
        }
        let n = n_f as usize;
        WavelengthGrid::new((0..n).map(|i| start_nm + step_nm * i as f64).collect())
    }

    /// The camsim default: 400–700 nm in 10 nm steps (31 bands).
    pub fn default_visible() -> Self {
        WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap()
    }

    /// Number of bands.
    pub fn len(&self) -> usize {
        self.wavelength_nm.len()
    }

    /// True when the grid is empty (never, for a validated grid).
    pub fn is_empty(&self) -> bool {
        self.wavelength_nm.is_empty()
    }

    /// The uniform step when the grid is regular (to 1e-6 relative), else None.
    pub fn step_nm(&self) -> Option<f64> {
        let w = &self.wavelength_nm;
        if w.len() < 2 {
            return None;
        }
        let s = w[1] - w[0];
        w.windows(2)
            .all(|p| ((p[1] - p[0]) - s).abs() <= 1e-6 * s)
            .then_some(s)
    }

    /// The "hat" basis function of band `i`: 1 at λ_i, linear to 0 at the neighbours, and (by
    /// the zero-outside rule) 0 beyond the first and last wavelengths. A band cube on this grid
    /// is the piecewise-linear spectrum Σ_i L_i hat_i.
    pub fn hat(&self, i: usize) -> Spectrum {
        let w = &self.wavelength_nm;
        let mut wl = Vec::with_capacity(3);
        let mut v = Vec::with_capacity(3);
        if i > 0 {
            wl.push(w[i - 1]);
            v.push(0.0);
        }
        wl.push(w[i]);
        v.push(1.0);
        if i + 1 < w.len() {
            wl.push(w[i + 1]);
            v.push(0.0);
        }
        Spectrum::Sampled {
            wavelength_nm: wl,
            values: v,
        }
    }

    /// Trapezoid quadrature weights (nm) of the grid: ∫ f = Σ f_i w_i for the piecewise-linear
    /// interpolant (equal to ∫ hat_i).
    pub fn trapezoid_weights_nm(&self) -> Vec<f64> {
        let w = &self.wavelength_nm;
        let n = w.len();
        (0..n)
            .map(|i| {
                let l = if i > 0 { w[i] - w[i - 1] } else { 0.0 };
                let r = if i + 1 < n { w[i + 1] - w[i] } else { 0.0 };
                0.5 * (l + r)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn s(w: &[f64], v: &[f64]) -> Spectrum {
        Spectrum::sampled(w.to_vec(), v.to_vec()).unwrap()
    }

    #[test]
    fn interpolates_and_is_zero_outside() {
        let a = s(&[400.0, 500.0], &[1.0, 3.0]);
        assert_eq!(a.eval(450.0), 2.0);
        assert_eq!(a.eval(399.9), 0.0);
        assert_eq!(a.eval(500.1), 0.0);
        assert_eq!(a.eval(500.0), 3.0);
    }

    #[test]
    fn rejects_bad_spectra() {
        assert!(Spectrum::sampled(vec![400.0, 400.0], vec![1.0, 1.0]).is_err());
        assert!(Spectrum::sampled(vec![500.0, 400.0], vec![1.0, 1.0]).is_err());
        assert!(Spectrum::sampled(vec![400.0], vec![1.0, 1.0]).is_err());
        assert!(Spectrum::sampled(vec![400.0, 410.0], vec![1.0, f64::NAN]).is_err());
    }

    #[test]
    fn product_integral_is_exact_for_linear_pieces() {
        // ∫_400^700 (λ-400)/300 · 2 dλ = 300 ; ∫ x² over [0,1]·300 = 100 for x·x
        let a = s(&[400.0, 700.0], &[0.0, 1.0]);
        let c = Spectrum::constant(2.0);
        assert_relative_eq!(
            Spectrum::integrate_product(&a, &c).unwrap(),
            300.0,
            epsilon = 1e-9
        );
        assert_relative_eq!(
            Spectrum::integrate_product(&a, &a).unwrap(),
            100.0,
            epsilon = 1e-9
        );
        // different breakpoints: (λ) on [400,700] × step inside [500,600]
        let b = s(&[500.0, 600.0], &[1.0, 1.0]);
        // ∫_500^600 (λ-400)/300 dλ = (200²-100²)/600 = 50
        assert_relative_eq!(
            Spectrum::integrate_product(&a, &b).unwrap(),
            50.0,
            epsilon = 1e-9
        );
        assert!(Spectrum::integrate_product(&c, &c).is_none());
    }

    #[test]
    fn hats_partition_unity_and_integrate_like_trapezoid() {
        let g = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
        let w = g.trapezoid_weights_nm();
        let one = Spectrum::constant(1.0);
        for i in 0..g.len() {
            assert_relative_eq!(
                Spectrum::integrate_product(&g.hat(i), &one).unwrap(),
                w[i],
                epsilon = 1e-12
            );
        }
        assert_relative_eq!(w.iter().sum::<f64>(), 300.0, epsilon = 1e-9);
    }

    #[test]
    fn energy_to_photons_roundtrip_value() {
        let c = crate::constants::ISETCAM;
        let e = s(&[400.0, 700.0], &[0.1, 0.1]);
        let p = e.energy_to_photons(&c);
        // ISETCam oracle utility_energy_quanta_1d: 0.1 W at 400 nm -> 2.01361446e17 photons
        assert_relative_eq!(p.eval(400.0), 2.01361446e17, max_relative = 1e-8);
    }

    #[test]
    fn wavelengths_beyond_1_mm_are_refused_and_products_stay_bounded() {
        // issue 16: a capture set's radiance at [400, 1.8e308] nm made energy_to_photons
        // refine the product every 2 nm for ever.
        let e = Spectrum::sampled(vec![400.0, f64::MAX], vec![1.0, 1.0]).unwrap_err();
        assert!(e.to_string().contains("wavelength_nm[1]"), "{e}");
        assert!(Spectrum::sampled(vec![400.0, MAX_WAVELENGTH_NM], vec![1.0, 1.0]).is_ok());
        assert!(WavelengthGrid::new(vec![400.0, 2e6]).is_err());
        assert!(WavelengthGrid::regular(1e300, 2e300, 1e299).is_err());
        // Built without `sampled`: the refinement widens its step instead of running away.
        let wide = Spectrum::Sampled {
            wavelength_nm: vec![400.0, 1e300],
            values: vec![1.0, 1.0],
        };
        let p = wide.energy_to_photons(&crate::constants::SI);
        let Spectrum::Sampled { wavelength_nm, .. } = &p else {
            panic!("{p:?}")
        };
        let n_max = (MAX_WAVELENGTH_NM / PRODUCT_MAX_STEP_NM) as usize + 2;
        assert!(wavelength_nm.len() <= n_max, "{}", wavelength_nm.len());
        // Within 1 mm the 2 nm refinement is unchanged.
        let q = s(&[400.0, 700.0], &[1.0, 1.0]).energy_to_photons(&crate::constants::SI);
        let Spectrum::Sampled { wavelength_nm, .. } = &q else {
            panic!("{q:?}")
        };
        assert_eq!(wavelength_nm.len(), 151);
    }
}
