//! `camsim demo diagnose`: capture sets in which an effect of effects.md is present but
//! concealed, with the truth (design per effect id in docs/effects.md).
//!
//! A set is a folder with the **believed** camera (`camera.json`, without the effects),
//! `captures.json`, 16-bit PNG frames simulated with the **true** camera (the believed one plus
//! the effects, in their generator forms: two-circle vignetting, pillbox defocus, asymmetric
//! crosstalk, tanh nonlinearity, division distortion, Cauchy lateral colour, lognormal hot
//! pixels, NIR leakage spectra) and `truth.json` (`{"effects": [{"effect", "magnitude"}]}`,
//! magnitudes in effects.md units computed from the true blocks with the crates' magnitude
//! functions). Deterministic in the seed.
use crate::chain::{shot_electron_rate, wavelength_grid};
use crate::config::{load_camera, load_captures, CameraFile};
use crate::error::CliError;
use crate::simulate::{simulate, SimulateOptions};
use camsim_core::image::SpectralImage;
use camsim_core::spectrum::WavelengthGrid;
use camsim_optics::{two_circle_overlap_fraction, Defocus};
use camsim_sensor::{fixed_pattern, hot_pixel_count, nonlinearity_magnitude, Nonlinearity};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Every effect id of effects.md, in its table's order.
pub const EFFECT_IDS: [&str; 23] = [
    "exposure_scale",
    "conversion_gain",
    "black_level",
    "dark_current",
    "read_noise",
    "dsnu",
    "prnu",
    "column_fpn",
    "hot_pixels",
    "nonlinearity",
    "full_well",
    "relative_illumination",
    "veiling_glare",
    "defocus",
    "crosstalk",
    "ir_leakage",
    "qe_shift",
    "distortion",
    "lateral_color",
    "row_noise",
    "rtn",
    "black_level_drift",
    "dark_temperature",
];

/// How an effect is hidden in the capture set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Concealment {
    /// The default capture set (darks, photon-transfer flats, two charts, edge, points).
    None,
    /// The magnitude is meant to be too small for any single frame to show; the set holds
    /// 2–4× more repeats so that it is detectable statistically.
    BelowNoise,
    /// No flat field: only darks, charts at two levels, a slanted edge, a point grid, a ramp.
    UnderScene,
    /// The set is built around the effect's look-alike (e.g. conversion_gain with an
    /// exposure series whose means alone look like exposure_scale); the evidence that tells
    /// them apart (repeats, darks, illuminants, edges) is present.
    Mimicked,
    /// Darks and six flats up to 85 % of full scale under one illuminant (3200 K), nothing
    /// else: a spectral change of a channel (QE shift, IR leakage, crosstalk) looks like a
    /// change of that channel's gain, so the set cannot tell them apart.
    OneIlluminant,
    /// [`Concealment::OneIlluminant`] plus the same flats under a second illuminant (a
    /// 6500 K blackbody), which separates a spectral change from a gain.
    TwoIlluminants,
    /// The dark and photon-transfer flat series of [`Concealment::None`] and three chart
    /// shots (D65 at 35 % and 70 % of full scale, illuminant A at 70 %), nothing else: the
    /// set of the 12 MP scale benchmark (issue 23, bench/diagnose_12mp.sh).
    Charts,
}

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoSpec {
    /// (effect id, magnitude in effects.md units); empty = a null set.
    pub effects: Vec<(String, f64)>,
    /// How the effects are concealed.
    pub concealment: Concealment,
    /// Sensor rows.
    pub rows: usize,
    /// Sensor columns.
    pub cols: usize,
    /// Seed of every random term (frames and fixed patterns).
    pub seed: u64,
}

/// One effect of the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct TrueEffect {
    /// Effect id.
    pub effect: String,
    /// Magnitude (effects.md units) of the generated effect.
    pub magnitude: f64,
}

/// What [`generate_capture_set`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoTruth {
    /// The effects and their true magnitudes (also in DIR/truth.json).
    pub effects: Vec<TrueEffect>,
    /// DIR/captures.json.
    pub captures_json: PathBuf,
}

/// `camsim demo …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum DemoCommand {
    /// Write a capture set with concealed effects for `camsim diagnose`, and its truth.
    Diagnose {
        /// An effect and its magnitude in effects.md units, `ID=MAGNITUDE` (repeatable; none:
        /// a null set whose frames are the believed camera's).
        #[arg(long = "effect", value_name = "ID=MAGNITUDE")]
        effects: Vec<String>,
        /// How the effect is concealed.
        #[arg(long, value_enum, default_value = "none")]
        conceal: Concealment,
        /// Sensor rows.
        #[arg(long, default_value_t = 96)]
        rows: usize,
        /// Sensor columns.
        #[arg(long, default_value_t = 128)]
        cols: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
}

/// Run a `camsim demo` subcommand.
pub fn run_demo(cmd: DemoCommand) -> Result<(), CliError> {
    match cmd {
        DemoCommand::Diagnose {
            effects,
            conceal,
            rows,
            cols,
            seed,
            out,
        } => {
            let mut list = Vec::new();
            for e in &effects {
                let (id, m) = e.split_once('=').ok_or_else(|| {
                    CliError::Other(format!(
                        "--effect {e}: expected ID=MAGNITUDE (e.g. crosstalk=0.04)"
                    ))
                })?;
                let m: f64 = m.trim().parse().map_err(|_| {
                    CliError::Other(format!("--effect {e}: magnitude \"{m}\" is not a number"))
                })?;
                list.push((id.trim().to_string(), m));
            }
            let spec = DemoSpec {
                effects: list,
                concealment: conceal,
                rows,
                cols,
                seed,
            };
            let truth = generate_capture_set(&spec, &out)?;
            for t in &truth.effects {
                eprintln!("camsim: {} = {}", t.effect, t.magnitude);
            }
            eprintln!(
                "camsim: wrote {} (diagnose it with `camsim diagnose {}`)",
                out.display(),
                truth.captures_json.display()
            );
            Ok(())
        }
    }
}

// ---------------------------------------------------------------------------------------
// The believed camera and the scenes

/// Pixel pitch of the demo camera (µm).
const PITCH_UM: f64 = 2.2;

/// A sampled spectrum `{"wavelength_nm", "values"}` of `f` on `lo..=hi` every `step` nm.
fn sampled(lo: f64, hi: f64, step: f64, f: impl Fn(f64) -> f64) -> Value {
    let n = ((hi - lo) / step).round() as usize;
    let w: Vec<f64> = (0..=n).map(|i| lo + step * i as f64).collect();
    let v: Vec<f64> = w.iter().map(|&l| f(l)).collect();
    json!({"wavelength_nm": w, "values": v})
}

/// Combined QE of a Bayer channel: a Gaussian band (peak, width, height) times an IR-cut
/// filter falling linearly from 1 at 650 nm to 0 at 700 nm, on 380–700 nm.
fn bayer_qe(peak_nm: f64, sigma_nm: f64, height: f64, floor: f64) -> Value {
    sampled(380.0, 700.0, 10.0, |l| {
        let cut = ((700.0 - l) / 50.0).clamp(0.0, 1.0);
        (height * (-0.5 * ((l - peak_nm) / sigma_nm).powi(2)).exp() + floor) * cut
    })
}

/// Relative Planck spectrum (peak-normalised) at `kelvin` on 380–1100 nm (W units).
fn blackbody(kelvin: f64) -> Value {
    let c2 = 1.438_776_877e-2; // m·K
    let f = |l: f64| {
        let m = l * 1e-9;
        1.0 / (m.powi(5) * ((c2 / (m * kelvin)).exp() - 1.0))
    };
    let peak = (380..=1100).map(|l| f(l as f64)).fold(0.0, f64::max);
    sampled(380.0, 1100.0, 10.0, |l| f(l) / peak)
}

/// The believed camera: a small Bayer CMOS sensor behind an f/2.8 lens with a Gaussian blur
/// (σ 1.2 µm) and cos⁴ fall-off; 12-bit ADC, full well 10 000 e⁻ = the 1 V swing.
pub fn believed_camera(rows: usize, cols: usize) -> CameraFile {
    let v = json!({
        "name": "demo-believed",
        "optics": {"f_number": 2.8, "focal_length_mm": 4.0, "transmittance": 1.0,
                   "relative_illumination": "cos4", "blur": {"kind": "gaussian", "sigma_um": 1.2}},
        "sensor": {
            "rows": rows, "cols": cols, "pixel_pitch_um": PITCH_UM, "fill_factor": 0.5,
            "cfa": ["gb", "rg"],
            "channels": {"r": bayer_qe(605.0, 35.0, 0.40, 0.01),
                         "g": bayer_qe(535.0, 38.0, 0.48, 0.01),
                         "b": bayer_qe(460.0, 30.0, 0.42, 0.01)},
            "well_capacity_e": 10000.0, "conversion_gain_v_per_e": 1.0e-4,
            "voltage_swing_v": 1.0, "analog_gain": 1.0, "analog_offset_v": 0.0,
            "adc_bits": 12, "black_level_dn": 64.0,
            "dark_voltage_v_per_s": 5.0e-3, "read_noise_v": 1.0e-3,
            "dsnu_sigma_v": 1.0e-3, "prnu_sigma_percent": 0.8
        }
    });
    serde_json::from_value(v).expect("the demo camera is valid")
}

/// One planned shot: its target, how bright (fraction of full scale at the brightest
/// expected pixel, or a fixed exposure for darks) and how many frames.
#[derive(Debug, Clone)]
struct Plan {
    id: String,
    target: Value,
    level: Level,
    repeats: usize,
    /// Sensor temperature of the shot (°C, captures.json `temperature_c`).
    temperature_c: Option<f64>,
}

#[derive(Debug, Clone, Copy)]
enum Level {
    Exposure(f64),
    FullScale(f64),
}

fn pct(f: f64) -> String {
    format!("{:02}", (f * 100.0).round() as i64)
}

fn darks(exposures: &[f64], repeats: usize) -> Vec<Plan> {
    exposures
        .iter()
        .map(|&t| Plan {
            id: format!("dark-{}ms", (t * 1000.0).round() as i64),
            target: json!({"kind": "dark"}),
            level: Level::Exposure(t),
            repeats,
            temperature_c: None,
        })
        .collect()
}

/// Darks at `exposures` at every sensor temperature of `temperatures_c` (ids
/// `dark-{ms}ms-{T}c`).
fn darks_at_temperatures(exposures: &[f64], temperatures_c: &[f64], repeats: usize) -> Vec<Plan> {
    let mut out = Vec::new();
    for &t in temperatures_c {
        for mut p in darks(exposures, repeats) {
            p.id = format!("{}-{}c", p.id, t.round() as i64);
            p.temperature_c = Some(t);
            out.push(p);
        }
    }
    out
}

/// Sensor temperatures of the dark-temperature series (°C): their mean is the true camera's
/// operating temperature [`DEMO_TEMPERATURE_C`], where the believed dark current holds.
const DARK_TEMPERATURES_C: [f64; 4] = [10.0, 20.0, 30.0, 40.0];
/// The true camera's operating temperature (°C) with `dark_temperature`.
const DEMO_TEMPERATURE_C: f64 = 25.0;

fn flats(levels: &[f64], repeats: usize) -> Vec<Plan> {
    levels
        .iter()
        .map(|&f| Plan {
            id: format!("flat-{}", pct(f)),
            target: json!({"kind": "uniform", "radiance": blackbody(3200.0),
                           "mean_luminance_cd_m2": 200.0}),
            level: Level::FullScale(f),
            repeats,
            temperature_c: None,
        })
        .collect()
}

/// Flats under a blackbody of `kelvin` (ids `flat-{kelvin}k-{level}`).
fn flats_at(kelvin: f64, levels: &[f64], repeats: usize) -> Vec<Plan> {
    levels
        .iter()
        .map(|&f| Plan {
            id: format!("flat-{}k-{}", kelvin.round() as i64, pct(f)),
            target: json!({"kind": "uniform", "radiance": blackbody(kelvin),
                           "mean_luminance_cd_m2": 200.0}),
            level: Level::FullScale(f),
            repeats,
            temperature_c: None,
        })
        .collect()
}

fn charts(levels: &[f64], repeats: usize) -> Vec<Plan> {
    let mut out = Vec::new();
    for (name, ill) in [("d65", json!("D65")), ("a", blackbody(2856.0))] {
        for &f in levels {
            out.push(Plan {
                id: format!("chart-{name}-{}", pct(f)),
                target: json!({"kind": "macbeth", "illuminant": ill, "patch_fraction": 0.7,
                               "mean_luminance_cd_m2": 100.0}),
                level: Level::FullScale(f),
                repeats,
                temperature_c: None,
            });
        }
    }
    out
}

fn scaled(s: &Value, k: f64) -> Value {
    let v: Vec<f64> = s["values"]
        .as_array()
        .map(|a| a.iter().map(|x| x.as_f64().unwrap_or(0.0) * k).collect())
        .unwrap_or_default();
    json!({"wavelength_nm": s["wavelength_nm"], "values": v})
}

fn edge(level: f64, repeats: usize) -> Vec<Plan> {
    let bb = blackbody(4000.0);
    vec![Plan {
        id: "edge".into(),
        target: json!({"kind": "slanted_edge", "dark": scaled(&bb, 0.1), "light": bb,
                       "angle_deg": 5.0, "mean_luminance_cd_m2": 100.0}),
        level: Level::FullScale(level),
        repeats,
        temperature_c: None,
    }]
}

fn points(level: f64, repeats: usize) -> Vec<Plan> {
    let bb = blackbody(4000.0);
    vec![Plan {
        id: "points".into(),
        target: json!({"kind": "point_array", "radiance": bb, "background": scaled(&bb, 0.02),
                       "spacing_px": 12, "point_size_px": 2}),
        level: Level::FullScale(level),
        repeats,
        temperature_c: None,
    }]
}

fn ramp(level: f64, repeats: usize) -> Vec<Plan> {
    vec![Plan {
        id: "ramp".into(),
        target: json!({"kind": "ramp", "radiance": blackbody(3200.0), "min": 0.05, "max": 1.0}),
        level: Level::FullScale(level),
        repeats,
        temperature_c: None,
    }]
}

/// A scene whose own radiance falls off radially like vignetting (the look-alike of
/// relative_illumination), written as a spectral EXR `scenes/radial.exr`.
fn radial_scene(dir: &Path, rows: usize, cols: usize) -> Result<Plan, CliError> {
    let grid = WavelengthGrid::regular(380.0, 1100.0, 10.0).expect("grid");
    let bb = blackbody(3200.0);
    let spectrum: Vec<f64> = bb["values"]
        .as_array()
        .expect("values")
        .iter()
        .map(|v| v.as_f64().unwrap_or(0.0))
        .collect();
    let (r, c) = (rows / 2, cols / 2);
    let (yc, xc) = ((r as f64 - 1.0) / 2.0, (c as f64 - 1.0) / 2.0);
    let hd = xc.hypot(yc);
    let weight: Vec<f32> = (0..r * c)
        .map(|i| {
            let h = ((i % c) as f64 - xc).hypot((i / c) as f64 - yc) / hd;
            (1.0 - 0.35 * h * h) as f32
        })
        .collect();
    let planes = spectrum
        .iter()
        .map(|s| weight.iter().map(|w| w * *s as f32 * 0.01).collect())
        .collect();
    let img = SpectralImage::new(r, c, camsim_core::image::SpectralBasis::Bands(grid), planes)
        .map_err(|e| CliError::Other(e.to_string()))?;
    let rel = Path::new("scenes/radial.exr");
    std::fs::create_dir_all(dir.join("scenes")).map_err(|e| CliError::output(dir, e))?;
    camsim_core::exr_io::write_spectral_exr(&dir.join(rel), &img, "W.m^-2.sr^-1.nm^-1", None)
        .map_err(|e| CliError::output(&dir.join(rel), e))?;
    Ok(Plan {
        id: "radial-scene".into(),
        target: json!({"kind": "image", "file": "scenes/radial.exr"}),
        level: Level::FullScale(0.7),
        repeats: 2,
        temperature_c: None,
    })
}

const DARK_T: [f64; 3] = [0.01, 0.25, 1.0];
const PTC: [f64; 6] = [0.05, 0.15, 0.3, 0.5, 0.7, 0.9];
/// Flat levels of the one- and two-illuminant sets (up to 85 % of full scale).
const FLATS_85: [f64; 6] = [0.05, 0.2, 0.35, 0.5, 0.7, 0.85];

/// The shots of a set (docs/effects.md, "Concealed-effect capture sets").
fn plan_shots(spec: &DemoSpec, dir: &Path) -> Result<Vec<Plan>, CliError> {
    let base = |k: usize| -> Vec<Plan> {
        let mut p = darks(&DARK_T, 3 * k);
        p.extend(flats(&PTC, 2 * k));
        p.extend(charts(&[0.7], k));
        p.extend(edge(0.7, k));
        p.extend(points(0.7, k));
        p
    };
    let mut plans = match spec.concealment {
        Concealment::None => base(1),
        Concealment::BelowNoise => {
            let mut p = darks(&DARK_T, 8);
            p.extend(flats(&PTC, 6));
            p.extend(charts(&[0.7], 4));
            p.extend(edge(0.7, 4));
            p.extend(points(0.7, 4));
            p
        }
        Concealment::UnderScene => {
            let mut p = darks(&DARK_T, 3);
            p.extend(charts(&[0.35, 0.7], 2));
            p.extend(edge(0.7, 2));
            p.extend(points(0.7, 2));
            p.extend(ramp(0.9, 2));
            p
        }
        Concealment::OneIlluminant => {
            let mut p = darks(&DARK_T, 4);
            p.extend(flats(&FLATS_85, 4));
            p
        }
        Concealment::Charts => {
            let mut p = darks(&DARK_T, 3);
            p.extend(flats(&PTC, 2));
            // D65 at 35 % and 70 %, A at 70 % (charts() pairs each level with both).
            p.extend(
                charts(&[0.35, 0.7], 1)
                    .into_iter()
                    .filter(|c| c.id != "chart-a-35"),
            );
            p
        }
        Concealment::TwoIlluminants => {
            let mut p = darks(&DARK_T, 4);
            p.extend(flats(&FLATS_85, 4));
            p.extend(flats_at(6500.0, &FLATS_85, 4));
            p
        }
        Concealment::Mimicked => {
            let mut p: Vec<Plan> = Vec::new();
            for (id, _) in &spec.effects {
                p.extend(match id.as_str() {
                    // Means scale alike; repeats give the photon-transfer slope.
                    "exposure_scale" | "conversion_gain" => {
                        let mut v = flats(&PTC, 4);
                        v.extend(darks(&DARK_T, 2));
                        v
                    }
                    // Offsets alike at one exposure; two exposures and repeats separate them.
                    "black_level" | "dsnu" | "dark_current" => {
                        let mut v = darks(&[0.002, 1.0], 6);
                        v.extend(flats(&[0.5], 2));
                        v
                    }
                    // The dark current's temperature law: darks at two exposures at four
                    // temperatures (its look-alike, dark_current, at one temperature).
                    "dark_temperature" => {
                        let mut v = darks_at_temperatures(&[0.01, 1.0], &DARK_TEMPERATURES_C, 3);
                        v.extend(flats(&[0.5], 2));
                        v
                    }
                    // Drift vs pedestal: darks and a flat with repeats in capture order.
                    "black_level_drift" => {
                        let mut v = darks(&[0.002, 1.0], 6);
                        v.extend(flats(&[0.5], 2));
                        v
                    }
                    // Fixed vs temporal noise: repeats at a few levels.
                    "prnu" | "read_noise" | "column_fpn" | "hot_pixels" | "full_well"
                    | "row_noise" | "rtn" => {
                        let mut v = flats(&[0.1, 0.4, 0.8, 0.95], 4);
                        v.extend(darks(&DARK_T, 4));
                        v
                    }
                    // Scene content that falls off radially, no flat field.
                    "relative_illumination" => {
                        let mut v = vec![radial_scene(dir, spec.rows, spec.cols)?];
                        v.extend(charts(&[0.7], 2));
                        v.extend(darks(&DARK_T, 2));
                        v
                    }
                    // Channel means alike a QE error; the edge and two illuminants separate.
                    "crosstalk" | "qe_shift" | "ir_leakage" => {
                        let mut v = charts(&[0.7], 2);
                        v.extend(flats(&[0.3, 0.7], 2));
                        v.extend(edge(0.7, 2));
                        v.extend(darks(&DARK_T, 2));
                        v
                    }
                    _ => base(1),
                });
            }
            if p.is_empty() {
                p = base(1);
            }
            p
        }
    };
    // One plan per id (effects sharing a look-alike share shots; keep the most repeats).
    let mut out: Vec<Plan> = Vec::new();
    for p in plans.drain(..) {
        match out.iter_mut().find(|q| q.id == p.id) {
            Some(q) => q.repeats = q.repeats.max(p.repeats),
            None => out.push(p),
        }
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------------
// Effects in their generator forms

/// Bisection of a monotone `f` on [lo, hi] for `f(x) = target`.
fn solve(f: impl Fn(f64) -> f64, target: f64, mut lo: f64, mut hi: f64) -> f64 {
    let increasing = f(hi) > f(lo);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if (f(mid) < target) == increasing {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

fn need(ok: bool, id: &str, m: f64, what: &str) -> Result<(), CliError> {
    if ok && m.is_finite() {
        Ok(())
    } else {
        Err(CliError::Other(format!(
            "--effect {id}={m}: the magnitude must be {what}"
        )))
    }
}

/// Adds effect `id` of magnitude `m` to the true camera (generator forms).
fn add_effect(cam: &mut Value, id: &str, m: f64, believed: &CameraFile) -> Result<(), CliError> {
    let s = &believed.sensor;
    match id {
        "exposure_scale" => {
            need(m > 0.0, id, m, "a ratio > 0")?;
            cam["optics"]["exposure_scale"] = json!({"factor": m});
        }
        "conversion_gain" => {
            need(m > 0.0, id, m, "a ratio > 0")?;
            cam["sensor"]["conversion_gain_v_per_e"] = json!(s.conversion_gain_v_per_e * m);
        }
        "black_level" => {
            need(true, id, m, "a number of DN")?;
            cam["sensor"]["black_level_dn"] = json!(s.black_level_dn.unwrap_or(0.0) + m);
        }
        "dark_current" => {
            need(m >= 0.0, id, m, "a dark voltage ≥ 0 (V/s)")?;
            cam["sensor"]["dark_voltage_v_per_s"] = json!(m);
        }
        "read_noise" => {
            need(m >= 0.0, id, m, "a read noise σ ≥ 0 (V)")?;
            cam["sensor"]["read_noise_v"] = json!(m);
        }
        "dsnu" => {
            need(m >= 0.0, id, m, "a DSNU σ ≥ 0 (V)")?;
            cam["sensor"]["dsnu_sigma_v"] = json!(m);
        }
        "prnu" => {
            need(m >= 0.0, id, m, "a PRNU σ ≥ 0 (percent)")?;
            cam["sensor"]["prnu_sigma_percent"] = json!(m);
        }
        "full_well" => {
            need(m > 0.0, id, m, "a well capacity > 0 (electrons)")?;
            cam["sensor"]["well_capacity_e"] = json!(m);
        }
        "column_fpn" => {
            need(m >= 0.0, id, m, "a σ ≥ 0 (V)")?;
            cam["sensor"]["column_fpn"] = json!({"sigma_v": m});
        }
        "hot_pixels" => {
            need((0.0..=1.0).contains(&m), id, m, "a fraction in [0, 1]")?;
            // 40× the believed dark rate (median), lognormal spread.
            cam["sensor"]["hot_pixels"] = json!({"fraction": m,
                "dark_voltage_v_per_s": 40.0 * s.dark_voltage_v_per_s.unwrap_or(5e-3).max(1e-3),
                "log_sigma": 0.6});
        }
        "nonlinearity" => {
            need(m > 0.0 && m < 0.5, id, m, "in (0, 0.5)")?;
            let sensor = sensor_model(believed)?;
            let mag = |sat: f64| {
                let mut t = sensor.clone();
                t.effects.nonlinearity = Some(Nonlinearity::Tanh { saturation_v: sat });
                nonlinearity_magnitude(&t, 1.0)
            };
            let sat = solve(mag, m, 1e-3, 1e3);
            cam["sensor"]["nonlinearity"] = json!({"kind": "tanh", "saturation_v": sat});
        }
        "relative_illumination" => {
            need(
                m > 0.0 && m < 1.0,
                id,
                m,
                "in (0, 1) (two-circle vignetting)",
            )?;
            let sep = solve(two_circle_overlap_fraction, 1.0 - m, 0.0, 2.0);
            cam["optics"]["relative_illumination"] = json!({"model": "cos4",
                "falloff": {"kind": "two_circle", "separation_at_h1": sep}});
        }
        "veiling_glare" => {
            need(m >= 0.0, id, m, "a fraction ≥ 0")?;
            cam["optics"]["veiling_glare"] = json!({"fraction": m});
        }
        "defocus" => {
            need(m > 0.0 && m < 50.0, id, m, "an equivalent σ in (0, 50) µm")?;
            let r = solve(
                |r| Defocus::Pillbox { radius_um: r }.equivalent_sigma_um(PITCH_UM),
                m,
                1e-6,
                10.0 * m + 10.0,
            );
            cam["optics"]["defocus"] = json!({"kind": "pillbox", "radius_um": r});
        }
        "crosstalk" => {
            need(m >= 0.0 && m < 1.0, id, m, "a total fraction in [0, 1)")?;
            cam["sensor"]["crosstalk"] = json!({"left": 0.35 * m, "right": 0.15 * m,
                                                 "up": 0.3 * m, "down": 0.2 * m});
        }
        "ir_leakage" => {
            need(m >= 0.0, id, m, "a mean QE ≥ 0")?;
            let w = [690.0, 700.0, 750.0, 850.0, 950.0, 1000.0, 1010.0];
            let shapes = [
                ("r", [0.0, 0.8, 1.0, 0.7, 0.4, 0.3, 0.0]),
                ("g", [0.0, 0.5, 0.6, 0.6, 0.4, 0.3, 0.0]),
                ("b", [0.0, 0.3, 0.4, 0.55, 0.4, 0.3, 0.0]),
            ];
            let band_mean = |v: &[f64; 7]| {
                let s = camsim_core::Spectrum::sampled(w.to_vec(), v.to_vec()).expect("spectrum");
                camsim_sensor::effects::band_mean(&s)
            };
            let max = shapes.iter().map(|(_, v)| band_mean(v)).fold(0.0, f64::max);
            let mut ch = serde_json::Map::new();
            for (name, v) in shapes {
                let vals: Vec<f64> = v.iter().map(|x| x * m / max).collect();
                ch.insert(name.into(), json!({"wavelength_nm": w, "values": vals}));
            }
            cam["sensor"]["ir_leakage"] = json!({"channels": ch});
        }
        "qe_shift" => {
            need(true, id, m, "a shift in nm")?;
            cam["sensor"]["qe_shift"] = json!({"shift_nm": {"r": m, "g": 0.3 * m}});
        }
        "distortion" => {
            need(m > -0.5 && m < 1.0, id, m, "in (−0.5, 1) (division model)")?;
            cam["optics"]["distortion"] = json!({"kind": "division", "k": m / (1.0 + m)});
        }
        "lateral_color" => {
            need(true, id, m, "a displacement in µm")?;
            cam["optics"]["lateral_color"] = json!({"kind": "cauchy", "displacement_um": m});
        }
        "row_noise" => {
            need(m >= 0.0, id, m, "a row-noise σ ≥ 0 (V)")?;
            cam["sensor"]["row_noise"] = json!({"sigma_v": m});
        }
        "rtn" => {
            need((0.0..=1.0).contains(&m), id, m, "a fraction in [0, 1]")?;
            // Steps lognormal about 8× the believed read noise (median), slower switching
            // than the fitted form's 1/2 per frame (mean dwell 2.5 frames each way).
            cam["sensor"]["rtn"] = json!({"fraction": m,
                "amplitude_v": 8.0 * s.read_noise_v.unwrap_or(1e-3).max(1e-4),
                "log_sigma": 0.3, "p_up": 0.4, "p_down": 0.4});
        }
        "black_level_drift" => {
            need(true, id, m, "a drift in DN over the capture set")?;
            // dn_per_frame is set once the set's frame count is known
            cam["sensor"]["black_level_drift"] = json!({"dn_per_frame": 0.0});
        }
        // 0: the temperature series without a temperature law (a null set for it).
        "dark_temperature" if m == 0.0 => {}
        "dark_temperature" => {
            need(
                (2.0..=50.0).contains(&m),
                id,
                m,
                "a doubling temperature in [2, 50] °C (or 0: no law)",
            )?;
            cam["sensor"]["temperature_c"] = json!(DEMO_TEMPERATURE_C);
            cam["sensor"]["dark_reference_temperature_c"] = json!(DEMO_TEMPERATURE_C);
            cam["sensor"]["dark_doubling_temperature_c"] = json!(m);
        }
        other => {
            return Err(CliError::Other(format!(
                "--effect {other}: unknown effect id (expected one of {})",
                EFFECT_IDS.join(", ")
            )))
        }
    }
    Ok(())
}

/// The validated sensor model of a camera file.
fn sensor_model(cam: &CameraFile) -> Result<camsim_sensor::SensorModel, CliError> {
    Ok(crate::config::camera_from_file(Path::new("camera.json"), cam.clone())?.sensor)
}

/// The magnitude (effects.md units) of effect `id` in the true camera.
fn true_magnitude(
    id: &str,
    m: f64,
    truth: &crate::config::Camera,
    seed: u64,
) -> Result<f64, CliError> {
    let (o, s) = (&truth.optics.effects, &truth.sensor);
    Ok(match id {
        "nonlinearity" => nonlinearity_magnitude(s, 1.0),
        "relative_illumination" => o.falloff.as_ref().map_or(0.0, |f| f.magnitude()),
        "defocus" => o
            .defocus
            .map_or(0.0, |d| d.equivalent_sigma_um(s.pixel_pitch_m * 1e6)),
        "crosstalk" => s.effects.crosstalk.map_or(0.0, |c| c.total()),
        "ir_leakage" => s.effects.ir_leakage.as_ref().map_or(0.0, |l| l.magnitude()),
        "qe_shift" => s.effects.qe_shift.as_ref().map_or(0.0, |q| q.magnitude()),
        "distortion" => o.distortion.map_or(0.0, |d| d.magnitude()),
        "lateral_color" => o.lateral_color.map_or(0.0, |l| l.magnitude()),
        "veiling_glare" => o.veiling_glare.unwrap_or(0.0),
        "exposure_scale" => o.exposure_scale.unwrap_or(1.0),
        "rtn" => camsim_sensor::rtn_pixel_count(s) as f64 / (s.rows * s.cols) as f64,
        "dark_temperature" => s
            .effects
            .dark_temperature
            .map_or(0.0, |d| d.doubling_temperature_c),
        // The realised fraction of the drawn pattern.
        "hot_pixels" => hot_pixel_count(s) as f64 / (s.rows * s.cols) as f64,
        // The realised σ of the drawn column offsets (about their mean).
        "column_fpn" => {
            let c = fixed_pattern(s, seed).column_offset_v;
            let n = c.len() as f64;
            let mean = c.iter().map(|&x| x as f64).sum::<f64>() / n;
            (c.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n).sqrt()
        }
        // Base parameters: the requested value (ratio, ΔDN, V/s, V, %, e⁻).
        _ => m,
    })
}

/// Writes a concealed-effect capture set into `out_dir` (all or nothing) and returns its
/// truth; see the module docs and docs/effects.md.
pub fn generate_capture_set(spec: &DemoSpec, out_dir: &Path) -> Result<DemoTruth, CliError> {
    if !(8..=4096).contains(&spec.rows) || !(8..=4096).contains(&spec.cols) {
        return Err(CliError::Other(format!(
            "demo: sensor {}×{} must be 8–4096 pixels per side",
            spec.rows, spec.cols
        )));
    }
    let mut seen = std::collections::HashSet::new();
    for (id, _) in &spec.effects {
        if !seen.insert(id.as_str()) {
            return Err(CliError::Other(format!("--effect {id}: given twice")));
        }
    }
    let believed = believed_camera(spec.rows, spec.cols);
    let mut true_json = serde_json::to_value(&believed)
        .map_err(|e| CliError::Other(format!("demo camera: {e}")))?;
    for (id, m) in &spec.effects {
        add_effect(&mut true_json, id, *m, &believed)?;
    }
    true_json["name"] = json!("demo-true");
    let mut effects_out = Vec::new();
    crate::staging::with_staging(out_dir, |stage| {
        // The believed camera and the true one (the latter only inside the staging folder,
        // which is removed afterwards).
        crate::config::write_camera_file(&stage.join("camera.json"), &believed)?;
        let plans = plan_shots(spec, stage)?;
        // Black-level drift: the requested drift over the set's frames, per frame.
        let n_frames: usize = plans.iter().map(|p| p.repeats).sum();
        let mut true_json = true_json.clone();
        for (id, m) in &spec.effects {
            if id == "black_level_drift" {
                true_json["sensor"]["black_level_drift"] =
                    json!({"dn_per_frame": m / (n_frames.max(2) - 1) as f64});
            }
        }
        let true_path = stage.join(".true-camera.json");
        std::fs::write(
            &true_path,
            serde_json::to_string_pretty(&true_json).unwrap_or_default(),
        )
        .map_err(|e| CliError::output(&true_path, e))?;
        let truth_cam = load_camera(&true_path)?;
        let mut files: Vec<PathBuf> = vec!["camera.json".into(), "captures.json".into()];
        if plans.iter().any(|p| p.id == "radial-scene") {
            files.push("scenes/radial.exr".into());
        }
        // Exposures from the believed camera's expected electron rates (brightest pixel at
        // the planned fraction of full scale).
        let provisional: Vec<Value> = plans
            .iter()
            .map(|p| json!({"id": p.id, "target": p.target, "exposure_s": 1.0, "frames": []}))
            .collect();
        let cap_path = stage.join("captures.json");
        let write_caps = |shots: &[Value]| -> Result<(), CliError> {
            let v = json!({"camera": "camera.json", "shots": shots,
                           "simulation": {"seed": spec.seed}});
            std::fs::write(
                &cap_path,
                serde_json::to_string_pretty(&v).unwrap_or_default(),
            )
            .map_err(|e| CliError::output(&cap_path, e))
        };
        write_caps(&provisional)?;
        let set = load_captures(&cap_path, None)?;
        let grid = wavelength_grid(&set);
        let s = &set.camera.sensor;
        let full_scale_v = (s.max_dn() - s.black_level_dn) / s.dn_per_output_v();
        let mut shots = Vec::new();
        for (i, p) in plans.iter().enumerate() {
            let t = match p.level {
                Level::Exposure(t) => t,
                Level::FullScale(f) => {
                    let rate = shot_electron_rate(&set, i, &grid)?;
                    let rmax = rate
                        .electrons_per_s
                        .iter()
                        .fold(0f64, |m, &r| m.max(r as f64));
                    if rmax <= 0.0 {
                        return Err(CliError::Other(format!("demo: shot {} is dark", p.id)));
                    }
                    f * full_scale_v / (s.conversion_gain_v_per_e * rmax)
                }
            };
            let frames: Vec<String> = (0..p.repeats)
                .map(|k| format!("raw/{}-{k}.png", p.id))
                .collect();
            let mut shot = json!({"id": p.id, "target": p.target, "exposure_s": t,
                                  "frames": frames});
            if let Some(tc) = p.temperature_c {
                shot["temperature_c"] = json!(tc);
            }
            shots.push(shot);
        }
        write_caps(&shots)?;
        // Frames from the true camera.
        let true_set = load_captures(&cap_path, Some(&true_path))?;
        let summary = simulate(
            &true_set,
            &SimulateOptions {
                out_dir: stage.to_path_buf(),
                seed: spec.seed,
                expected: false,
                progress: false,
            },
        )?;
        files.extend(summary.files);
        // The truth.
        for (id, m) in &spec.effects {
            effects_out.push(TrueEffect {
                effect: id.clone(),
                magnitude: true_magnitude(id, *m, &truth_cam, spec.seed)?,
            });
        }
        let truth = json!({"effects": effects_out.iter()
            .map(|e| json!({"effect": e.effect, "magnitude": e.magnitude}))
            .collect::<Vec<_>>()});
        std::fs::write(
            stage.join("truth.json"),
            serde_json::to_string_pretty(&truth).unwrap_or_default(),
        )
        .map_err(|e| CliError::output(&stage.join("truth.json"), e))?;
        files.push("truth.json".into());
        Ok(files)
    })?;
    Ok(DemoTruth {
        effects: effects_out,
        captures_json: out_dir.join("captures.json"),
    })
}
