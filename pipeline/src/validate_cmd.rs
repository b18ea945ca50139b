//! `camsim validate CAPTURES.json --out DIR`: every shot of a capture set simulated with its
//! camera and compared with the recording, as Farrell, Catrysse & Wandell, "Digital camera
//! simulation" (Applied Optics 2012) compare simulated and measured captures in Figs. 3–6:
//!
//! * per shot and channel: mean measured DN against the simulated frames and the expected
//!   (noise-free) image, the normalised residual `(measured mean − expected mean) / σ_model`
//!   (σ_model: the camera model's temporal + fixed-pattern noise of that mean) and the reduced
//!   χ² of the frame-averaged pixels;
//! * for a 4 × 6 chart: per-patch means and SNR, measured vs simulated (Figs. 3–4), a 3 × 3
//!   colour correction fitted on the measured and on the simulated chart to the Macbeth D65
//!   sRGB targets, and the ΔE2000 of each corrected chart against the targets (Figs. 5–6);
//! * a residual image per shot (frame-averaged measured − expected), diverging colour map.
//!
//! The simulation draws one frame per recorded frame with `simulate`'s seed scheme (fixed
//! patterns from `seed`, frame `fi` of shot `si` from the streams `[si, fi]`), so validating a
//! set that `camsim simulate --seed S` wrote, with seed S and the same camera, reproduces the
//! recording exactly. Outputs: DIR/validation.json, DIR/report.html and the figures, all or
//! nothing.
use crate::chain::{shot_electron_rate, wavelength_grid};
use crate::color_eval::{patch_delta_e, through_srgb8};
use crate::config::CaptureSet;
use crate::error::CliError;
use crate::plots;
use crate::raw_input::read_frame_with;
use crate::report::html_escape;
use crate::staging::with_staging;
use camsim_core::RawFrame;
use camsim_isp::{fit_color_correction, macbeth_target_linear_srgb};
use camsim_metrics::patch_sample_rect;
use camsim_sensor::{fixed_pattern, ElectronRate, FixedPattern, PatternSource, SensorModel, Shot};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Linear sRGB level of the Macbeth white patch in the colour targets (`camsim run`'s default).
const WHITE_LEVEL: f64 = 0.9;
/// A relative mismatch is reported only when the measured signal above black exceeds this
/// many standard errors of its mean (otherwise it is dominated by noise, e.g. dark shots).
const MIN_SIGNAL_SIGMAS: f64 = 10.0;

/// Noise model of one shot: per-pixel variances (DN²) of a single frame's value.
struct NoiseModel {
    t: f64,
    dark_e: f64,
    well: f64,
    /// DN per electron at the shot's analog gain.
    dn_per_e: f64,
    max_dn: f64,
    shot: bool,
    dark: bool,
    prnu: f64,
    /// Temporal variance independent of the signal: read (+ reset without CDS) + quantisation.
    temporal_const: f64,
    /// Fixed-pattern variance independent of the signal and pixel-independent: DSNU.
    fixed_const: f64,
    /// Variance of the per-column offsets (correlated along a column).
    column_var: f64,
}

impl NoiseModel {
    fn new(s: &SensorModel, shot: &Shot) -> Self {
        let sw = s.noise;
        let dn_per_v = shot.analog_gain * s.dn_per_output_v();
        let reset = s.reset_noise.filter(|r| !r.cds).map_or(0.0, |r| r.sigma_v);
        let read = if sw.read { s.read_noise_v } else { 0.0 };
        let dsnu = if sw.dsnu { s.dsnu_sigma_v } else { 0.0 };
        let col = s.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
        NoiseModel {
            t: shot.exposure_s,
            dark_e: shot.exposure_s * s.dark_voltage_v_per_s / s.conversion_gain_v_per_e,
            well: s.well_capacity_e,
            dn_per_e: s.dn_per_e(shot.analog_gain),
            max_dn: s.max_dn(),
            shot: sw.shot,
            dark: sw.dark,
            prnu: if sw.prnu {
                s.prnu_sigma_percent / 100.0
            } else {
                0.0
            },
            temporal_const: dn_per_v * dn_per_v * (read * read + reset * reset) + 1.0 / 12.0,
            fixed_const: dn_per_v * dn_per_v * dsnu * dsnu,
            column_var: dn_per_v * dn_per_v * col * col,
        }
    }

    /// (temporal, fixed-pattern) variance in DN² of one frame's value of a pixel with electron
    /// rate `rate` and expected value `expected` (DN). A saturated pixel keeps only the
    /// quantisation variance.
    fn variances(&self, rate: f64, expected: f64) -> (f64, f64) {
        let e = rate * self.t;
        if e + self.dark_e >= self.well || expected >= self.max_dn - 0.5 {
            return (1.0 / 12.0, 0.0);
        }
        let poisson = if self.shot { e } else { 0.0 } + if self.dark { self.dark_e } else { 0.0 };
        let temporal = self.dn_per_e * self.dn_per_e * poisson + self.temporal_const;
        let prnu = self.dn_per_e * e * self.prnu;
        (temporal, self.fixed_const + prnu * prnu)
    }
}

/// Sums over a set of pixels of the frame-averaged measured and simulated values, the expected
/// value and the model variance of the frame average.
#[derive(Debug, Clone, Default)]
struct Acc {
    n: usize,
    measured: f64,
    simulated: f64,
    expected: f64,
    /// Σ σ²_i of the frame-averaged pixel (temporal / frames + fixed, column FPN excluded).
    var_sum: f64,
    chi2_measured: f64,
    chi2_simulated: f64,
    /// Pixels per column (column FPN is shared along a column).
    per_column: Vec<u32>,
}

/// Per-pixel images of one shot.
struct ShotImages {
    measured_mean: Vec<f64>,
    simulated_mean: Vec<f64>,
    expected: Vec<f32>,
    /// Variance of the frame-averaged pixel (DN²), column FPN excluded.
    var_mean: Vec<f64>,
    frames: usize,
}

impl Acc {
    fn add(&mut self, img: &ShotImages, i: usize, col: usize) {
        let (m, s, e, v) = (
            img.measured_mean[i],
            img.simulated_mean[i],
            img.expected[i] as f64,
            img.var_mean[i],
        );
        self.n += 1;
        self.measured += m;
        self.simulated += s;
        self.expected += e;
        self.var_sum += v;
        let v = v.max(1e-12);
        self.chi2_measured += (m - e) * (m - e) / v;
        self.chi2_simulated += (s - e) * (s - e) / v;
        if self.per_column.len() <= col {
            self.per_column.resize(col + 1, 0);
        }
        self.per_column[col] += 1;
    }

    /// Standard error (DN) of the region's mean under the model.
    fn sigma_mean(&self, column_var: f64) -> f64 {
        let n = self.n.max(1) as f64;
        let col: f64 = self
            .per_column
            .iter()
            .map(|&k| (k as f64 / n).powi(2))
            .sum();
        (self.var_sum / (n * n) + column_var * col).sqrt()
    }

    fn json(&self, column_var: f64, black: f64) -> Value {
        let n = self.n.max(1) as f64;
        let (m, s, e) = (self.measured / n, self.simulated / n, self.expected / n);
        let sigma = self.sigma_mean(column_var);
        let signal = m - black;
        let rel = |x: f64| {
            if signal > MIN_SIGNAL_SIGMAS * sigma && signal > 0.0 {
                json!((x - black) / signal - 1.0)
            } else {
                Value::Null
            }
        };
        json!({
            "pixels": self.n,
            "measured_mean_dn": m,
            "simulated_mean_dn": s,
            "expected_mean_dn": e,
            "sigma_model_dn": sigma,
            "normalised_residual": (m - e) / sigma.max(1e-12),
            "simulated_normalised_residual": (s - e) / sigma.max(1e-12),
            "relative_mismatch": rel(e),
            "simulated_relative_mismatch": rel(s),
            "chi2_per_pixel": self.chi2_measured / n,
            "simulated_chi2_per_pixel": self.chi2_simulated / n,
        })
    }
}

/// Spatial moments of one frame over a set of pixels (for the patch SNR).
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    n: f64,
    sum: f64,
    sum2: f64,
}

impl Moments {
    fn mean_var(&self) -> (f64, f64) {
        let n = self.n.max(1.0);
        let m = self.sum / n;
        let v = if self.n > 1.0 {
            ((self.sum2 - n * m * m) / (n - 1.0)).max(0.0)
        } else {
            0.0
        };
        (m, v)
    }
}

/// Mean over frames of each (patch, channel)'s spatial mean and variance.
#[derive(Debug, Clone, Default)]
struct PatchSnr {
    mean: f64,
    var: f64,
    frames: usize,
}

impl PatchSnr {
    fn add(&mut self, m: &Moments) {
        let (mean, var) = m.mean_var();
        self.mean += mean;
        self.var += var;
        self.frames += 1;
    }
    /// (mean above black, std, SNR dB).
    fn get(&self, black: f64) -> (f64, f64, f64) {
        let f = self.frames.max(1) as f64;
        let mean = self.mean / f - black;
        let std = (self.var / f).sqrt();
        (mean, std, 20.0 * (mean.abs() / std).log10())
    }
}

fn channel_colour(name: &str, k: usize) -> [u8; 3] {
    match name {
        "r" | "R" => [220, 30, 30],
        "g" | "G" => [30, 160, 30],
        "b" | "B" => [30, 60, 220],
        _ => [[120, 60, 160], [200, 140, 20], [20, 160, 160], [90, 90, 90]][k % 4],
    }
}

/// Checks every recorded frame (readable, the sensor's size, within the ADC range) before
/// anything is simulated.
fn check_frames(set: &CaptureSet) -> Result<(), CliError> {
    let s = &set.camera.sensor;
    for shot in &set.shots {
        for f in &shot.frames {
            let p = set.dir.join(f);
            let is_png = p
                .extension()
                .map(|e| e.eq_ignore_ascii_case("png"))
                .unwrap_or(false);
            if is_png {
                // the header is enough for the size and bit depth
                crate::frames::check_frame(&p, s.rows, s.cols)?;
            } else {
                let fr = read_frame_with(&p, set.raw_format.as_ref())?;
                check_size(&p, &fr, s)?;
            }
        }
    }
    Ok(())
}

fn check_size(path: &Path, f: &RawFrame, s: &SensorModel) -> Result<(), CliError> {
    if f.rows != s.rows || f.cols != s.cols {
        return Err(CliError::input(
            path,
            format!(
                "frame is {}×{} (rows×cols) but the sensor is {}×{}",
                f.rows, f.cols, s.rows, s.cols
            ),
        ));
    }
    let max_dn = s.max_dn() as u32;
    if let Some(v) = f.dn.iter().find(|&&v| v as u32 > max_dn) {
        return Err(CliError::input(
            path,
            format!(
                "value {v} DN exceeds the camera's {}-bit ADC range (max {max_dn})",
                s.adc_bits
            ),
        ));
    }
    Ok(())
}

/// Diverging blue–white–red rendering of `v / scale` clipped to [−1, 1].
fn diverging_rgb8(v: &[f64], scale: f64) -> Vec<u8> {
    let scale = scale.max(1e-12);
    v.iter()
        .flat_map(|&x| {
            let x = if x.is_finite() {
                (x / scale).clamp(-1.0, 1.0)
            } else {
                0.0
            };
            let k = (255.0 * (1.0 - x.abs())).round() as u8;
            if x < 0.0 {
                [k, k, 255]
            } else {
                [255, k, k]
            }
        })
        .collect()
}

/// What `validate` reports: the worst mismatches, and validation.json as written.
#[derive(Debug, Clone)]
pub struct ValidateSummary {
    /// Largest |relative mismatch| of a shot's mean over every shot and channel.
    pub max_abs_relative_mismatch: Option<f64>,
    /// Largest |normalised residual| (measured − expected mean, in standard errors).
    pub max_abs_normalised_residual: Option<f64>,
    /// Files written into `--out` (relative paths).
    pub files: Vec<PathBuf>,
    /// validation.json as written.
    pub json: Value,
}

/// Validate `set` against its camera and write the outputs into `out` (all or nothing).
pub fn run_validate(
    set: &CaptureSet,
    out: &Path,
    seed: u64,
    progress: bool,
) -> Result<ValidateSummary, CliError> {
    check_frames(set)?;
    let mut summary = Value::Null;
    let files = with_staging(out, |st| {
        let (s, files) = validate_into(set, st, seed, progress)?;
        summary = s;
        Ok(files)
    })?;
    let num = |k: &str| summary["summary"][k].as_f64();
    Ok(ValidateSummary {
        max_abs_relative_mismatch: num("max_abs_relative_mismatch"),
        max_abs_normalised_residual: num("max_abs_normalised_residual"),
        files,
        json: summary,
    })
}

/// Figures of the report: (file, caption).
type Figures = Vec<(String, String)>;

fn validate_into(
    set: &CaptureSet,
    st: &Path,
    seed: u64,
    progress: bool,
) -> Result<(Value, Vec<PathBuf>), CliError> {
    let sensor = &set.camera.sensor;
    let (rows, cols) = (sensor.rows, sensor.cols);
    let black = sensor.black_level_dn;
    let names = &sensor.channel_names;
    let grid = wavelength_grid(set);
    let total: u64 = set.shots.iter().map(|s| s.frames.len() as u64 + 1).sum();
    let bar = crate::progress::bar(
        progress,
        total,
        "{spinner} validate [{bar:40}] {pos}/{len} {msg}",
    );
    let mut files: Vec<PathBuf> = Vec::new();
    let mut put = |name: &str| -> PathBuf {
        files.push(PathBuf::from(name));
        st.join(name)
    };
    let mut figures: Figures = Vec::new();
    let rgb_idx: Option<[usize; 3]> = {
        let f = |n: &str| names.iter().position(|x| x == n);
        match (f("r"), f("g"), f("b")) {
            (Some(r), Some(g), Some(b)) => Some([r, g, b]),
            _ => None,
        }
    };
    let d65 =
        camsim_core::data::illuminant("D65").map_err(|e| CliError::Other(format!("D65: {e}")))?;
    let targets = macbeth_target_linear_srgb(&d65, WHITE_LEVEL)
        .map_err(|e| CliError::Other(format!("colour targets: {e}")))?;
    let mut fixed: Option<FixedPattern> = None;
    let mut cache: HashMap<&str, ElectronRate> = HashMap::new();
    let mut shots_json = Vec::new();
    // (shot, channel) means for the all-shots scatter
    let (mut sx, mut sy, mut sc) = (Vec::new(), Vec::new(), Vec::new());
    let mut worst_rel: Option<(f64, String)> = None;
    let mut worst_z: Option<(f64, String)> = None;
    let mut html_shots = String::new();

    for (si, shot) in set.shots.iter().enumerate() {
        bar.set_message(shot.id.clone());
        let kind = serde_json::from_str::<Value>(&shot.target_key)
            .ok()
            .and_then(|v| v["kind"].as_str().map(String::from))
            .unwrap_or_default();
        if shot.frames.is_empty() {
            shots_json
                .push(json!({"id": shot.id, "target_kind": kind, "skipped": "no recorded frames"}));
            bar.inc(1);
            continue;
        }
        if !cache.contains_key(shot.target_key.as_str()) {
            let rate = shot_electron_rate(set, si, &grid)?;
            cache.insert(shot.target_key.as_str(), rate);
        }
        let rate = &cache[shot.target_key.as_str()];
        let sh = crate::chain::shot_exposure(set, si, rate);
        let rate = &*crate::chain::shot_time_rate(set, si, rate, &sh);
        let exposure_s = sh.exposure_s;
        let expected = crate::chain::expected_frame(sensor, rate, &sh).data;
        let model = NoiseModel::new(sensor, &sh);
        let layout = crate::targets::chart_layout(&shot.target.target);
        let n_patches = layout.map_or(0, |l| l.chart_rows * l.chart_cols);
        let nch = names.len();
        // per (patch, channel): spatial moments per frame, averaged over frames
        let mut snr_meas = vec![PatchSnr::default(); n_patches * nch];
        let mut snr_sim = vec![PatchSnr::default(); n_patches * nch];
        let rects: Vec<_> = layout
            .map(|l| {
                (0..n_patches)
                    .map(|p| patch_sample_rect(rows, cols, &l, p / l.chart_cols, p % l.chart_cols))
                    .collect()
            })
            .unwrap_or_default();
        let patch_moments = |dn: &[u16]| -> Vec<Moments> {
            let mut m = vec![Moments::default(); n_patches * nch];
            for (p, r) in rects.iter().enumerate() {
                for y in r.row0..r.row1 {
                    for x in r.col0..r.col1 {
                        let c = sensor.cfa.channel_at(y, x);
                        let v = dn[y * cols + x] as f64;
                        let a = &mut m[p * nch + c];
                        a.n += 1.0;
                        a.sum += v;
                        a.sum2 += v * v;
                    }
                }
            }
            m
        };
        let mut measured_sum = vec![0f64; rows * cols];
        let mut simulated_sum = vec![0f64; rows * cols];
        if fixed.is_none() {
            fixed = Some(fixed_pattern(sensor, seed));
        }
        let fixed_ref = fixed.as_ref().expect("built above");
        for (fi, f) in shot.frames.iter().enumerate() {
            let path = set.dir.join(f);
            let measured = read_frame_with(&path, set.raw_format.as_ref())?;
            check_size(&path, &measured, sensor)?;
            let simulated = crate::chain::simulate_frame(
                sensor,
                rate,
                &sh,
                PatternSource::Maps(fixed_ref),
                seed,
                &[si as u64, fi as u64],
            );
            for (a, &v) in measured_sum.iter_mut().zip(&measured.dn) {
                *a += v as f64;
            }
            for (a, &v) in simulated_sum.iter_mut().zip(&simulated.dn) {
                *a += v as f64;
            }
            for (acc, m) in snr_meas.iter_mut().zip(patch_moments(&measured.dn)) {
                acc.add(&m);
            }
            for (acc, m) in snr_sim.iter_mut().zip(patch_moments(&simulated.dn)) {
                acc.add(&m);
            }
            bar.inc(1);
        }
        let nf = shot.frames.len() as f64;
        let var_mean: Vec<f64> = rate
            .electrons_per_s
            .iter()
            .zip(&expected)
            .map(|(&r, &e)| {
                let (t, f) = model.variances(r as f64, e as f64);
                t / nf + f
            })
            .collect();
        let img = ShotImages {
            measured_mean: measured_sum.iter().map(|v| v / nf).collect(),
            simulated_mean: simulated_sum.iter().map(|v| v / nf).collect(),
            expected,
            var_mean,
            frames: shot.frames.len(),
        };
        // whole-frame statistics per channel and over all pixels
        let mut per_ch = vec![Acc::default(); nch];
        let mut all = Acc::default();
        for y in 0..rows {
            for x in 0..cols {
                let i = y * cols + x;
                per_ch[sensor.cfa.channel_at(y, x)].add(&img, i, x);
                all.add(&img, i, x);
            }
        }
        let mut channels = serde_json::Map::new();
        for (c, acc) in per_ch.iter().enumerate() {
            if acc.n == 0 {
                continue;
            }
            let j = acc.json(model.column_var, black);
            sx.push(j["measured_mean_dn"].as_f64().unwrap_or(f64::NAN));
            sy.push(j["simulated_mean_dn"].as_f64().unwrap_or(f64::NAN));
            sc.push(channel_colour(&names[c], c));
            let label = format!("{} / {}", shot.id, names[c]);
            if let Some(r) = j["relative_mismatch"].as_f64() {
                if worst_rel.as_ref().is_none_or(|w| r.abs() > w.0.abs()) {
                    worst_rel = Some((r, label.clone()));
                }
            }
            if let Some(z) = j["normalised_residual"].as_f64() {
                if worst_z.as_ref().is_none_or(|w| z.abs() > w.0.abs()) {
                    worst_z = Some((z, label));
                }
            }
            channels.insert(names[c].clone(), j);
        }
        let all_json = all.json(model.column_var, black);
        // residual image: frame-averaged measured − expected, ±3 model σ (rms) full scale
        let residual: Vec<f64> = img
            .measured_mean
            .iter()
            .zip(&img.expected)
            .map(|(m, &e)| m - e as f64)
            .collect();
        let rms_sigma = (img.var_mean.iter().sum::<f64>() / img.var_mean.len().max(1) as f64)
            .sqrt()
            .max(0.5);
        let scale = 3.0 * rms_sigma;
        let rms_residual =
            (residual.iter().map(|v| v * v).sum::<f64>() / residual.len().max(1) as f64).sqrt();
        let res_name = format!("residual_{}.png", shot.id);
        plots::rgb8_png(
            &put(&res_name),
            &diverging_rgb8(&residual, scale),
            rows,
            cols,
        )?;
        figures.push((
            res_name.clone(),
            format!(
                "{}: residual, frame-averaged measured − expected (blue −, red +; full scale ±{scale:.2} DN = 3 × model σ)",
                shot.id
            ),
        ));
        let mut sj = json!({
            "id": shot.id,
            "target_kind": kind,
            "exposure_s": exposure_s,
            "analog_gain": shot.analog_gain,
            "frames": img.frames,
            "channels": Value::Object(channels),
            "all_pixels": all_json,
            "residual_image": res_name,
            "residual_rms_dn": rms_residual,
            "residual_full_scale_dn": scale,
        });
        // the chart: per-patch statistics (Figs. 3–4) and colour (Figs. 5–6)
        let mut html_chart = String::new();
        if layout.is_some() {
            let mut patch_ch: Vec<Vec<Value>> = vec![Vec::new(); nch];
            // patch means above black, [patch][channel]: measured, simulated
            let mut pm = vec![vec![f64::NAN; nch]; n_patches];
            let mut ps = vec![vec![f64::NAN; nch]; n_patches];
            let (mut mx, mut my, mut mc) = (Vec::new(), Vec::new(), Vec::new());
            let (mut nx, mut ny, mut nc) = (Vec::new(), Vec::new(), Vec::new());
            for (p, r) in rects.iter().enumerate() {
                let mut acc = vec![Acc::default(); nch];
                for y in r.row0..r.row1 {
                    for x in r.col0..r.col1 {
                        acc[sensor.cfa.channel_at(y, x)].add(&img, y * cols + x, x);
                    }
                }
                for c in 0..nch {
                    if acc[c].n == 0 {
                        patch_ch[c].push(Value::Null);
                        continue;
                    }
                    let mut j = acc[c].json(model.column_var, black);
                    let (mm, mstd, msnr) = snr_meas[p * nch + c].get(black);
                    let (sm, sstd, ssnr) = snr_sim[p * nch + c].get(black);
                    j["measured_std_dn"] = json!(mstd);
                    j["simulated_std_dn"] = json!(sstd);
                    j["measured_snr_db"] = json!(msnr);
                    j["simulated_snr_db"] = json!(ssnr);
                    pm[p][c] = mm;
                    ps[p][c] = sm;
                    let col = channel_colour(&names[c], c);
                    mx.push(mm);
                    my.push(sm);
                    mc.push(col);
                    if msnr.is_finite() && ssnr.is_finite() {
                        nx.push(msnr);
                        ny.push(ssnr);
                        nc.push(col);
                    }
                    patch_ch[c].push(j);
                }
            }
            let mut patches = serde_json::Map::new();
            for (c, v) in patch_ch.into_iter().enumerate() {
                patches.insert(names[c].clone(), Value::Array(v));
            }
            sj["patches"] = Value::Object(patches);
            let f = format!("patch_means_{}.png", shot.id);
            plots::scatter(
                &put(&f),
                &format!("{}: patch means above black, per channel", shot.id),
                &mx,
                &my,
                Some(&mc),
                ("measured (DN)", "simulated (DN)"),
                true,
            )?;
            figures.push((f, format!("{}: measured vs simulated mean of every patch and channel (red/green/blue points = channels; paper Fig. 3)", shot.id)));
            if !nx.is_empty() {
                let f = format!("patch_snr_{}.png", shot.id);
                plots::scatter(
                    &put(&f),
                    &format!("{}: patch SNR, per channel", shot.id),
                    &nx,
                    &ny,
                    Some(&nc),
                    ("measured SNR (dB)", "simulated SNR (dB)"),
                    true,
                )?;
                figures.push((f, format!("{}: measured vs simulated SNR (mean / spatial σ within the patch, per frame) of every patch and channel (paper Fig. 4)", shot.id)));
            }
            // colour: 3×3 matrix fitted on each chart to the D65 sRGB targets (paper §3)
            sj["colour"] = match (rgb_idx, n_patches == targets.len()) {
                (None, _) => {
                    json!({"skipped": format!("needs channels r, g and b (have {})", names.join(", "))})
                }
                (_, false) => json!({"skipped": "the chart does not have 24 patches"}),
                (Some(idx), true) => {
                    let vals = |v: &Vec<Vec<f64>>| -> Vec<[f64; 3]> {
                        v.iter().map(|p| idx.map(|c| p[c])).collect()
                    };
                    let (vm, vs) = (vals(&pm), vals(&ps));
                    let finite = |v: &[[f64; 3]]| v.iter().flatten().all(|x| x.is_finite());
                    if !finite(&vm) || !finite(&vs) {
                        json!({"skipped": "a patch has no pixels of one of the channels r, g, b"})
                    } else {
                        match (
                            fit_color_correction(&vm, &targets),
                            fit_color_correction(&vs, &targets),
                        ) {
                            (Ok(cm), Ok(cs)) => {
                                let shown = |ccm: &camsim_isp::ColorMatrix,
                                             v: &[[f64; 3]]|
                                 -> Vec<[f64; 3]> {
                                    v.iter().map(|x| through_srgb8(ccm.apply(*x))).collect()
                                };
                                let (om, os) = (shown(&cm, &vm), shown(&cs, &vs));
                                let dm = patch_delta_e(&targets, &om)?;
                                let ds = patch_delta_e(&targets, &os)?;
                                let dx = patch_delta_e(&om, &os)?;
                                let fm = format!("delta_e_measured_{}.png", shot.id);
                                let fs = format!("delta_e_simulated_{}.png", shot.id);
                                plots::histogram(
                                    &put(&fm),
                                    &format!(
                                        "{}: ΔE2000, measured chart (mean {:.2})",
                                        shot.id, dm.stats2000.mean
                                    ),
                                    &dm.de2000,
                                    12,
                                    "ΔE2000",
                                )?;
                                plots::histogram(
                                    &put(&fs),
                                    &format!(
                                        "{}: ΔE2000, simulated chart (mean {:.2})",
                                        shot.id, ds.stats2000.mean
                                    ),
                                    &ds.de2000,
                                    12,
                                    "ΔE2000",
                                )?;
                                figures.push((fm, format!("{}: ΔE2000 of the colour-corrected measured chart vs the D65 sRGB targets (paper Fig. 6)", shot.id)));
                                figures.push((fs, format!("{}: ΔE2000 of the colour-corrected simulated chart vs the D65 sRGB targets (paper Fig. 6)", shot.id)));
                                html_chart.push_str(&format!(
                                "<h4>Colour (3×3 fitted on each chart to the D65 sRGB targets)</h4><table><tr><th></th><th>mean ΔE2000</th><th>median</th><th>95th pct</th><th>max</th></tr>\
                                 <tr><th>measured</th><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td></tr>\
                                 <tr><th>simulated</th><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td></tr>\
                                 <tr><th>measured vs simulated</th><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td></tr></table>",
                                dm.stats2000.mean, dm.stats2000.median, dm.stats2000.p95, dm.stats2000.max,
                                ds.stats2000.mean, ds.stats2000.median, ds.stats2000.p95, ds.stats2000.max,
                                dx.stats2000.mean, dx.stats2000.median, dx.stats2000.p95, dx.stats2000.max,
                            ));
                                json!({
                                    "targets": "Macbeth ColorChecker, D65, linear sRGB (white patch Y = 0.9)",
                                    "ccm_measured": cm.m,
                                    "ccm_simulated": cs.m,
                                    "delta_e_2000_measured": dm.json_2000(),
                                    "delta_e_2000_simulated": ds.json_2000(),
                                    "delta_e_76_measured": dm.json_76(),
                                    "delta_e_76_simulated": ds.json_76(),
                                    "delta_e_2000_measured_vs_simulated": dx.json_2000(),
                                    "patches": (0..targets.len()).map(|i| json!({"desired_linear_srgb": targets[i], "measured_linear_srgb": om[i], "simulated_linear_srgb": os[i]})).collect::<Vec<_>>(),
                                })
                            }
                            (a, b) => {
                                json!({"skipped": format!("colour correction could not be fitted: {}",
                            a.err().or(b.err()).map(|e| e.to_string()).unwrap_or_default())})
                            }
                        }
                    }
                }
            };
        }
        // report rows of this shot
        html_shots.push_str(&format!(
            "<h3>{} <small>({}, {} frame(s), exposure {:.4e} s)</small></h3><table><tr><th>channel</th><th>measured mean (DN)</th><th>simulated mean (DN)</th><th>expected mean (DN)</th><th>σ model (DN)</th><th>normalised residual</th><th>relative mismatch (expected/measured − 1, above black)</th><th>χ²/pixel</th></tr>",
            html_escape(&shot.id),
            html_escape(&kind),
            img.frames,
            exposure_s
        ));
        let row = |name: &str, j: &Value| {
            let f = |k: &str, d: usize| {
                j[k].as_f64()
                    .map(|x| format!("{x:.d$}"))
                    .unwrap_or_else(|| "–".into())
            };
            format!(
                "<tr><th>{}</th><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                html_escape(name),
                f("measured_mean_dn", 2),
                f("simulated_mean_dn", 2),
                f("expected_mean_dn", 2),
                f("sigma_model_dn", 3),
                f("normalised_residual", 2),
                f("relative_mismatch", 4),
                f("chi2_per_pixel", 3)
            )
        };
        for n in names {
            if let Some(j) = sj["channels"].get(n) {
                html_shots.push_str(&row(n, j));
            }
        }
        html_shots.push_str(&row("all", &sj["all_pixels"]));
        html_shots.push_str("</table>");
        html_shots.push_str(&html_chart);
        shots_json.push(sj);
        bar.inc(1);
    }
    if !sx.is_empty() {
        plots::scatter(
            &put("shot_means.png"),
            "Mean DN per shot and channel",
            &sx,
            &sy,
            Some(&sc),
            ("measured mean (DN)", "simulated mean (DN)"),
            true,
        )?;
        figures.insert(
            0,
            (
                "shot_means.png".into(),
                "Measured vs simulated mean DN of every shot and channel (red/green/blue points = channels)".into(),
            ),
        );
    }
    let mut summary = json!({
        "captures": set.path.display().to_string(),
        "camera": set.camera.name,
        "camera_file": set.camera_path.display().to_string(),
        "seed": seed,
        "method": "one simulated frame per recorded frame (simulate's seed scheme) and the expected image per shot; normalised residual = (measured mean − expected mean) / σ_model with σ_model the standard error of that mean under the camera's noise model (shot + dark shot + read + quantisation over the frames, DSNU + PRNU + column FPN); relative mismatch = (expected − black) / (measured − black) − 1",
        "shots": shots_json,
        "summary": {
            "max_abs_relative_mismatch": worst_rel.as_ref().map(|w| w.0.abs()),
            "worst_relative_mismatch": worst_rel.as_ref().map(|w| json!({"value": w.0, "where": w.1})),
            "max_abs_normalised_residual": worst_z.as_ref().map(|w| w.0.abs()),
            "worst_normalised_residual": worst_z.as_ref().map(|w| json!({"value": w.0, "where": w.1})),
        },
    });
    let fig_names: Vec<String> = figures.iter().map(|f| f.0.clone()).collect();
    summary["figures"] = json!(fig_names);
    let mut all_files = fig_names.clone();
    all_files.push("validation.json".into());
    all_files.push("report.html".into());
    summary["files"] = json!(all_files);
    let p = put("validation.json");
    std::fs::write(&p, serde_json::to_string_pretty(&summary).expect("json"))
        .map_err(|e| CliError::output(&p, e))?;
    // report
    let mut h = String::from("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>camsim validate</title><style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}figure{display:inline-block;margin:8px;vertical-align:top}figure img{max-width:520px;border:1px solid #ccc;image-rendering:pixelated}figcaption{max-width:520px}table{border-collapse:collapse;margin-bottom:1em}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}</style></head><body>");
    h.push_str("<h1>camsim validate</h1><p>Recorded captures compared with the simulation of their camera, after Farrell, Catrysse &amp; Wandell, <i>Digital camera simulation</i>, Applied Optics 2012, Figs. 3–6.</p>");
    h.push_str(&format!(
        "<p>Capture set: {}<br>Camera: {} ({})<br>Seed: {seed}</p>",
        html_escape(&set.path.display().to_string()),
        html_escape(&set.camera.name),
        html_escape(&set.camera_path.display().to_string())
    ));
    let fmt = |v: &Value| {
        v.as_f64()
            .map(|x| format!("{x:.4}"))
            .unwrap_or_else(|| "–".into())
    };
    h.push_str(&format!(
        "<h2>Summary</h2><table><tr><th>largest |relative mismatch|</th><td>{}</td><td>{}</td></tr><tr><th>largest |normalised residual|</th><td>{}</td><td>{}</td></tr></table>",
        fmt(&summary["summary"]["max_abs_relative_mismatch"]),
        html_escape(summary["summary"]["worst_relative_mismatch"]["where"].as_str().unwrap_or("")),
        fmt(&summary["summary"]["max_abs_normalised_residual"]),
        html_escape(summary["summary"]["worst_normalised_residual"]["where"].as_str().unwrap_or("")),
    ));
    h.push_str("<p>Normalised residual: (measured mean − expected mean) / σ<sub>model</sub>, ~N(0, 1) when the camera model is right. χ²/pixel: mean over pixels of the squared frame-averaged residual over its model variance, ~1 when the model is right.</p>");
    h.push_str("<h2>Shots</h2>");
    h.push_str(&html_shots);
    h.push_str("<h2>Figures</h2>");
    for (f, c) in &figures {
        h.push_str(&format!(
            "<figure><img src=\"{0}\" alt=\"{1}\"><figcaption>{1}</figcaption></figure>",
            html_escape(f),
            html_escape(c)
        ));
    }
    h.push_str("</body></html>\n");
    let p = put("report.html");
    std::fs::write(&p, h).map_err(|e| CliError::output(&p, e))?;
    bar.finish_and_clear();
    Ok((summary, files))
}
