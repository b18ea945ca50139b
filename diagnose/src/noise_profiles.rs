//! Real noise recordings: darktable's per-camera noise profiles (`noiseprofiles.json`, GPL-3.0
//! data of the darktable project, read in place, never copied) read as photon-transfer fits,
//! and what a shot-plus-read-noise sensor model implies from each.
//!
//! Each profile gives, per ISO and per CFA channel, a Poisson–Gaussian fit
//! `var = a · mean + b` with the signal normalised to [0, 1] of the raw range (black → 0,
//! white → 1). For a sensor whose only noises are photon/dark shot noise and signal-independent
//! read noise (EMVA 1288 photon-transfer model; Janesick, *Photon Transfer*, 2007, ch. 3)
//! with `N` electrons at full scale and read noise `σ_r` electrons:
//!
//! * mean `x = n_e / N`, so `var_x = n_e / N² + σ_r² / N² = x / N + σ_r² / N²`;
//! * hence `a = 1 / N` (electrons at full scale `N = 1 / a`, conversion gain `N / (white −
//!   black)` e⁻/DN when the raw range is known) and `b = σ_r² / N²`
//!   (read noise `σ_r = √b / a` electrons, engineering dynamic range `N / σ_r = 1 / √b`).
//!
//! In that model `a > 0` and `b ≥ 0`. A fit with `b < 0` cannot come from it: the variance near
//! black is *smaller* than the shot-noise line allows. Physics that produces it:
//! * black-level clipping — raw values below the black level are cut at 0 (or stored
//!   unsigned after black subtraction), truncating the lower half of the noise distribution
//!   and shrinking the variance of dark patches;
//! * a black level (offset) mis-estimate — if the black subtracted is too low by `δ` (fraction
//!   of full scale) the measured mean is shifted by `+δ` and the fitted intercept becomes
//!   `b − a·δ`; it turns negative once `δ > b / a`, so `b < 0` needs an offset error of at least
//!   `−b / a` of full scale (`−b / a²` electrons);
//! * noise reduction or lossy raw compression inside the camera's raw pipeline, which lowers
//!   the variance of low signals more than of high ones.
//!
//! `a ≤ 0` (variance not growing with signal) is also flagged. darktable measures the
//! profiles on its own pipeline's buffer, after white-balance pre-gains and demosaicking, so
//! `N` and `σ_r` here are *apparent* values of that buffer (per-channel pre-gain `k` scales
//! `a` by `k`; averaging neighbours in demosaicking lowers the variance) — relative trends over
//! ISO and between channels are what they measure reliably (docs/diagnose_real.md).
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A problem with a noise-profile file.
#[derive(Debug, thiserror::Error)]
pub enum NoiseProfileError {
    /// The file cannot be read.
    #[error("{path}: cannot read: {msg}")]
    Read {
        /// the file
        path: String,
        /// why
        msg: String,
    },
    /// The JSON does not have darktable's layout.
    #[error("{path}: {msg}")]
    Format {
        /// the file
        path: String,
        /// what is wrong, with the JSON location
        msg: String,
    },
}

/// One noise profile: a camera at one ISO.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseProfile {
    /// Maker, as in the file.
    pub maker: String,
    /// Model, as in the file.
    pub model: String,
    /// ISO speed.
    pub iso: f64,
    /// Shot-noise slope per CFA channel (R, G, B), normalised units.
    pub a: [f64; 3],
    /// Zero-signal variance per channel (R, G, B), normalised units².
    pub b: [f64; 3],
    /// darktable's `skip` flag (profile not offered to users).
    pub skip: bool,
}

#[derive(Deserialize)]
struct FileRaw {
    noiseprofiles: Vec<MakerRaw>,
}
#[derive(Deserialize)]
struct MakerRaw {
    maker: String,
    models: Vec<ModelRaw>,
}
#[derive(Deserialize)]
struct ModelRaw {
    model: String,
    profiles: Vec<ProfileRaw>,
}
#[derive(Deserialize)]
struct ProfileRaw {
    iso: f64,
    a: Vec<f64>,
    b: Vec<f64>,
    #[serde(default)]
    skip: bool,
}

/// Read every profile of a darktable `noiseprofiles.json`.
pub fn read_noise_profiles(path: &Path) -> Result<Vec<NoiseProfile>, NoiseProfileError> {
    let p = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| NoiseProfileError::Read {
        path: p.clone(),
        msg: e.to_string(),
    })?;
    let raw: FileRaw = serde_json::from_str(&text).map_err(|e| NoiseProfileError::Format {
        path: p.clone(),
        msg: format!(
            "not a darktable noise-profile file (expected {{\"noiseprofiles\": [{{\"maker\", \"models\": [{{\"model\", \"profiles\": [{{\"iso\", \"a\": [3], \"b\": [3]}}]}}]}}]}}): {e}"
        ),
    })?;
    let mut out = Vec::new();
    for (i, m) in raw.noiseprofiles.into_iter().enumerate() {
        for (j, mo) in m.models.into_iter().enumerate() {
            for (k, pr) in mo.profiles.into_iter().enumerate() {
                let at = format!("noiseprofiles[{i}].models[{j}].profiles[{k}]");
                let three = |v: &[f64], key: &str| -> Result<[f64; 3], NoiseProfileError> {
                    match v {
                        [r, g, b] if v.iter().all(|x| x.is_finite()) => Ok([*r, *g, *b]),
                        _ => Err(NoiseProfileError::Format {
                            path: p.clone(),
                            msg: format!(
                                "{at}.{key}: expected 3 finite numbers (R, G, B), got {v:?}"
                            ),
                        }),
                    }
                };
                if !(pr.iso.is_finite() && pr.iso > 0.0) {
                    return Err(NoiseProfileError::Format {
                        path: p.clone(),
                        msg: format!("{at}.iso: expected a positive number, got {}", pr.iso),
                    });
                }
                out.push(NoiseProfile {
                    maker: m.maker.clone(),
                    model: mo.model.clone(),
                    iso: pr.iso,
                    a: three(&pr.a, "a")?,
                    b: three(&pr.b, "b")?,
                    skip: pr.skip,
                });
            }
        }
    }
    Ok(out)
}

/// Why a channel's fit cannot come from a shot-plus-read-noise sensor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Impossibility {
    /// `b < 0`: negative read-noise variance.
    NegativeReadVariance {
        /// The fitted `b`.
        b: f64,
        /// Smallest black-offset error that turns a non-negative read variance into this `b`:
        /// `−b / a`, fraction of full scale.
        min_offset_error_fraction: f64,
        /// The same in electrons, `−b / a²`.
        min_offset_error_e: f64,
    },
    /// `a ≤ 0`: variance not growing with the signal (no shot noise).
    NonPositiveShotSlope {
        /// The fitted `a`.
        a: f64,
    },
}

impl Impossibility {
    /// The physics that can produce it, one sentence.
    pub fn explanation(&self) -> &'static str {
        match self {
            Impossibility::NegativeReadVariance { .. } => {
                "negative read-noise variance: the variance near black is below the shot-noise line; produced by black-level clipping (raw values below black cut at 0 truncate the noise floor), a black-level (offset) mis-estimate shifting the means, or noise reduction / lossy compression in the raw pipeline"
            }
            Impossibility::NonPositiveShotSlope { .. } => {
                "variance does not grow with signal: no photon shot noise, so the data are not linear raw (tone curve, heavy noise reduction) or the fit failed"
            }
        }
    }
}

/// What the shot-plus-read model implies for one channel of one profile.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelImplication {
    /// "R", "G" or "B".
    pub channel: &'static str,
    /// Fitted slope.
    pub a: f64,
    /// Fitted intercept.
    pub b: f64,
    /// Electrons at full scale `1 / a` (apparent; `None` when `a ≤ 0`).
    pub full_scale_e: Option<f64>,
    /// Read noise `√b / a` electrons (`None` when `b < 0` or `a ≤ 0`).
    pub read_noise_e: Option<f64>,
    /// Engineering dynamic range `1 / √b` (`None` when `b ≤ 0`).
    pub dynamic_range: Option<f64>,
    /// Why the fit is impossible for the model, if it is.
    pub impossible: Option<Impossibility>,
}

/// One profile read through the model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProfileImplication {
    /// Maker.
    pub maker: String,
    /// Model.
    pub model: String,
    /// ISO.
    pub iso: f64,
    /// R, G, B.
    pub channels: [ChannelImplication; 3],
}

impl ProfileImplication {
    /// Whether any channel is impossible for a shot-plus-read sensor.
    pub fn any_impossible(&self) -> bool {
        self.channels.iter().any(|c| c.impossible.is_some())
    }
}

/// Read one profile through the shot-plus-read model (module documentation).
pub fn implication(p: &NoiseProfile) -> ProfileImplication {
    let ch = |k: usize| {
        let (a, b) = (p.a[k], p.b[k]);
        let impossible = if a <= 0.0 {
            Some(Impossibility::NonPositiveShotSlope { a })
        } else if b < 0.0 {
            Some(Impossibility::NegativeReadVariance {
                b,
                min_offset_error_fraction: -b / a,
                min_offset_error_e: -b / (a * a),
            })
        } else {
            None
        };
        ChannelImplication {
            channel: ["R", "G", "B"][k],
            a,
            b,
            full_scale_e: (a > 0.0).then(|| 1.0 / a),
            read_noise_e: (a > 0.0 && b >= 0.0).then(|| b.sqrt() / a),
            dynamic_range: (b > 0.0).then(|| 1.0 / b.sqrt()),
            impossible,
        }
    };
    ProfileImplication {
        maker: p.maker.clone(),
        model: p.model.clone(),
        iso: p.iso,
        channels: [ch(0), ch(1), ch(2)],
    }
}

/// Counts over a whole file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProfileCensus {
    /// Distinct makers.
    pub makers: usize,
    /// Distinct (maker, model) pairs.
    pub models: usize,
    /// Profiles (camera × ISO).
    pub profiles: usize,
    /// Profiles with `b < 0` in at least one channel.
    pub negative_b_profiles: usize,
    /// Channel fits with `b < 0`.
    pub negative_b_channels: usize,
    /// Channel fits with `a ≤ 0`.
    pub nonpositive_a_channels: usize,
    /// Models with `b < 0` at some ISO.
    pub models_with_negative_b: usize,
}

/// Count makers, models, profiles and impossible fits.
pub fn census(profiles: &[NoiseProfile]) -> ProfileCensus {
    use std::collections::BTreeSet;
    let makers: BTreeSet<&str> = profiles.iter().map(|p| p.maker.as_str()).collect();
    let models: BTreeSet<(&str, &str)> = profiles
        .iter()
        .map(|p| (p.maker.as_str(), p.model.as_str()))
        .collect();
    let neg = |p: &&NoiseProfile| p.b.iter().any(|&b| b < 0.0);
    let bad_models: BTreeSet<(&str, &str)> = profiles
        .iter()
        .filter(neg)
        .map(|p| (p.maker.as_str(), p.model.as_str()))
        .collect();
    ProfileCensus {
        makers: makers.len(),
        models: models.len(),
        profiles: profiles.len(),
        negative_b_profiles: profiles.iter().filter(neg).count(),
        negative_b_channels: profiles
            .iter()
            .map(|p| p.b.iter().filter(|&&b| b < 0.0).count())
            .sum(),
        nonpositive_a_channels: profiles
            .iter()
            .map(|p| p.a.iter().filter(|&&a| a <= 0.0).count())
            .sum(),
        models_with_negative_b: bad_models.len(),
    }
}

/// Profiles of one camera (model name matched case-insensitively, exact or as
/// "maker model"), sorted by ISO.
pub fn camera<'a>(profiles: &'a [NoiseProfile], name: &str) -> Vec<&'a NoiseProfile> {
    let n = name.trim().to_ascii_lowercase();
    let mut v: Vec<&NoiseProfile> = profiles
        .iter()
        .filter(|p| {
            p.model.to_ascii_lowercase() == n
                || format!("{} {}", p.maker, p.model).to_ascii_lowercase() == n
        })
        .collect();
    v.sort_by(|a, b| a.iso.total_cmp(&b.iso));
    v
}
