//! EMVA 1288 Release 4.0 Linear: the characterisation of a linear camera from a photon-transfer
//! series (pairs of bright and dark frames at increasing photon counts) and two stacks of
//! frames (bright at about 50 % saturation, dark) for the spatial nonuniformities.
//!
//! Every datasheet number has one function here, each documented with the part of the
//! standard (Release 4.0 Linear, "Rel. 4.0 §…" below; sections as numbered in that
//! document: §6 sensitivity, linearity and noise by the photon-transfer method, §7 dark
//! current, §8 spatial nonuniformity) it implements. Input statistics are computed by
//! [`pair_stats`] and [`spatial::StackAccumulator`] from `u16` frames, so a series is analysed
//! in one pass without holding its frames.
//!
//! Conventions where the standard leaves a choice (the same as the reference implementation
//! `emva1288` 1.0.2, so both give the same numbers on the same images):
//! * the saturation point is the measurement point of largest temporal variance;
//! * K and R are fitted through the origin over the points from the first up to the last one
//!   at or below 70 % of the saturation signal; the linearity fit uses 5 %–95 %;
//! * with more than two exposure times the dark variance and dark mean are fitted linearly
//!   against exposure time: the intercept of the variance gives σ²_y.dark (floored at
//!   0.24 DN², the standard's quantisation limit), the slopes give the dark current.
pub mod spatial;

use serde::Serialize;

/// Quantisation noise variance of an ideal ADC, 1/12 DN² (Rel. 4.0 §2, camera model).
pub const QUANTISATION_VAR_DN2: f64 = 1.0 / 12.0;

/// Lower limit of the temporal dark variance, 0.24 DN²: below it the dark noise is dominated
/// by quantisation and is not resolved (Rel. 4.0 §6, temporal dark noise).
pub const MIN_DARK_VAR_DN2: f64 = 0.24;

/// Mean and temporal variance of one measurement point from its two frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PairStats {
    /// Mean of both frames μ_y (DN).
    pub mean_dn: f64,
    /// Temporal variance σ²_y (DN²).
    pub var_dn2: f64,
}

/// Mean and temporal variance from two frames A and B of N pixels (Rel. 4.0 §6, the
/// photon-transfer evaluation):
/// `μ_y = 1/(2N) Σ (y_A + y_B)`,
/// `σ²_y = 1/(2N) Σ (y_A − y_B)² − ½ (μ_A − μ_B)²` (the second term removes a change of the
/// mean between the two frames). Frames of different sizes give NaN.
pub fn pair_stats(a: &[u16], b: &[u16]) -> PairStats {
    if a.len() != b.len() || a.is_empty() {
        return PairStats {
            mean_dn: f64::NAN,
            var_dn2: f64::NAN,
        };
    }
    let (mut sa, mut sb, mut sd2) = (0u64, 0u64, 0u64);
    for (&x, &y) in a.iter().zip(b) {
        sa += x as u64;
        sb += y as u64;
        // |x − y|² < 2³²: exact in u32 (a 16-bit widening multiply, which vectorises).
        let d = x.abs_diff(y) as u32;
        sd2 += (d * d) as u64;
    }
    let n = a.len() as f64;
    let (ma, mb) = (sa as f64 / n, sb as f64 / n);
    PairStats {
        mean_dn: 0.5 * (ma + mb),
        var_dn2: sd2 as f64 / (2.0 * n) - 0.5 * (ma - mb).powi(2),
    }
}

/// One photon-transfer measurement point: a bright pair and the dark pair at its exposure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TemporalPoint {
    /// Exposure time (s).
    pub exposure_s: f64,
    /// Mean photons per pixel during the exposure μ_p.
    pub photons_per_pixel: f64,
    /// Bright pair.
    pub bright: PairStats,
    /// Dark pair at the same exposure time.
    pub dark: PairStats,
}

impl TemporalPoint {
    /// Signal above dark μ_y − μ_y.dark (DN).
    pub fn signal_dn(&self) -> f64 {
        self.bright.mean_dn - self.dark.mean_dn
    }
    /// Temporal variance above dark σ²_y − σ²_y.dark (DN²).
    pub fn signal_var_dn2(&self) -> f64 {
        self.bright.var_dn2 - self.dark.var_dn2
    }
}

/// A value with its standard uncertainty (NaN when the standard defines none and none can
/// be estimated).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Measured {
    /// The value.
    pub value: f64,
    /// Its standard uncertainty (same unit).
    pub uncertainty: f64,
}

impl Measured {
    fn new(value: f64, uncertainty: f64) -> Self {
        Measured { value, uncertainty }
    }
}

/// A straight-line least-squares fit `y = slope · x + offset` with standard errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LineFit {
    /// Slope.
    pub slope: f64,
    /// Standard error of the slope.
    pub slope_se: f64,
    /// Offset (0 for a fit through the origin).
    pub offset: f64,
    /// Standard error of the offset (0 for a fit through the origin).
    pub offset_se: f64,
}

/// Least-squares slope through the origin `y = m x` (Rel. 4.0 §6: R and K are fitted
/// "through the origin"): `m = Σxy / Σx²`, standard error `√(Σr²/(n−1) / Σx²)`.
pub fn fit_through_origin(x: &[f64], y: &[f64]) -> LineFit {
    let sxx: f64 = x.iter().map(|v| v * v).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| a * b).sum();
    let m = sxy / sxx;
    let n = x.len() as f64;
    let rss: f64 = x.iter().zip(y).map(|(a, b)| (b - m * a).powi(2)).sum();
    LineFit {
        slope: m,
        slope_se: if n > 1.0 {
            (rss / (n - 1.0) / sxx).sqrt()
        } else {
            f64::NAN
        },
        offset: 0.0,
        offset_se: 0.0,
    }
}

/// Ordinary least-squares line `y = a x + b` with the textbook standard errors
/// (Rel. 4.0 §7: dark mean and dark variance against exposure time):
/// [`camsim_core::stats::fit_line`] in this module's field names.
pub fn fit_line(x: &[f64], y: &[f64]) -> LineFit {
    let f = camsim_core::stats::fit_line(x, y);
    LineFit {
        slope: f.slope,
        slope_se: f.slope_std_error,
        offset: f.intercept,
        offset_se: f.intercept_std_error,
    }
}

/// Index of the saturation point: the point of largest temporal variance σ²_y
/// (Rel. 4.0 §6, saturation: "the maximum of the variance"). Points must be sorted by μ_p.
pub fn saturation_index(points: &[TemporalPoint]) -> usize {
    let mut best = 0;
    for (i, p) in points.iter().enumerate() {
        if p.bright.var_dn2 > points[best].bright.var_dn2 {
            best = i;
        }
    }
    best
}

/// Last index whose signal above dark is at or below `fraction` of the signal at
/// saturation, and first index at or above it: the fit ranges of Rel. 4.0 §6 (K, R: up to
/// 70 %) and of the linearity (5 %–95 %).
fn last_at_or_below(points: &[TemporalPoint], sat: usize, fraction: f64) -> Option<usize> {
    let limit = fraction * points[sat].signal_dn();
    points.iter().rposition(|p| p.signal_dn() <= limit)
}

fn first_at_or_above(points: &[TemporalPoint], sat: usize, fraction: f64) -> Option<usize> {
    let limit = fraction * points[sat].signal_dn();
    points.iter().position(|p| p.signal_dn() >= limit)
}

/// Responsivity R (DN/photon): slope through the origin of μ_y − μ_y.dark against μ_p over
/// the points up to 70 % of saturation (Rel. 4.0 §6, sensitivity).
pub fn responsivity(points: &[TemporalPoint], fit_end: usize) -> LineFit {
    let x: Vec<f64> = points[..=fit_end]
        .iter()
        .map(|p| p.photons_per_pixel)
        .collect();
    let y: Vec<f64> = points[..=fit_end].iter().map(|p| p.signal_dn()).collect();
    fit_through_origin(&x, &y)
}

/// Overall system gain K (DN/e⁻): slope through the origin of σ²_y − σ²_y.dark against
/// μ_y − μ_y.dark up to 70 % of saturation (Rel. 4.0 §6, photon transfer:
/// `σ²_y − σ²_y.dark = K (μ_y − μ_y.dark)`).
pub fn system_gain(points: &[TemporalPoint], fit_end: usize) -> LineFit {
    let x: Vec<f64> = points[..=fit_end].iter().map(|p| p.signal_dn()).collect();
    let y: Vec<f64> = points[..=fit_end]
        .iter()
        .map(|p| p.signal_var_dn2())
        .collect();
    fit_through_origin(&x, &y)
}

/// Quantum efficiency η = R / K (Rel. 4.0 §6), with the uncertainties of R and K combined
/// as independent.
pub fn quantum_efficiency(r: &LineFit, k: &LineFit) -> Measured {
    let eta = r.slope / k.slope;
    let rel = ((r.slope_se / r.slope).powi(2) + (k.slope_se / k.slope).powi(2)).sqrt();
    Measured::new(eta, eta * rel)
}

/// Temporal dark variance σ²_y.dark (DN²) at zero exposure: the intercept of a line fitted to
/// the dark variances against exposure time when more than two exposure times were used,
/// else the first dark variance; floored at [`MIN_DARK_VAR_DN2`] (Rel. 4.0 §6, temporal
/// dark noise, and §7).
pub fn dark_variance(points: &[TemporalPoint]) -> Measured {
    let (v, u) = if distinct_exposures(points) > 2 {
        let f = dark_fit(points, |p| p.dark.var_dn2);
        (f.offset, f.offset_se)
    } else {
        let v = points[0].dark.var_dn2;
        (v, f64::NAN)
    };
    if v < MIN_DARK_VAR_DN2 {
        Measured::new(MIN_DARK_VAR_DN2, u)
    } else {
        Measured::new(v, u)
    }
}

fn distinct_exposures(points: &[TemporalPoint]) -> usize {
    let mut t: Vec<f64> = points.iter().map(|p| p.exposure_s).collect();
    t.sort_by(f64::total_cmp);
    t.dedup();
    t.len()
}

fn dark_fit(points: &[TemporalPoint], f: impl Fn(&TemporalPoint) -> f64) -> LineFit {
    let x: Vec<f64> = points.iter().map(|p| p.exposure_s).collect();
    let y: Vec<f64> = points.iter().map(f).collect();
    fit_line(&x, &y)
}

/// Temporal dark noise σ_d in electrons: `σ_d = √(σ²_y.dark − σ²_q) / K` (Rel. 4.0 §6).
pub fn dark_noise_electrons(dark_var: &Measured, k: &LineFit) -> Measured {
    let s = (dark_var.value - QUANTISATION_VAR_DN2).max(0.0).sqrt();
    let v = s / k.slope;
    let u_s = dark_var.uncertainty / (2.0 * s.max(1e-12));
    let u = v * ((u_s / s).powi(2) + (k.slope_se / k.slope).powi(2)).sqrt();
    Measured::new(v, u)
}

/// Absolute sensitivity threshold μ_p.min (photons): the photon count for SNR = 1,
/// `μ_p.min = (σ_y.dark / K + ½) / η` (Rel. 4.0 §6, eq. for the absolute sensitivity
/// threshold, with σ_y.dark = √σ²_y.dark in DN).
pub fn sensitivity_threshold_photons(dark_var: &Measured, k: &LineFit, eta: &Measured) -> Measured {
    let sy = dark_var.value.sqrt();
    let v = (sy / k.slope + 0.5) / eta.value;
    let u = v * (eta.uncertainty / eta.value);
    Measured::new(v, u)
}

/// Saturation capacity μ_p.sat (photons) = μ_p at the saturation point, and μ_e.sat = η μ_p.sat
/// (Rel. 4.0 §6, saturation). The uncertainty of μ_p.sat is one photon step of the series
/// at that point (its resolution: the variance peak can fall on either neighbour).
pub fn saturation_capacity(points: &[TemporalPoint], sat: usize) -> Measured {
    let p = points[sat].photons_per_pixel;
    let lo = if sat > 0 {
        points[sat - 1].photons_per_pixel
    } else {
        p
    };
    let hi = points.get(sat + 1).map_or(p, |q| q.photons_per_pixel);
    Measured::new(p, 0.5 * (hi - lo).abs())
}

/// Maximum signal-to-noise ratio `SNR_max = √μ_e.sat` (Rel. 4.0 §6, SNR).
pub fn snr_max(ue_sat: &Measured) -> Measured {
    let v = ue_sat.value.sqrt();
    Measured::new(v, 0.5 * v * ue_sat.uncertainty / ue_sat.value)
}

/// Dynamic range `DR = μ_p.sat / μ_p.min` (Rel. 4.0 §6, dynamic range).
pub fn dynamic_range(up_sat: &Measured, up_min: &Measured) -> Measured {
    let v = up_sat.value / up_min.value;
    let rel = ((up_sat.uncertainty / up_sat.value).powi(2)
        + (up_min.uncertainty / up_min.value).powi(2))
    .sqrt();
    Measured::new(v, v * rel)
}

/// The SNR model curve of Rel. 4.0 §6 (SNR diagram):
/// `SNR(μ_p) = η μ_p / √(σ²_d + σ²_q/K² + η μ_p)`.
pub fn snr_model(photons: f64, eta: f64, sigma_d_e: f64, k: f64) -> f64 {
    let s = eta * photons;
    s / (sigma_d_e * sigma_d_e + QUANTISATION_VAR_DN2 / (k * k) + s).sqrt()
}

/// The linearity evaluation of Rel. 4.0 §6 (linearity).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Linearity {
    /// Slope a₁ of the weighted fit μ_y − μ_y.dark = a₀ + a₁ μ_p (DN/photon).
    pub slope_dn_per_photon: f64,
    /// Offset a₀ (DN).
    pub offset_dn: f64,
    /// Relative deviation from the fit for every point (%).
    pub deviation_percent: Vec<f64>,
    /// First and last index of the fit range (5 %–95 % of saturation).
    pub range: (usize, usize),
    /// Smallest deviation in the range (%).
    pub le_min_percent: f64,
    /// Largest deviation in the range (%).
    pub le_max_percent: f64,
    /// Linearity error LE = (max δ − min δ) / 2 (%).
    pub le_percent: f64,
}

/// Linearity (Rel. 4.0 §6): a line `y = a₀ + a₁ μ_p` fitted to y = μ_y − μ_y.dark between
/// 5 % and 95 % of the saturation signal, minimising the relative deviations
/// `Σ ((y − a₀ − a₁ μ_p) / y)²`; the deviation `δ = 100 (y − fit) / fit` % and
/// `LE = (max δ − min δ) / 2` over the range.
pub fn linearity(points: &[TemporalPoint], sat: usize) -> Option<Linearity> {
    let lo = first_at_or_above(points, sat, 0.05)?;
    let hi = last_at_or_below(points, sat, 0.95)?;
    if hi < lo + 1 {
        return None;
    }
    // Weighted normal equations with weights w = 1/y².
    let (mut s, mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in &points[lo..=hi] {
        let y = p.signal_dn();
        let x = p.photons_per_pixel;
        let w = 1.0 / (y * y);
        s += w;
        sx += w * x;
        sxx += w * x * x;
        sy += w * y;
        sxy += w * x * y;
    }
    let det = s * sxx - sx * sx;
    let a1 = (s * sxy - sx * sy) / det;
    let a0 = (sy - a1 * sx) / s;
    let dev: Vec<f64> = points
        .iter()
        .map(|p| {
            let f = a0 + a1 * p.photons_per_pixel;
            100.0 * (p.signal_dn() - f) / f
        })
        .collect();
    let in_range = &dev[lo..=hi];
    let mn = in_range.iter().copied().fold(f64::INFINITY, f64::min);
    let mx = in_range.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some(Linearity {
        slope_dn_per_photon: a1,
        offset_dn: a0,
        deviation_percent: dev,
        range: (lo, hi),
        le_min_percent: mn,
        le_max_percent: mx,
        le_percent: 0.5 * (mx - mn),
    })
}

/// Dark current from the mean (e⁻/s): slope of μ_y.dark against exposure time divided by K
/// (Rel. 4.0 §7, "dark current from the mean"). Needs more than two exposure times.
pub fn dark_current_from_mean(points: &[TemporalPoint], k: &LineFit) -> Option<Measured> {
    (distinct_exposures(points) > 2).then(|| {
        let f = dark_fit(points, |p| p.dark.mean_dn);
        let v = f.slope / k.slope;
        Measured::new(
            v,
            v.abs() * ((f.slope_se / f.slope).powi(2) + (k.slope_se / k.slope).powi(2)).sqrt(),
        )
    })
}

/// Dark current from the variance (e⁻/s): slope of σ²_y.dark against exposure time divided
/// by K² (Rel. 4.0 §7, "dark current from the variance": the dark electrons are Poisson, so
/// their variance grows like their mean). None with two or fewer exposure times or a
/// negative slope.
pub fn dark_current_from_variance(points: &[TemporalPoint], k: &LineFit) -> Option<Measured> {
    if distinct_exposures(points) <= 2 {
        return None;
    }
    let f = dark_fit(points, |p| p.dark.var_dn2);
    (f.slope >= 0.0).then(|| {
        let v = f.slope / (k.slope * k.slope);
        Measured::new(
            v,
            v * ((f.slope_se / f.slope).powi(2) + (2.0 * k.slope_se / k.slope).powi(2)).sqrt(),
        )
    })
}

/// The temporal (photon-transfer) part of the datasheet.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TemporalResult {
    /// Index of the saturation point.
    pub saturation_index: usize,
    /// Last index of the K and R fits (70 % of saturation).
    pub fit_end_index: usize,
    /// Responsivity R (DN/photon).
    pub responsivity_dn_per_photon: LineFit,
    /// Overall system gain K (DN/e⁻).
    pub system_gain_dn_per_e: LineFit,
    /// Quantum efficiency η (fraction, not %).
    pub quantum_efficiency: Measured,
    /// σ²_y.dark (DN²).
    pub dark_var_dn2: Measured,
    /// Temporal dark noise σ_d (e⁻).
    pub dark_noise_e: Measured,
    /// Absolute sensitivity threshold μ_p.min (photons).
    pub sensitivity_threshold_photons: Measured,
    /// μ_e.min = η μ_p.min (e⁻).
    pub sensitivity_threshold_e: Measured,
    /// Saturation capacity μ_p.sat (photons).
    pub saturation_photons: Measured,
    /// Saturation capacity μ_e.sat = η μ_p.sat (e⁻).
    pub saturation_e: Measured,
    /// SNR_max = √μ_e.sat.
    pub snr_max: Measured,
    /// Dynamic range μ_p.sat / μ_p.min.
    pub dynamic_range: Measured,
    /// Linearity (None if fewer than two points lie between 5 % and 95 % of saturation).
    pub linearity: Option<Linearity>,
    /// Dark current from the mean (e⁻/s).
    pub dark_current_mean_e_per_s: Option<Measured>,
    /// Dark current from the variance (e⁻/s).
    pub dark_current_var_e_per_s: Option<Measured>,
}

/// Why a series cannot be analysed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Emva1288Error {
    /// Too few points or no usable fit range.
    #[error("EMVA 1288 analysis: {0}")]
    Series(String),
}

/// The temporal part of the datasheet from the photon-transfer points (sorted here by
/// exposure time, then photon count, as the standard's series is ordered).
pub fn analyse_temporal(points: &[TemporalPoint]) -> Result<TemporalResult, Emva1288Error> {
    if points.len() < 3 {
        return Err(Emva1288Error::Series(format!(
            "{} bright points; at least 3 are needed (the standard asks for 50)",
            points.len()
        )));
    }
    if let Some(p) = points
        .iter()
        .find(|p| !(p.bright.mean_dn.is_finite() && p.dark.mean_dn.is_finite()))
    {
        return Err(Emva1288Error::Series(format!(
            "the point at {} s, {} photons has frames of different sizes",
            p.exposure_s, p.photons_per_pixel
        )));
    }
    let mut pts = points.to_vec();
    pts.sort_by(|a, b| {
        a.exposure_s
            .total_cmp(&b.exposure_s)
            .then(a.photons_per_pixel.total_cmp(&b.photons_per_pixel))
    });
    let sat = saturation_index(&pts);
    let fit_end = last_at_or_below(&pts, sat, 0.7)
        .filter(|&i| i >= 1)
        .ok_or_else(|| {
            Emva1288Error::Series(format!(
                "fewer than two points below 70 % of saturation (saturation at point {sat})"
            ))
        })?;
    let r = responsivity(&pts, fit_end);
    let k = system_gain(&pts, fit_end);
    let eta = quantum_efficiency(&r, &k);
    let dark_var = dark_variance(&pts);
    let sigma_d = dark_noise_electrons(&dark_var, &k);
    let up_min = sensitivity_threshold_photons(&dark_var, &k, &eta);
    let up_sat = saturation_capacity(&pts, sat);
    let ue_sat = scale(&up_sat, &eta);
    Ok(TemporalResult {
        saturation_index: sat,
        fit_end_index: fit_end,
        responsivity_dn_per_photon: r,
        system_gain_dn_per_e: k,
        quantum_efficiency: eta,
        dark_var_dn2: dark_var,
        dark_noise_e: sigma_d,
        sensitivity_threshold_photons: up_min,
        sensitivity_threshold_e: scale(&up_min, &eta),
        saturation_photons: up_sat,
        snr_max: snr_max(&ue_sat),
        saturation_e: ue_sat,
        dynamic_range: dynamic_range(&up_sat, &up_min),
        linearity: linearity(&pts, sat),
        dark_current_mean_e_per_s: dark_current_from_mean(&pts, &k),
        dark_current_var_e_per_s: dark_current_from_variance(&pts, &k),
    })
}

/// A photon count turned into electrons, μ_e = η μ_p (Rel. 4.0 §2, camera model).
fn scale(photons: &Measured, eta: &Measured) -> Measured {
    let v = photons.value * eta.value;
    let rel = ((photons.uncertainty / photons.value).powi(2)
        + (eta.uncertainty / eta.value).powi(2))
    .sqrt();
    Measured::new(v, v * rel)
}

#[cfg(test)]
mod tests;
