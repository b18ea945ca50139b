//! Appendix B on charts: channel spectral efficiencies from `patches` shots whose patches
//! have known spectral radiance (e.g. a ColorChecker lit through narrowband filters, each
//! filter photographed at several exposures).
//!
//! Per exposure series (shots with the same target), patch and channel: the mean DN of the
//! patch's pixels (label image, eroded, or the spec's patch rectangle shrunk to its central
//! 80 %) at each unclipped exposure; a weighted straight line `DN = P + b·G·t` through them
//! and the pedestal P (a prior point at zero exposure with its uncertainty) gives the signal
//! rate `b`. With the spec's forward model (steps 2–7) `b = k·(g·e + V_d)`, k = DN per volt,
//! so the photo-electron rate is `e = (b/k − V_d)/g = p²·FF·π/(4N²)·R̄·∫ QE(λ) T(λ) L(λ) dλ`
//! (R̄: the camera's relative illumination averaged over the patch). These rows go to
//! [`camsim_diagnose::fit_spectral_efficiency`], cross-validated by leaving out one series
//! (one filter) at a time.
use crate::raw_input::PatchLabels;
use camsim_core::{RawFrame, Spectrum, WavelengthGrid};
use camsim_diagnose::{
    fit_spectral_efficiency, CalibrationResult, Outcome, SpectralFit, SpectralObservation,
};
use camsim_optics::{
    relative_illumination_cos4, relative_illumination_isetcam, OpticsModel, RelativeIllumination,
};
use camsim_sensor::SensorModel;
use serde::Serialize;
use std::sync::Arc;

/// Label regions are eroded by this many pixels (blur, lateral colour, label misregistration).
pub const LABEL_EROSION_PX: usize = 3;
/// Without labels, the central fraction (per side) of the spec's patch rectangle is used.
pub const GRID_PATCH_CORE: f64 = 0.8;
/// A point is censored when more than this fraction of its pixels read 0 DN.
pub const MAX_ZERO_FRACTION: f64 = 0.01;
/// A point is saturated when any pixel reaches this fraction of the clipping level.
pub const SATURATION_FRACTION: f64 = 0.98;
/// Radiance below this fraction of its peak is its "floor" (a filter's blocking band).
pub const FLOOR_FRACTION: f64 = 0.01;
/// Observations whose predicted signal comes more than this share from the floor are left out.
pub const MAX_FLOOR_SHARE: f64 = 0.5;
/// Patch illumination factors need this many exposure series (filters).
pub const MIN_SERIES_FOR_GAINS: usize = 3;
/// After this many alternations the set of floor-dominated observations may only shrink (it
/// can otherwise cycle between two states).
pub const LEAK_FREEZE_ITERATIONS: usize = 10;
/// Alternation stops when no factor changes by more than this.
pub const GAIN_TOLERANCE: f64 = 1e-4;
/// At most this many alternations.
pub const MAX_GAIN_ITERATIONS: usize = 30;
/// Uncertainty of the believed pedestal when no dark shots estimate it (DN).
pub const BELIEVED_PEDESTAL_SIGMA_DN: f64 = 0.5;

/// A `patches` shot as loaded for the fit.
#[derive(Debug, Clone)]
pub struct PatchShot {
    /// Shot id.
    pub id: String,
    /// Shots with equal keys (the target as written) form one exposure series.
    pub series_key: String,
    /// Exposure time (s).
    pub exposure_s: f64,
    /// Analog gain.
    pub analog_gain: f64,
    /// Frames.
    pub frames: Vec<RawFrame>,
    /// Chart rows.
    pub chart_rows: usize,
    /// Chart columns.
    pub chart_cols: usize,
    /// Patch side as a fraction of the cell side.
    pub patch_fraction: f64,
    /// Patch radiances (photons / (s · sr · m² · nm)), row-major.
    pub patches: Vec<Spectrum>,
    /// Label image, when the target has one.
    pub labels: Option<Arc<PatchLabels>>,
}

/// One exposure of one patch in one channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchPoint {
    /// Shot id.
    pub shot: String,
    /// Exposure × analog gain (s).
    pub gain_exposure_s: f64,
    /// Mean DN over the patch's pixels of this channel (all frames).
    pub mean_dn: f64,
    /// Its standard error: √(pixel variance / n + 1/12) (the 1/12 DN² covers the
    /// quantisation of a mean over strongly correlated pixels).
    pub sigma_dn: f64,
    /// Pixels × frames.
    pub n: usize,
    /// Used in the line fit, or why not.
    pub used: bool,
    /// "censored at 0 DN" / "saturated" / "too few pixels" when not used.
    pub reason: Option<String>,
}

/// The line through one patch/channel exposure series.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchSeriesFit {
    /// Series name.
    pub series: String,
    /// Patch number (1-based, row-major).
    pub patch: usize,
    /// Channel name.
    pub channel: String,
    /// Slope (DN per second at unit gain).
    pub slope_dn_per_s: f64,
    /// Its standard error (inflated by √(χ²/dof) when above 1).
    pub slope_sigma_dn_per_s: f64,
    /// Intercept (DN).
    pub intercept_dn: f64,
    /// Its standard error.
    pub intercept_sigma_dn: f64,
    /// Exposures used.
    pub n_points: usize,
    /// χ²/dof of the line (the pedestal prior counts as a point); None with one exposure.
    pub chi2_per_dof: Option<f64>,
    /// Mean relative illumination over the patch (the camera's model).
    pub relative_illumination: f64,
    /// Every exposure.
    pub points: Vec<PatchPoint>,
}

/// The illumination factor of one patch.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchGain {
    /// Patch number (1-based, row-major).
    pub patch: usize,
    /// Irradiance on the patch relative to the chart mean (wavelength independent).
    pub factor: f64,
    /// Its 1σ.
    pub sigma: f64,
}

/// What the chart fit found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchSpectral {
    /// The curves and every observation against them (predictions include the patch
    /// illumination factors), or why not.
    pub fit: Outcome<SpectralFit>,
    /// Per-patch illumination factors I_p (mean 1), fitted jointly with the curves by
    /// alternating least squares: a chart lit unevenly (a projector, a lamp to one side)
    /// scales every wavelength of a patch alike. None when not estimable.
    pub patch_illumination: Option<Vec<PatchGain>>,
    /// Curve fits run (alternations).
    pub gain_iterations: usize,
    /// Relative scatter ε of the patch signal rates beyond their measurement noise (the
    /// model error: radiance errors, filter leakage, non-uniform light), estimated so that
    /// χ² = N − (fitted factors); every observation's σ in `fit` is σ_measured ⊕ ε·signal.
    /// 0 when the measurement noise explains the residuals.
    pub model_error_fraction: f64,
    /// Observations left out because their predicted signal comes mostly from the
    /// radiance's floor (below [`FLOOR_FRACTION`] of its peak): with narrowband filters, the
    /// blocking band, whose measured transmittance is the spectrometer's noise floor.
    pub leak_dominated: Vec<String>,
    /// Pedestal used as the prior intercept (DN) and its uncertainty.
    pub pedestal_dn: f64,
    /// Its uncertainty (DN).
    pub pedestal_sigma_dn: f64,
    /// Where the pedestal came from.
    pub pedestal_source: String,
    /// Median intercept of the lines with ≥ 3 exposures (DN): the black level the chart
    /// series themselves imply.
    pub median_intercept_dn: Option<f64>,
    /// The series: name and shot ids.
    pub series: Vec<(String, Vec<String>)>,
    /// Every patch/channel line.
    pub lines: Vec<PatchSeriesFit>,
    /// Notes (series or patches left out and why).
    pub notes: Vec<String>,
}

/// Pixel indices (row-major) of each patch.
pub fn patch_regions(shot: &PatchShot, rows: usize, cols: usize) -> Vec<Vec<usize>> {
    let n = shot.chart_rows * shot.chart_cols;
    let mut out = vec![Vec::new(); n];
    match &shot.labels {
        Some(l) => {
            let e = LABEL_EROSION_PX as i64;
            for r in 0..rows {
                for c in 0..cols {
                    let v = l.label[r * cols + c];
                    if v == 0 {
                        continue;
                    }
                    // keep the pixel when its (2e+1)² neighbourhood carries the same label
                    let inside = (-e..=e).all(|dr| {
                        (-e..=e).all(|dc| {
                            let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                            rr >= 0
                                && cc >= 0
                                && (rr as usize) < rows
                                && (cc as usize) < cols
                                && l.label[rr as usize * cols + cc as usize] == v
                        })
                    });
                    if inside {
                        out[v as usize - 1].push(r * cols + c);
                    }
                }
            }
        }
        None => {
            // spec geometry: cell (i, j) spans [j·W/cols, (j+1)·W/cols) × [i·H/rows, …);
            // its patch is the centred rectangle of side patch_fraction of the cell.
            let f = shot.patch_fraction * GRID_PATCH_CORE;
            let (cw, chh) = (
                cols as f64 / shot.chart_cols as f64,
                rows as f64 / shot.chart_rows as f64,
            );
            for i in 0..shot.chart_rows {
                for j in 0..shot.chart_cols {
                    let (xc, yc) = ((j as f64 + 0.5) * cw, (i as f64 + 0.5) * chh);
                    let (hw, hh) = (0.5 * f * cw, 0.5 * f * chh);
                    let k = i * shot.chart_cols + j;
                    for r in 0..rows {
                        let y = r as f64 + 0.5;
                        if (y - yc).abs() >= hh {
                            continue;
                        }
                        for c in 0..cols {
                            let x = c as f64 + 0.5;
                            if (x - xc).abs() < hw {
                                out[k].push(r * cols + c);
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// The camera's relative illumination at a pixel (the camera equation's R(x)).
fn relative_illumination(optics: &OpticsModel, s: &SensorModel, r: usize, c: usize) -> f64 {
    let p = s.pixel_pitch_m;
    let y = (r as f64 - (s.rows as f64 - 1.0) / 2.0) * p;
    let x = (c as f64 - (s.cols as f64 - 1.0) / 2.0) * p;
    match optics.relative_illumination {
        RelativeIllumination::None => 1.0,
        RelativeIllumination::Cos4 => relative_illumination_cos4(x.hypot(y), optics.focal_length_m),
        _ => {
            let diag = p * ((s.rows * s.rows + s.cols * s.cols) as f64).sqrt();
            relative_illumination_isetcam(x, y, optics.focal_length_m, optics.f_number, 0.0, diag)
        }
    }
}

/// The part of a sampled spectrum below [`FLOOR_FRACTION`] of its peak (0 elsewhere);
/// None when there is none.
fn floor_part(l: &Spectrum) -> Option<Spectrum> {
    let Spectrum::Sampled {
        wavelength_nm,
        values,
    } = l
    else {
        return None;
    };
    let peak = values.iter().cloned().fold(0.0f64, f64::max);
    let v: Vec<f64> = values
        .iter()
        .map(|&x| if x < FLOOR_FRACTION * peak { x } else { 0.0 })
        .collect();
    v.iter()
        .any(|&x| x > 0.0)
        .then(|| Spectrum::sampled(wavelength_nm.clone(), v).ok())
        .flatten()
}

/// Weighted straight line y = a + b·x; returns (a, b, σa, σb, χ²).
fn weighted_line(pts: &[(f64, f64, f64)]) -> (f64, f64, f64, f64, f64) {
    let (mut s, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y, sg) in pts {
        let w = 1.0 / (sg * sg);
        s += w;
        sx += w * x;
        sy += w * y;
        sxx += w * x * x;
        sxy += w * x * y;
    }
    let det = s * sxx - sx * sx;
    let a = (sxx * sy - sx * sxy) / det;
    let b = (s * sxy - sx * sy) / det;
    let chi2 = pts
        .iter()
        .map(|&(x, y, sg)| ((y - a - b * x) / sg).powi(2))
        .sum();
    (a, b, (sxx / det).sqrt(), (s / det).sqrt(), chi2)
}

/// A readable name for a series: the shots' common id prefix without trailing separators.
fn series_name(ids: &[&str]) -> String {
    let first = ids[0];
    if ids.len() == 1 {
        return first.to_string();
    }
    let mut n = first.len();
    for id in &ids[1..] {
        n = n.min(
            first
                .char_indices()
                .zip(id.chars())
                .take_while(|((_, a), b)| a == b)
                .map(|((i, a), _)| i + a.len_utf8())
                .last()
                .unwrap_or(0),
        );
    }
    let p = first[..n].trim_end_matches(['-', '_', ' ', '.']);
    if p.is_empty() {
        first.to_string()
    } else {
        p.to_string()
    }
}

/// The wavelength grid of the chart fit: the calibration grid extended by one step at each
/// end (light in the outer half-steps is then modelled rather than cut off).
pub fn chart_grid(grid: &WavelengthGrid) -> WavelengthGrid {
    match grid.step_nm() {
        Some(st) if grid.wavelength_nm[0] - st > 0.0 => WavelengthGrid::regular(
            grid.wavelength_nm[0] - st,
            grid.wavelength_nm[grid.len() - 1] + st,
            st,
        )
        .unwrap_or_else(|_| grid.clone()),
        _ => grid.clone(),
    }
}

/// Run the chart fit on the `patches` shots of a capture set.
pub fn patch_spectral(
    shots: &[PatchShot],
    sensor: &SensorModel,
    optics: &OpticsModel,
    result: &CalibrationResult,
    grid: &WavelengthGrid,
) -> PatchSpectral {
    let k = sensor.dn_per_output_v();
    let (pedestal, ped_sigma, pedestal_source) = match result.black_level_dn.get() {
        Some(e) => (
            e.value,
            e.std_error.max(1e-6),
            "estimated from the dark shots".to_string(),
        ),
        None => (
            sensor.black_level_dn + sensor.analog_offset_v * k,
            BELIEVED_PEDESTAL_SIGMA_DN,
            format!(
                "believed camera (black level not estimable from this set), ±{BELIEVED_PEDESTAL_SIGMA_DN} DN"
            ),
        ),
    };
    let g = result
        .conversion_gain_v_per_e
        .value()
        .unwrap_or(sensor.conversion_gain_v_per_e);
    let vd = result
        .dark_voltage_v_per_s
        .value()
        .unwrap_or(sensor.dark_voltage_v_per_s);
    let hot: std::collections::HashSet<usize> = result
        .hot_pixels
        .get()
        .map(|h| h.pixels.iter().map(|p| p.0 * sensor.cols + p.1).collect())
        .unwrap_or_default();
    let mut notes = Vec::new();
    // series in file order
    let mut keys: Vec<&str> = Vec::new();
    for s in shots {
        if !keys.contains(&s.series_key.as_str()) {
            keys.push(&s.series_key);
        }
    }
    let (rows, cols) = (sensor.rows, sensor.cols);
    // p² · FF times the camera equation (Eq. 1, object at infinity).
    let area_kappa = sensor.pixel_pitch_m.powi(2)
        * sensor.fill_factor
        * camsim_optics::camera_equation_factor(optics.f_number, 0.0);
    let mut series_list = Vec::new();
    let mut lines = Vec::new();
    let mut obs = Vec::new();
    let mut obs_patch = Vec::new();
    for key in keys {
        let members: Vec<&PatchShot> = shots.iter().filter(|s| s.series_key == key).collect();
        let ids: Vec<&str> = members.iter().map(|s| s.id.as_str()).collect();
        let name = series_name(&ids);
        series_list.push((name.clone(), ids.iter().map(|s| s.to_string()).collect()));
        let bad: Vec<&str> = members
            .iter()
            .filter(|s| {
                s.frames
                    .iter()
                    .any(|f| f.rows != rows || f.cols != cols || f.dn.len() != rows * cols)
            })
            .map(|s| s.id.as_str())
            .collect();
        if !bad.is_empty() {
            notes.push(format!(
                "series {name}: left out, frames of shots {} are not {rows}×{cols}",
                bad.join(", ")
            ));
            continue;
        }
        let first = members[0];
        let regions = patch_regions(first, rows, cols);
        for (p, region) in regions.iter().enumerate() {
            if region.is_empty() {
                notes.push(format!(
                    "series {name}: patch {} has no pixels after erosion",
                    p + 1
                ));
                continue;
            }
            let radiance = match &optics.transmittance {
                Spectrum::Affine {
                    offset,
                    slope_per_nm,
                } if *slope_per_nm == 0.0 && *offset == 1.0 => first.patches[p].clone(),
                t => Spectrum::multiply(&first.patches[p], t),
            };
            for (c, cname) in sensor.channel_names.iter().enumerate() {
                let px: Vec<usize> = region
                    .iter()
                    .copied()
                    .filter(|&i| {
                        sensor.cfa.channel_at(i / cols, i % cols) == c && !hot.contains(&i)
                    })
                    .collect();
                if px.len() < 2 {
                    continue;
                }
                let ri = px
                    .iter()
                    .map(|&i| relative_illumination(optics, sensor, i / cols, i % cols))
                    .sum::<f64>()
                    / px.len() as f64;
                let mut points = Vec::new();
                let mut fit_pts = vec![(0.0, pedestal, ped_sigma)];
                for s in &members {
                    let (mut sum, mut sum2, mut n, mut zeros, mut mx) =
                        (0.0, 0.0, 0usize, 0usize, 0u16);
                    for f in &s.frames {
                        for &i in &px {
                            let v = f.dn[i];
                            sum += v as f64;
                            sum2 += (v as f64) * (v as f64);
                            n += 1;
                            zeros += (v == 0) as usize;
                            mx = mx.max(v);
                        }
                    }
                    let m = sum / n as f64;
                    let var = ((sum2 - n as f64 * m * m) / (n as f64 - 1.0)).max(0.0);
                    let sigma = (var / n as f64 + 1.0 / 12.0).sqrt();
                    let gt = s.analog_gain * s.exposure_s;
                    // clipping level: the ADC maximum or the believed full well
                    let clip = sensor
                        .max_dn()
                        .min(pedestal + s.analog_gain * k * g * sensor.well_capacity_e);
                    let reason = if n < 4 {
                        Some("too few pixels")
                    } else if (zeros as f64) > MAX_ZERO_FRACTION * n as f64 {
                        Some("censored at 0 DN")
                    } else if mx as f64 >= SATURATION_FRACTION * clip {
                        Some("saturated")
                    } else {
                        None
                    };
                    if reason.is_none() {
                        fit_pts.push((gt, m, sigma));
                    }
                    points.push(PatchPoint {
                        shot: s.id.clone(),
                        gain_exposure_s: gt,
                        mean_dn: m,
                        sigma_dn: sigma,
                        n,
                        used: reason.is_none(),
                        reason: reason.map(str::to_string),
                    });
                }
                let n_pts = fit_pts.len() - 1;
                if n_pts == 0 {
                    lines.push(PatchSeriesFit {
                        series: name.clone(),
                        patch: p + 1,
                        channel: cname.clone(),
                        slope_dn_per_s: f64::NAN,
                        slope_sigma_dn_per_s: f64::NAN,
                        intercept_dn: f64::NAN,
                        intercept_sigma_dn: f64::NAN,
                        n_points: 0,
                        chi2_per_dof: None,
                        relative_illumination: ri,
                        points,
                    });
                    continue;
                }
                let (a, b, sa, sb, chi2) = weighted_line(&fit_pts);
                let dof = fit_pts.len() as f64 - 2.0;
                let chi2_per_dof = (dof >= 1.0).then(|| chi2 / dof);
                let inflate = chi2_per_dof.unwrap_or(1.0).max(1.0).sqrt();
                let (sa, sb) = (sa * inflate, sb * inflate);
                lines.push(PatchSeriesFit {
                    series: name.clone(),
                    patch: p + 1,
                    channel: cname.clone(),
                    slope_dn_per_s: b,
                    slope_sigma_dn_per_s: sb,
                    intercept_dn: a,
                    intercept_sigma_dn: sa,
                    n_points: n_pts,
                    chi2_per_dof,
                    relative_illumination: ri,
                    points,
                });
                obs_patch.push(p);
                obs.push(SpectralObservation {
                    id: format!("{name}/patch {}/{cname}", p + 1),
                    group: name.clone(),
                    channel: c,
                    radiance: radiance.clone(),
                    scale: area_kappa * ri,
                    signal: (b / k - vd) / g,
                    sigma: sb / (k * g),
                });
            }
        }
    }
    let mut icpt: Vec<f64> = lines
        .iter()
        .filter(|l| l.n_points >= 3)
        .map(|l| l.intercept_dn)
        .collect();
    icpt.sort_by(f64::total_cmp);
    let median_intercept_dn = (!icpt.is_empty()).then(|| icpt[icpt.len() / 2]);
    let unused = lines.iter().filter(|l| l.n_points == 0).count();
    if unused > 0 {
        notes.push(format!(
            "{unused} patch/channel series have no unclipped exposure (all censored at 0 DN or saturated) and give no observation"
        ));
    }
    // Per-patch illumination factors: estimable when every series images the same chart
    // layout and there are ≥ MIN_SERIES_FOR_GAINS series (each patch then has observations
    // at several wavelengths, and a wavelength-independent factor is separable from the
    // curves).
    let n_patches = shots
        .first()
        .map(|s| s.chart_rows * s.chart_cols)
        .unwrap_or(0);
    let same_layout = shots.iter().all(|s| {
        s.chart_rows * s.chart_cols == n_patches
            && match (&s.labels, &shots[0].labels) {
                (None, None) => {
                    s.chart_rows == shots[0].chart_rows
                        && s.patch_fraction == shots[0].patch_fraction
                }
                (Some(a), Some(b)) => Arc::ptr_eq(a, b) || a == b,
                _ => false,
            }
    });
    let n_series = series_list.len();
    let estimate_gains = same_layout && n_series >= MIN_SERIES_FOR_GAINS;
    if !estimate_gains && !shots.is_empty() {
        notes.push(format!(
            "patch illumination factors not estimated ({}): every patch is taken to be lit as the radiance says",
            if same_layout {
                format!("{n_series} series; needs ≥ {MIN_SERIES_FOR_GAINS}")
            } else {
                "the series image different chart layouts".to_string()
            }
        ));
    }
    let method = "Appendix B on chart patches: per series, patch and channel the slope b of mean \
         DN against analog gain × exposure (weighted line through the unclipped exposures and \
         the pedestal), electrons/s = (b/k − V_d)/g = I_p·p²·FF·π/(4N²)·R̄·∫QE·T·L";
    let grid = chart_grid(grid);
    let mut gains = vec![1.0; n_patches];
    let mut gain_sigma = vec![f64::NAN; n_patches];
    let mut eps = 0.0f64;
    let mut iterations = 0;
    // the part of each radiance below FLOOR_FRACTION of its peak (a filter's blocking band)
    let floor_parts: Vec<Option<Spectrum>> = obs.iter().map(|o| floor_part(&o.radiance)).collect();
    let mut leak = vec![false; obs.len()];
    let mut leak_dominated = Vec::new();
    // the observations as the solver sees them: scale × I_p, σ ⊕ ε·signal
    let scaled = |gains: &[f64], eps: f64, leak: &[bool]| -> Vec<SpectralObservation> {
        obs.iter()
            .zip(&obs_patch)
            .zip(leak)
            .filter(|(_, &l)| !l)
            .map(|((o, &p), _)| SpectralObservation {
                scale: o.scale * gains[p],
                sigma: o.sigma.hypot(eps * o.signal),
                ..o.clone()
            })
            .collect()
    };
    let fit = loop {
        if shots.is_empty() {
            break Outcome::NotEstimable {
                reason: "chart spectral efficiency: the set has no `patches` shots".into(),
            };
        }
        iterations += 1;
        let fit = fit_spectral_efficiency(
            &scaled(&gains, eps, &leak),
            &grid,
            &sensor.channel_names,
            method,
        );
        let Some(f) = fit.get() else { break fit };
        // u_i: the prediction of observation i at unit illumination factor
        let curves: Vec<Option<Spectrum>> = (0..sensor.channel_names.len())
            .map(|c| {
                f.qe.channels
                    .iter()
                    .find(|q| q.name == sensor.channel_names[c])
                    .and_then(|q| Spectrum::sampled(f.qe.wavelength_nm.clone(), q.qe.clone()).ok())
            })
            .collect();
        let units: Vec<Option<f64>> = obs
            .iter()
            .map(|o| {
                curves[o.channel]
                    .as_ref()
                    .map(|q| o.scale * Spectrum::integrate_product(q, &o.radiance).unwrap_or(0.0))
            })
            .collect();
        // observations whose predicted signal comes mostly from the floor part
        // After LEAK_FREEZE_ITERATIONS the set can only shrink (intersection with the last
        // one: an observation is left out only while every later fit agrees), so it cannot
        // cycle and the alternation of illumination factors and model error converges.
        let frozen = iterations > LEAK_FREEZE_ITERATIONS;
        let new_leak: Vec<bool> = obs
            .iter()
            .enumerate()
            .map(
                |(i, o)| match (&curves[o.channel], &floor_parts[i], units[i]) {
                    (Some(q), Some(fl), Some(u)) if u > 0.0 => {
                        o.scale * Spectrum::integrate_product(q, fl).unwrap_or(0.0)
                            > MAX_FLOOR_SHARE * u
                    }
                    _ => false,
                },
            )
            .zip(&leak)
            .map(|(l, &was)| if frozen { l && was } else { l })
            .collect();
        let units: Vec<Option<f64>> = units
            .into_iter()
            .zip(&new_leak)
            .map(|(u, &l)| if l { None } else { u })
            .collect();
        let sig = |i: usize, e: f64| obs[i].sigma.hypot(e * obs[i].signal);
        // I_p = Σ w s u / Σ w u² over the patch's observations (weighted least squares)
        let mut new = gains.clone();
        if estimate_gains {
            let mut num = vec![0.0; n_patches];
            let mut den = vec![0.0; n_patches];
            for (i, o) in obs.iter().enumerate() {
                let Some(u) = units[i] else { continue };
                let w = sig(i, eps).powi(-2);
                num[obs_patch[i]] += w * o.signal * u;
                den[obs_patch[i]] += w * u * u;
            }
            for p in 0..n_patches {
                new[p] = if den[p] > 0.0 { num[p] / den[p] } else { 1.0 };
            }
            let mean = new.iter().sum::<f64>() / n_patches as f64;
            new.iter_mut().for_each(|g| *g /= mean);
            for p in 0..n_patches {
                gain_sigma[p] = 1.0 / den[p].sqrt() / mean;
            }
        }
        // ε: the relative scatter beyond the measurement noise, from
        // Σ r²/(σ² + ε² s²) = N − (illumination factors fitted)   (0 when χ² ≤ that already)
        let n_used = units.iter().filter(|u| u.is_some()).count();
        let target = (n_used as f64
            - if estimate_gains {
                n_patches as f64
            } else {
                0.0
            })
        .max(1.0);
        let chi2 = |e: f64| -> f64 {
            obs.iter()
                .enumerate()
                .filter_map(|(i, o)| {
                    units[i].map(|u| ((o.signal - new[obs_patch[i]] * u) / sig(i, e)).powi(2))
                })
                .sum()
        };
        let new_eps = if chi2(0.0) <= target {
            0.0
        } else {
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            while chi2(hi) > target && hi < 1e3 {
                hi *= 2.0;
            }
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if chi2(mid) > target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            hi
        };
        let mut change = new
            .iter()
            .zip(&gains)
            .fold((new_eps - eps).abs(), |a, (x, y)| a.max((x - y).abs()));
        if new_leak != leak {
            change = f64::INFINITY;
        }
        gains = new;
        eps = new_eps;
        leak = new_leak;
        if change < GAIN_TOLERANCE || iterations >= MAX_GAIN_ITERATIONS {
            if change >= GAIN_TOLERANCE {
                notes.push(format!(
                    "illumination factors / model error: not converged after {iterations} iterations (last change {change:.1e})"
                ));
            }
            let n_leak = leak.iter().filter(|&&l| l).count();
            if n_leak > 0 {
                notes.push(format!(
                    "{n_leak} observations left out of the fit: more than {:.0} % of their predicted signal comes from wavelengths where the radiance is below {:.0} % of its peak (a filter's blocking band, where a spectrometer measures its own floor, not the blocking)",
                    100.0 * MAX_FLOOR_SHARE,
                    100.0 * FLOOR_FRACTION
                ));
            }
            leak_dominated = obs
                .iter()
                .zip(&leak)
                .filter(|(_, &l)| l)
                .map(|(o, _)| o.id.clone())
                .collect();
            break fit_spectral_efficiency(
                &scaled(&gains, eps, &leak),
                &grid,
                &sensor.channel_names,
                method,
            );
        }
    };
    let patch_illumination = estimate_gains.then(|| {
        gains
            .iter()
            .zip(&gain_sigma)
            .enumerate()
            .map(|(p, (g, s))| PatchGain {
                patch: p + 1,
                factor: *g,
                sigma: *s,
            })
            .collect()
    });
    PatchSpectral {
        fit,
        patch_illumination,
        gain_iterations: iterations,
        model_error_fraction: eps,
        leak_dominated,
        pedestal_dn: pedestal,
        pedestal_sigma_dn: ped_sigma,
        pedestal_source,
        median_intercept_dn,
        series: series_list,
        lines,
        notes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weighted_line_matches_closed_form_and_series_names() {
        // exact line, equal weights: y = 2 + 3x
        let pts: Vec<(f64, f64, f64)> = (0..5)
            .map(|i| (i as f64, 2.0 + 3.0 * i as f64, 0.5))
            .collect();
        let (a, b, sa, sb, chi2) = weighted_line(&pts);
        assert!((a - 2.0).abs() < 1e-12 && (b - 3.0).abs() < 1e-12 && chi2 < 1e-20);
        // σ_b = σ/√Σ(x − x̄)² = 0.5/√10, σ_a = σ·√(Σx²/(nΣ(x − x̄)²)) = 0.5·√(30/50)
        assert!((sb - 0.5 / 10f64.sqrt()).abs() < 1e-12);
        assert!((sa - 0.5 * (30.0f64 / 50.0).sqrt()).abs() < 1e-12);
        assert_eq!(series_name(&["cc-550nm-25ms", "cc-550nm-50ms"]), "cc-550nm");
        assert_eq!(series_name(&["a", "b"]), "a");
        assert_eq!(series_name(&["only"]), "only");
    }

    #[test]
    fn grid_regions_follow_the_spec_geometry_and_labels_erode() {
        let shot = PatchShot {
            id: "x".into(),
            series_key: "k".into(),
            exposure_s: 1.0,
            analog_gain: 1.0,
            frames: vec![],
            chart_rows: 2,
            chart_cols: 2,
            patch_fraction: 0.5,
            patches: vec![Spectrum::constant(1.0); 4],
            labels: None,
        };
        // 20×20 sensor, 10×10 cells, patch 5×5 centred, core 4×4 → pixels 3..7 of each cell
        let r = patch_regions(&shot, 20, 20);
        assert!(
            r.iter().all(|p| p.len() == 16),
            "{:?}",
            r.iter().map(|p| p.len()).collect::<Vec<_>>()
        );
        assert!(r[0].contains(&(3 * 20 + 3)) && !r[0].contains(&(2 * 20 + 3)));
        assert!(r[3].contains(&(16 * 20 + 16)) && !r[3].contains(&(17 * 20 + 16)));
        // a 12×12 labelled square eroded by 3 leaves 6×6
        let mut label = vec![0u16; 400];
        for rr in 4..16 {
            for cc in 4..16 {
                label[rr * 20 + cc] = 2;
            }
        }
        let l = PatchShot {
            labels: Some(Arc::new(PatchLabels {
                rows: 20,
                cols: 20,
                label,
            })),
            ..shot
        };
        let r = patch_regions(&l, 20, 20);
        assert_eq!(r[1].len(), 36);
        assert!(r[0].is_empty() && r[2].is_empty());
    }
}
