//! Honest colour accuracy for `camsim run` (docs/isp.md): the colour matrix is fitted on a
//! *calibration capture* — the same camera's noise-free responses to the Macbeth chart under a
//! calibration illuminant (default D65) — and applied to the scene, which is scored held-out.
//! The fitted ΔE (the calibration capture through its own matrix) is reported beside it.
//!
//! Chain for both captures: per-channel white balance (the chosen method, evaluated on each
//! capture itself) → the 3 × K matrix → exposure normalisation: one scalar that brings the
//! brightest chart patch's luminance to the target white (`white_level`), so that a global
//! exposure difference between the captures is not counted as colour error → 8-bit sRGB
//! coding → ΔE2000 against the chart's D65 sRGB targets.
use crate::color_eval::{patch_delta_e, srgb_to_xyz, through_srgb8, PatchDeltaE};
use crate::error::CliError;
use camsim_core::Spectrum;
use camsim_isp::{
    fit_channel_matrix, illuminant_channel_gains, macbeth_channel_responses, reference_channel,
    ChannelMatrix, ChannelPlanes,
};

/// The white-balance rules of `processor.white_balance`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WbMethod {
    /// No gains.
    None,
    /// Grey world.
    GreyWorld,
    /// White patch (max per channel).
    WhitePatch,
    /// Gains from the capture's illuminant and the channel QEs.
    KnownIlluminant,
}

impl WbMethod {
    /// Every method, in report order.
    pub const ALL: [WbMethod; 4] = [
        WbMethod::None,
        WbMethod::GreyWorld,
        WbMethod::WhitePatch,
        WbMethod::KnownIlluminant,
    ];
    /// Configuration name.
    pub fn name(&self) -> &'static str {
        match self {
            WbMethod::None => "none",
            WbMethod::GreyWorld => "grey_world",
            WbMethod::WhitePatch => "white_patch",
            WbMethod::KnownIlluminant => "known_illuminant",
        }
    }
    /// Parse a configuration name.
    pub fn parse(s: &str) -> Option<Self> {
        WbMethod::ALL.into_iter().find(|m| m.name() == s)
    }
}

/// A capture as the colour evaluation needs it: channel statistics, not pixels.
#[derive(Debug, Clone)]
pub struct CaptureStats {
    /// Mean of each channel over the whole capture (grey world).
    pub channel_mean: Vec<f64>,
    /// Maximum of each channel over the capture (white patch).
    pub channel_max: Vec<f64>,
    /// Mean channel values of the 24 chart patches (row-major).
    pub patches: Vec<Vec<f64>>,
    /// The capture's illuminant (photons), for the known-illuminant gains.
    pub illuminant_photons: Spectrum,
}

impl CaptureStats {
    /// Statistics of demosaicked planes with the chart's patch means.
    pub fn of_planes(
        p: &ChannelPlanes,
        patches: Vec<Vec<f64>>,
        illuminant_photons: Spectrum,
    ) -> Self {
        let n = (p.rows * p.cols).max(1) as f64;
        CaptureStats {
            channel_mean: p
                .planes
                .iter()
                .map(|v| v.iter().map(|&x| x as f64).sum::<f64>() / n)
                .collect(),
            channel_max: p
                .planes
                .iter()
                .map(|v| {
                    v.iter()
                        .map(|&x| x as f64)
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect(),
            patches,
            illuminant_photons,
        }
    }

    /// The noise-free calibration capture: the chart's channel responses under `illuminant`,
    /// scaled so the largest value is 0.9 (an auto-exposed capture); grey world and white
    /// patch see only the 24 patches.
    pub fn calibration(
        channel_qe: &[Spectrum],
        illuminant_photons: &Spectrum,
    ) -> Result<Self, CliError> {
        let mut v = macbeth_channel_responses(channel_qe, illuminant_photons)
            .map_err(|e| CliError::Other(format!("calibration capture: {e}")))?;
        let mx = v.iter().flatten().cloned().fold(0.0, f64::max);
        if !(mx > 0.0) {
            return Err(CliError::Other(
                "calibration capture: the camera sees nothing of the chart".into(),
            ));
        }
        for p in v.iter_mut() {
            p.iter_mut().for_each(|x| *x *= 0.9 / mx);
        }
        let k = channel_qe.len();
        let channel_mean = (0..k)
            .map(|c| v.iter().map(|p| p[c]).sum::<f64>() / v.len() as f64)
            .collect();
        let channel_max = (0..k)
            .map(|c| v.iter().map(|p| p[c]).fold(0.0, f64::max))
            .collect();
        Ok(CaptureStats {
            channel_mean,
            channel_max,
            patches: v,
            illuminant_photons: illuminant_photons.clone(),
        })
    }
}

/// Gains of `method` for a capture (reference channel = 1).
pub fn gains(
    method: WbMethod,
    c: &CaptureStats,
    qe: &[Spectrum],
    names: &[String],
) -> Result<Vec<f64>, CliError> {
    let r = reference_channel(names);
    let from = |s: &[f64], what: &str| -> Result<Vec<f64>, CliError> {
        if let Some(k) = (0..s.len()).find(|&k| !(s[k] > 0.0 && s[k].is_finite())) {
            return Err(CliError::Other(format!(
                "white balance {}: channel '{}' has {what} {} (must be positive)",
                method.name(),
                names[k],
                s[k]
            )));
        }
        Ok(s.iter().map(|x| s[r] / x).collect())
    };
    match method {
        WbMethod::None => Ok(vec![1.0; names.len()]),
        WbMethod::GreyWorld => from(&c.channel_mean, "mean"),
        WbMethod::WhitePatch => from(&c.channel_max, "maximum"),
        WbMethod::KnownIlluminant => illuminant_channel_gains(qe, names, &c.illuminant_photons)
            .map_err(|e| CliError::Other(format!("white balance: {e}"))),
    }
}

/// The exposure scalar that brings the brightest rendered patch's Y to `white_level`.
pub fn exposure_scale(rendered_patches: &[[f64; 3]], white_level: f64) -> f64 {
    let y = rendered_patches
        .iter()
        .map(|p| srgb_to_xyz(*p)[1])
        .fold(0.0, f64::max);
    if y > 0.0 {
        white_level / y
    } else {
        1.0
    }
}

/// Render the chart patches of a capture: gains, matrix, exposure normalisation, 8-bit coding.
pub fn render_patches(
    c: &CaptureStats,
    g: &[f64],
    m: &ChannelMatrix,
    white_level: f64,
) -> (Vec<[f64; 3]>, f64) {
    let lin: Vec<[f64; 3]> = c
        .patches
        .iter()
        .map(|p| {
            let wb: Vec<f64> = p.iter().zip(g).map(|(a, b)| a * b).collect();
            m.apply(&wb)
        })
        .collect();
    let k = exposure_scale(&lin, white_level);
    (
        lin.iter()
            .map(|v| through_srgb8(v.map(|x| x * k)))
            .collect(),
        k,
    )
}

/// The matrix fitted on the calibration capture (white-balanced by `method`), its gains there,
/// and the fitted (calibration) ΔE.
pub struct Calibrated {
    /// The 3 × K matrix.
    pub matrix: ChannelMatrix,
    /// White-balance gains on the calibration capture.
    pub calibration_gains: Vec<f64>,
    /// ΔE of the calibration capture through its own matrix (the fitted ΔE).
    pub fitted: PatchDeltaE,
}

/// Fit the matrix on the calibration capture (least squares to `targets`).
pub fn calibrate(
    method: WbMethod,
    cal: &CaptureStats,
    qe: &[Spectrum],
    names: &[String],
    targets: &[[f64; 3]],
    white_level: f64,
) -> Result<Calibrated, CliError> {
    let g = gains(method, cal, qe, names)?;
    let samples: Vec<Vec<f64>> = cal
        .patches
        .iter()
        .map(|p| p.iter().zip(&g).map(|(a, b)| a * b).collect())
        .collect();
    let matrix = fit_channel_matrix(&samples, targets)
        .map_err(|e| CliError::Other(format!("colour correction: {e}")))?;
    let (rendered, _) = render_patches(cal, &g, &matrix, white_level);
    let fitted = patch_delta_e(targets, &rendered)?;
    Ok(Calibrated {
        matrix,
        calibration_gains: g,
        fitted,
    })
}

/// One row of the white-balance comparison of the report.
#[derive(Debug, Clone)]
pub struct WbRow {
    /// Method.
    pub method: WbMethod,
    /// Gains on the scored capture.
    pub gains: Vec<f64>,
    /// Mean ΔE2000 of the calibration capture (fitted).
    pub fitted_mean: f64,
    /// Mean ΔE2000 of the scored capture (held out).
    pub held_out_mean: f64,
    /// Max ΔE2000 of the scored capture.
    pub held_out_max: f64,
}

/// Score every white-balance method: each fits its own matrix on the calibration capture and
/// is applied to the scored capture.
pub fn compare_white_balance(
    cal: &CaptureStats,
    scored: &CaptureStats,
    qe: &[Spectrum],
    names: &[String],
    targets: &[[f64; 3]],
    white_level: f64,
) -> Result<Vec<WbRow>, CliError> {
    WbMethod::ALL
        .iter()
        .map(|&m| {
            let c = calibrate(m, cal, qe, names, targets, white_level)?;
            let g = gains(m, scored, qe, names)?;
            let (rendered, _) = render_patches(scored, &g, &c.matrix, white_level);
            let de = patch_delta_e(targets, &rendered)?;
            Ok(WbRow {
                method: m,
                gains: g,
                fitted_mean: c.fitted.stats2000.mean,
                held_out_mean: de.stats2000.mean,
                held_out_max: de.stats2000.max,
            })
        })
        .collect()
}
