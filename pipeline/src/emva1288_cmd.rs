//! `camsim emva1288 CAMERA.json --out DIR` and `camsim calibrate --emva1288 DESCRIPTOR --out DIR`:
//! the EMVA 1288 Release 4.0 Linear characterisation (docs/emva1288.md).
//!
//! `emva1288` simulates the standard's measurement series with the camera's sensor stage
//! (`camsim_sensor::expose_with`, the same chain `camsim simulate` runs): uniform
//! monochromatic irradiance on the bare sensor (the standard measures without a lens), a
//! photon-transfer series of exposure times at fixed irradiance with a dark pair at every
//! exposure, and two stacks (bright at 50 % saturation, dark) for the nonuniformities. It
//! writes the series as the reference implementation `emva1288` reads it (a descriptor file
//! `EMVA1288descriptor.txt` and 16-bit PNG images), analyses it
//! ([`camsim_diagnose::emva1288`]) and writes `datasheet.json`, `results.xml` (the reference
//! implementation's result format) and `report.html` with the standard's plots.
//!
//! `calibrate --emva1288` analyses any series given by such a descriptor file.
use crate::error::CliError;
use crate::frames::write_png16;
use crate::plots;
use crate::png_stored::decode_stored_gray16;
use crate::report::html_escape;
use camsim_core::constants::SI;
use camsim_core::RawFrame;
use camsim_diagnose::emva1288::spatial::{analyse_spatial, SpatialResult, StackAccumulator};
use camsim_diagnose::emva1288::{
    analyse_temporal, pair_stats, snr_model, Measured, PairStats, TemporalPoint, TemporalResult,
};
use camsim_sensor::{fixed_pattern, Cfa, ElectronRate, PatternSource, SensorModel, Shot};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Options of one `camsim emva1288` run.
#[derive(Debug, Clone)]
pub struct Emva1288Options {
    /// Output folder.
    pub out_dir: PathBuf,
    /// Seed of every random term.
    pub seed: u64,
    /// Wavelength of the monochromatic light (nm); default: the peak of the channel's QE.
    pub wavelength_nm: Option<f64>,
    /// Channel whose pixels are characterised (name in camera.json); default: the channel
    /// with the highest QE at the wavelength.
    pub channel: Option<String>,
    /// Override of the sensor rows (a small region for quick runs).
    pub rows: Option<usize>,
    /// Override of the sensor columns.
    pub cols: Option<usize>,
    /// Photon-transfer points from dark to saturation (the standard asks for ≥ 50); the
    /// series continues 20 % beyond saturation.
    pub steps_to_saturation: usize,
    /// Frames of each spatial stack (the standard's L; ≥ 3).
    pub spatial_frames: usize,
    /// Exposure time at which the signal saturates (s).
    pub saturation_exposure_s: f64,
}

impl Emva1288Options {
    /// Defaults: seed 0, 50 steps, L = 100, saturation at 10 ms.
    pub fn new(out_dir: PathBuf) -> Self {
        Emva1288Options {
            out_dir,
            seed: 0,
            wavelength_nm: None,
            channel: None,
            rows: None,
            cols: None,
            steps_to_saturation: 50,
            spatial_frames: 100,
            saturation_exposure_s: 0.01,
        }
    }
}

/// The camera's configured values as EMVA 1288 would report them (for the comparison of
/// acceptance point 3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConfiguredValues {
    /// Characterised channel's effective QE times the fill factor, η = FF · QE(λ).
    pub quantum_efficiency: f64,
    /// K = analog gain · g · (2^bits − 1) / swing (DN/e⁻).
    pub system_gain_dn_per_e: f64,
    /// Temporal dark noise without quantisation, read noise / g (e⁻).
    pub dark_noise_e: f64,
    /// Electrons at which the signal saturates (well, swing or ADC, whichever first).
    pub saturation_e: f64,
    /// Dark current, dark voltage rate / g (e⁻/s).
    pub dark_current_e_per_s: f64,
    /// DSNU, dsnu_sigma_v / g (e⁻).
    pub dsnu_e: f64,
    /// PRNU (%).
    pub prnu_percent: f64,
}

/// How the series was simulated.
#[derive(Debug, Clone, Serialize)]
pub struct SeriesSetup {
    /// Channel characterised.
    pub channel: String,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Irradiance on the sensor (µW/cm²).
    pub irradiance_uw_per_cm2: f64,
    /// Photons per pixel per second.
    pub photons_per_pixel_per_s: f64,
    /// Rows × columns.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Pixel area (µm²).
    pub pixel_area_um2: f64,
    /// Exposure of the spatial stacks (s).
    pub spatial_exposure_s: f64,
    /// Frames per spatial stack.
    pub spatial_frames: usize,
    /// Seed.
    pub seed: u64,
}

/// The full analysis: the datasheet and the data behind its plots.
#[derive(Debug, Clone, Serialize)]
pub struct Emva1288Report {
    /// Source: camera file or descriptor file.
    pub source: String,
    /// Bits of the ADC.
    pub bits: u32,
    /// Photon-transfer points (sorted by exposure, then photons).
    pub points: Vec<TemporalPoint>,
    /// Sensitivity, noise, saturation, linearity and dark current.
    pub temporal: TemporalResult,
    /// Nonuniformities (None without spatial stacks).
    pub spatial: Option<SpatialResult>,
    /// Every scalar datasheet number under the reference implementation's name, with its
    /// value and standard uncertainty (NaN where none is defined).
    pub values: BTreeMap<String, Measured>,
    /// The series setup (simulated series only).
    pub setup: Option<SeriesSetup>,
    /// The camera's configured values (simulated series only).
    pub configured: Option<ConfiguredValues>,
}

/// Running per-exposure frame pairs and stacks, filled as frames arrive.
struct SeriesBuilder {
    bright: Vec<(f64, f64, PairStats)>,
    dark: Vec<(f64, PairStats)>,
    stack_bright: Option<StackAccumulator>,
    stack_dark: Option<StackAccumulator>,
}

impl SeriesBuilder {
    fn points(&self) -> Result<Vec<TemporalPoint>, String> {
        self.bright
            .iter()
            .map(|&(t, p, b)| {
                let d = self
                    .dark
                    .iter()
                    .find(|(td, _)| *td == t)
                    .ok_or_else(|| format!("no dark pair at exposure {t} s"))?;
                Ok(TemporalPoint {
                    exposure_s: t,
                    photons_per_pixel: p,
                    bright: b,
                    dark: d.1,
                })
            })
            .collect()
    }
}

/// The monochrome sensor of one channel: every pixel gets that channel's QE (the standard
/// characterises each channel of a colour sensor on its own), rows/cols overridden.
fn channel_sensor(s: &SensorModel, c: usize, rows: usize, cols: usize) -> SensorModel {
    let mut m = s.clone();
    m.rows = rows;
    m.cols = cols;
    m.cfa = Cfa::mono();
    m.channel_names = vec![s.channel_names[c].clone()];
    m.channel_qe = vec![s.channel_qe[c].clone()];
    m.effects.qe_shift = s.effects.qe_shift.as_ref().map(|q| {
        let mut q = q.clone();
        q.shift_nm = vec![q.shift_nm.get(c).copied().unwrap_or(0.0)];
        q
    });
    m.effects.ir_leakage = s.effects.ir_leakage.as_ref().map(|l| {
        let mut l = l.clone();
        l.channels = vec![l.channels.get(c).cloned().flatten()];
        l
    });
    m
}

/// Electrons at which the output saturates: full well, voltage swing or ADC full scale.
fn saturation_electrons(s: &SensorModel, dark_e: f64) -> f64 {
    let g = s.conversion_gain_v_per_e * s.analog_gain;
    let swing_e = (s.voltage_swing_v - s.analog_offset_v) / g;
    let adc_e = ((s.max_dn() - s.black_level_dn) / s.dn_per_output_v() - s.analog_offset_v) / g;
    s.well_capacity_e.min(swing_e.min(adc_e) - dark_e)
}

fn fmt_ns(t_s: f64) -> String {
    format!("{:.1}", t_s * 1e9)
}

/// Simulates and analyses the EMVA 1288 series of the camera in `camera_path`.
pub fn run_emva1288(
    camera_path: &Path,
    opts: &Emva1288Options,
) -> Result<Emva1288Report, CliError> {
    let cam = crate::config::load_camera(camera_path)?;
    let s = &cam.sensor;
    let bad = |key: &str, msg: String| CliError::input(camera_path, format!("{key}: {msg}"));
    // Channel and wavelength.
    let c = match &opts.channel {
        Some(name) => s
            .channel_names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| {
                bad(
                    "--channel",
                    format!(
                        "\"{name}\" is not a channel (have: {})",
                        s.channel_names.join(", ")
                    ),
                )
            })?,
        None => {
            let l = opts.wavelength_nm.unwrap_or(550.0);
            (0..s.channel_qe.len())
                .max_by(|&a, &b| s.effective_qe_at(a, l).total_cmp(&s.effective_qe_at(b, l)))
                .unwrap_or(0)
        }
    };
    let wavelength_nm = match opts.wavelength_nm {
        Some(l) => l,
        None => {
            let (lo, hi) = s.effective_qe_support_nm();
            let (lo, hi) = (lo.max(350.0), hi.min(1100.0));
            let mut best = (550.0, -1.0);
            let mut l = lo;
            while l <= hi {
                let q = s.effective_qe_at(c, l);
                if q > best.1 {
                    best = (l, q);
                }
                l += 1.0;
            }
            best.0
        }
    };
    let qe = s.effective_qe_at(c, wavelength_nm);
    let eta = qe * s.fill_factor;
    if !(eta > 0.0) {
        return Err(bad(
            "--wavelength-nm",
            format!(
                "channel {} has no QE at {wavelength_nm} nm",
                s.channel_names[c]
            ),
        ));
    }
    if opts.spatial_frames < 3 {
        return Err(CliError::Other(format!(
            "--spatial-frames {}: the stacks need at least 3 frames",
            opts.spatial_frames
        )));
    }
    if opts.steps_to_saturation < 3 {
        return Err(CliError::Other(format!(
            "--steps {}: at least 3 photon-transfer points are needed (the standard asks for 50)",
            opts.steps_to_saturation
        )));
    }
    if !(opts.saturation_exposure_s.is_finite() && opts.saturation_exposure_s > 0.0) {
        return Err(CliError::Other(format!(
            "--saturation-exposure-s {}: must be a positive number of seconds",
            opts.saturation_exposure_s
        )));
    }
    let rows = opts.rows.unwrap_or(s.rows);
    let cols = opts.cols.unwrap_or(s.cols);
    if rows < 8 || cols < 8 {
        return Err(CliError::Other(format!(
            "--rows {rows} --cols {cols}: the analysis needs at least 8 × 8 pixels"
        )));
    }
    let sensor = channel_sensor(s, c, rows, cols);
    let g = sensor.conversion_gain_v_per_e;
    // Irradiance: saturation is reached at `saturation_exposure_s`.
    let t_sat = opts.saturation_exposure_s;
    let dark_e_per_s = sensor.dark_voltage_v_per_s / g;
    let sat_e = saturation_electrons(&sensor, dark_e_per_s * t_sat);
    let photons_per_s = sat_e / (eta * t_sat);
    let pixel_area_m2 = sensor.pixel_pitch_m * sensor.pixel_pitch_m;
    let photon_energy_j = SI.planck_j_s * SI.light_speed_m_per_s / (wavelength_nm * 1e-9);
    let irradiance_w_m2 = photons_per_s / pixel_area_m2 * photon_energy_j;
    // Photo-electron rate of a uniform monochromatic field: p² · FF · QE(λ) · E_p(λ)
    // (step 2 of the forward model for a line spectrum) = η · photons per pixel per second.
    let rate = ElectronRate {
        rows,
        cols,
        electrons_per_s: vec![(eta * photons_per_s) as f32; rows * cols],
    };
    let dark_rate = ElectronRate {
        rows,
        cols,
        electrons_per_s: vec![0.0; rows * cols],
    };
    let fixed = fixed_pattern(&sensor, opts.seed);
    let out = &opts.out_dir;
    let img_dir = out.join("images");
    std::fs::create_dir_all(&img_dir).map_err(|e| CliError::output(&img_dir, e))?;
    let mut desc = String::new();
    let _ = writeln!(
        desc,
        "# EMVA 1288 series simulated by camsim from {} (channel {}, {:.1} nm, {:.6e} µW/cm², seed {})",
        camera_path.display(),
        sensor.channel_names[0],
        wavelength_nm,
        irradiance_w_m2 * 100.0,
        opts.seed
    );
    let _ = writeln!(desc, "v 4.0");
    let _ = writeln!(desc, "n {} {} {}", sensor.adc_bits, cols, rows);
    let mut builder = SeriesBuilder {
        bright: Vec::new(),
        dark: Vec::new(),
        stack_bright: None,
        stack_dark: None,
    };
    let mut image_no = 0usize;
    let mut frame =
        |rate: &ElectronRate, t: f64, ids: &[u64]| -> Result<(RawFrame, String), CliError> {
            let f = crate::chain::simulate_frame(
                &sensor,
                rate,
                &Shot::new(&sensor, t),
                PatternSource::Maps(&fixed),
                opts.seed,
                ids,
            );
            let name = format!("image{image_no:05}.png");
            image_no += 1;
            write_png16(&img_dir.join(&name), &f)?;
            Ok((f, name))
        };
    // Photon-transfer series: exposures t_i = i · t_sat / steps, i = 1 … 1.2 · steps.
    let n = opts.steps_to_saturation;
    let n_total = (n as f64 * 1.2).ceil() as usize;
    for i in 1..=n_total {
        let t = t_sat * i as f64 / n as f64;
        // the photon count as written in the descriptor (both analyses read the same value)
        let photons: f64 = format!("{:.6}", photons_per_s * t).parse().unwrap_or(0.0);
        let (a, na) = frame(&rate, t, &[0, i as u64, 0])?;
        let (b, nb) = frame(&rate, t, &[0, i as u64, 1])?;
        let _ = writeln!(
            desc,
            "b {} {photons:.6}\ni images/{na}\ni images/{nb}",
            fmt_ns(t)
        );
        builder.bright.push((t, photons, pair_stats(&a.dn, &b.dn)));
        let (a, na) = frame(&dark_rate, t, &[1, i as u64, 0])?;
        let (b, nb) = frame(&dark_rate, t, &[1, i as u64, 1])?;
        let _ = writeln!(desc, "d {}\ni images/{na}\ni images/{nb}", fmt_ns(t));
        builder.dark.push((t, pair_stats(&a.dn, &b.dn)));
    }
    // Spatial stacks at 50 % saturation.
    let t50 = 0.5 * t_sat;
    let photons50: f64 = format!("{:.6}", photons_per_s * t50).parse().unwrap_or(0.0);
    let mut sb = StackAccumulator::new(rows, cols);
    let mut sd = StackAccumulator::new(rows, cols);
    let _ = writeln!(desc, "b {} {photons50:.6}", fmt_ns(t50));
    for l in 0..opts.spatial_frames {
        let (f, name) = frame(&rate, t50, &[2, l as u64])?;
        sb.add(&f.dn).map_err(CliError::Other)?;
        let _ = writeln!(desc, "i images/{name}");
    }
    let _ = writeln!(desc, "d {}", fmt_ns(t50));
    for l in 0..opts.spatial_frames {
        let (f, name) = frame(&dark_rate, t50, &[3, l as u64])?;
        sd.add(&f.dn).map_err(CliError::Other)?;
        let _ = writeln!(desc, "i images/{name}");
    }
    builder.stack_bright = Some(sb);
    builder.stack_dark = Some(sd);
    let desc_path = out.join("EMVA1288descriptor.txt");
    std::fs::write(&desc_path, desc).map_err(|e| CliError::output(&desc_path, e))?;
    let configured = ConfiguredValues {
        quantum_efficiency: eta,
        system_gain_dn_per_e: sensor.dn_per_e(sensor.analog_gain),
        dark_noise_e: sensor.read_noise_v / g,
        saturation_e: sat_e,
        dark_current_e_per_s: dark_e_per_s,
        dsnu_e: sensor.dsnu_sigma_v / g,
        prnu_percent: sensor.prnu_sigma_percent,
    };
    let setup = SeriesSetup {
        channel: sensor.channel_names[0].clone(),
        wavelength_nm,
        irradiance_uw_per_cm2: irradiance_w_m2 * 100.0,
        photons_per_pixel_per_s: photons_per_s,
        rows,
        cols,
        pixel_area_um2: pixel_area_m2 * 1e12,
        spatial_exposure_s: t50,
        spatial_frames: opts.spatial_frames,
        seed: opts.seed,
    };
    let mut report = analyse(
        &builder,
        &camera_path.display().to_string(),
        sensor.adc_bits,
    )
    .map_err(|e| CliError::input(camera_path, e))?;
    report.setup = Some(setup);
    report.configured = Some(configured);
    write_outputs(&report, out)?;
    Ok(report)
}

fn analyse(b: &SeriesBuilder, source: &str, bits: u32) -> Result<Emva1288Report, String> {
    let points = b.points()?;
    let temporal = analyse_temporal(&points).map_err(|e| e.to_string())?;
    let spatial = match (&b.stack_bright, &b.stack_dark) {
        (Some(sb), Some(sd)) => Some(analyse_spatial(sb, sd, &temporal.system_gain_dn_per_e)?),
        _ => None,
    };
    let mut points = points;
    points.sort_by(|a, b| {
        a.exposure_s
            .total_cmp(&b.exposure_s)
            .then(a.photons_per_pixel.total_cmp(&b.photons_per_pixel))
    });
    let values = reference_values(&temporal, spatial.as_ref());
    Ok(Emva1288Report {
        source: source.to_string(),
        bits,
        points,
        temporal,
        spatial,
        values,
        setup: None,
        configured: None,
    })
}

/// The scalar datasheet numbers under the names of the reference implementation's results
/// (`emva1288.process.Results1288`), in its units (QE and LE in %, dark current in e⁻/s).
fn reference_values(t: &TemporalResult, s: Option<&SpatialResult>) -> BTreeMap<String, Measured> {
    let mut v = BTreeMap::new();
    let m = |value: f64, uncertainty: f64| Measured { value, uncertainty };
    let k = &t.system_gain_dn_per_e;
    v.insert("K".into(), m(k.slope, k.slope_se));
    v.insert(
        "inverse_K".into(),
        m(1.0 / k.slope, k.slope_se / (k.slope * k.slope)),
    );
    let r = &t.responsivity_dn_per_photon;
    v.insert("R".into(), m(r.slope, r.slope_se));
    let q = &t.quantum_efficiency;
    v.insert("QE".into(), m(100.0 * q.value, 100.0 * q.uncertainty));
    let dv = &t.dark_var_dn2;
    let sy = dv.value.sqrt();
    v.insert("sigma_y_dark".into(), m(sy, dv.uncertainty / (2.0 * sy)));
    v.insert("sigma_d".into(), t.dark_noise_e);
    v.insert("u_p_min".into(), t.sensitivity_threshold_photons);
    v.insert("u_e_min".into(), t.sensitivity_threshold_e);
    v.insert("u_p_sat".into(), t.saturation_photons);
    v.insert("u_e_sat".into(), t.saturation_e);
    v.insert("SNR_max".into(), t.snr_max);
    let sm = t.snr_max;
    v.insert(
        "SNR_max_dB".into(),
        m(
            20.0 * sm.value.log10(),
            20.0 / std::f64::consts::LN_10 * sm.uncertainty / sm.value,
        ),
    );
    v.insert(
        "SNR_max_bit".into(),
        m(
            sm.value.log2(),
            sm.uncertainty / (sm.value * std::f64::consts::LN_2),
        ),
    );
    v.insert(
        "inverse_SNR_max".into(),
        m(
            100.0 / sm.value,
            100.0 * sm.uncertainty / (sm.value * sm.value),
        ),
    );
    v.insert("DR".into(), t.dynamic_range);
    let dr = t.dynamic_range;
    v.insert(
        "DR_dB".into(),
        m(
            20.0 * dr.value.log10(),
            20.0 / std::f64::consts::LN_10 * dr.uncertainty / dr.value,
        ),
    );
    if let Some(l) = &t.linearity {
        v.insert("LE_min".into(), m(l.le_min_percent, f64::NAN));
        v.insert("LE_max".into(), m(l.le_max_percent, f64::NAN));
    }
    if let Some(d) = t.dark_current_mean_e_per_s {
        v.insert("u_I_mean".into(), d);
    }
    if let Some(d) = t.dark_current_var_e_per_s {
        v.insert("u_I_var".into(), d);
    }
    if let Some(s) = s {
        v.insert("DSNU1288".into(), s.dsnu_e);
        v.insert(
            "DSNU1288_DN".into(),
            m(s.dsnu_e.value * k.slope, s.dsnu_e.uncertainty * k.slope),
        );
        v.insert("DSNU1288_row".into(), m(s.dsnu_row_e, f64::NAN));
        v.insert("DSNU1288_col".into(), m(s.dsnu_col_e, f64::NAN));
        v.insert("DSNU1288_pixel".into(), m(s.dsnu_pixel_e, f64::NAN));
        v.insert("PRNU1288".into(), s.prnu_percent);
        v.insert("PRNU1288_row".into(), m(s.prnu_row_percent, f64::NAN));
        v.insert("PRNU1288_col".into(), m(s.prnu_col_percent, f64::NAN));
        v.insert("PRNU1288_pixel".into(), m(s.prnu_pixel_percent, f64::NAN));
        v.insert(
            "sigma_2_y_stack".into(),
            m(s.bright.var_stack_dn2, f64::NAN),
        );
        v.insert(
            "sigma_2_y_stack_dark".into(),
            m(s.dark.var_stack_dn2, f64::NAN),
        );
        v.insert("s_2_y".into(), m(s.bright.s2_dn2, f64::NAN));
        v.insert("s_2_y_dark".into(), m(s.dark.s2_dn2, f64::NAN));
    }
    v
}

/// Section, unit and description of each reference name, for `results.xml`.
fn reference_meta(name: &str) -> (&'static str, &'static str, &'static str) {
    match name {
        "K" => ("sensitivity", "DN/e-", "System gain"),
        "inverse_K" => ("sensitivity", "e-/DN", "Inverse of overall system gain"),
        "R" => ("sensitivity", "DN/p", "Responsivity"),
        "QE" => ("sensitivity", "%", "Quantum efficiency"),
        "sigma_y_dark" => ("sensitivity", "DN", "Temporal Dark Noise"),
        "sigma_d" => ("sensitivity", "e-", "Temporal Dark Noise"),
        "u_p_min" => ("sensitivity", "p", "Absolute sensitivity threshold"),
        "u_e_min" => ("sensitivity", "e-", "Sensitivity threshold"),
        "u_p_sat" => ("sensitivity", "p", "Saturation Capacity"),
        "u_e_sat" => ("sensitivity", "e-", "Saturation Capacity"),
        "SNR_max" => ("sensitivity", "", "Signal-to-Noise Ratio"),
        "SNR_max_dB" => ("sensitivity", "dB", "Maximum Signal to Noise Ratio in Db"),
        "SNR_max_bit" => (
            "sensitivity",
            "bit",
            "Maximum Signal to Noise Ratio in Bits",
        ),
        "inverse_SNR_max" => ("sensitivity", "%", "Inverse Maximum Signal to Noise Ratio"),
        "DR" => ("sensitivity", "", "Dynamic Range"),
        "DR_dB" => ("sensitivity", "dB", "Dynamic Range"),
        "LE_min" => ("linearity", "%", "Min Linearity error"),
        "LE_max" => ("linearity", "%", "Max Linearity error"),
        "u_I_mean" => ("dark_current", "e-/s", "Dark Current from mean"),
        "u_I_var" => ("dark_current", "e-/s", "Dark Current from variance"),
        "DSNU1288_DN" => ("spatial", "DN", "DSNU in DN"),
        "PRNU1288" | "PRNU1288_row" | "PRNU1288_col" | "PRNU1288_pixel" => ("spatial", "%", "PRNU"),
        "sigma_2_y_stack" | "sigma_2_y_stack_dark" => ("spatial", "DN2", "Temporal variance stack"),
        "s_2_y" | "s_2_y_dark" => ("spatial", "DN2", "Spatial variance from image"),
        _ => ("spatial", "e-", "DSNU"),
    }
}

/// The datasheet in the reference implementation's result format: `<results>` with one
/// element per section and per quantity, each holding `<value>`, `<short>`, `<unit>` (and
/// camsim's `<uncertainty>`), as `emva1288.process.routines.xml_to_dict` reads it.
pub fn results_xml(values: &BTreeMap<String, Measured>) -> String {
    let mut sections: BTreeMap<&str, Vec<(&String, &Measured)>> = BTreeMap::new();
    for (k, v) in values {
        sections
            .entry(reference_meta(k).0)
            .or_default()
            .push((k, v));
    }
    let mut x = String::from("<results>\n");
    for (sec, items) in sections {
        let _ = writeln!(x, "  <{sec}>");
        for (k, v) in items {
            let (_, unit, short) = reference_meta(k);
            let _ = writeln!(
                x,
                "    <{k}>\n      <section>{sec}</section>\n      <short>{short}</short>\n      <unit>{unit}</unit>\n      <value>{}</value>\n      <uncertainty>{}</uncertainty>\n    </{k}>",
                xml_num(v.value),
                xml_num(v.uncertainty)
            );
        }
        let _ = writeln!(x, "  </{sec}>");
    }
    x.push_str("</results>\n");
    x
}

fn xml_num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:e}")
    } else {
        "nan".into()
    }
}

/// Writes datasheet.json, results.xml, the figures and report.html.
fn write_outputs(r: &Emva1288Report, out: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(out).map_err(|e| CliError::output(out, e))?;
    let p = out.join("datasheet.json");
    let json = serde_json::to_string_pretty(r).map_err(|e| CliError::output(&p, e))?;
    std::fs::write(&p, json).map_err(|e| CliError::output(&p, e))?;
    let p = out.join("results.xml");
    std::fs::write(&p, results_xml(&r.values)).map_err(|e| CliError::output(&p, e))?;
    let figs = write_figures(r, out)?;
    let p = out.join("report.html");
    std::fs::write(&p, report_html(r, &figs)).map_err(|e| CliError::output(&p, e))?;
    Ok(())
}

fn write_figures(r: &Emva1288Report, out: &Path) -> Result<Vec<(String, String)>, CliError> {
    let t = &r.temporal;
    let mut figs = Vec::new();
    let below = |i: usize| i <= t.saturation_index;
    let pts = &r.points;
    let k = t.system_gain_dn_per_e.slope;
    // Photon transfer.
    let ptc: Vec<(f64, f64)> = pts
        .iter()
        .map(|p| (p.signal_dn(), p.signal_var_dn2()))
        .collect();
    let fit: Vec<(f64, f64)> = pts[..=t.fit_end_index]
        .iter()
        .map(|p| (p.signal_dn(), k * p.signal_dn()))
        .collect();
    plots::line_plot(
        &out.join("photon_transfer.png"),
        "Photon transfer",
        &[
            ("σ²_y − σ²_y.dark".into(), ptc),
            (format!("fit K = {k:.4} DN/e⁻"), fit),
        ],
        ("μ_y − μ_y.dark (DN)", "σ²_y − σ²_y.dark (DN²)"),
    )?;
    figs.push((
        "photon_transfer.png".into(),
        "Photon transfer: the slope is K".into(),
    ));
    // SNR against photons, with the model curve.
    let eta = t.quantum_efficiency.value;
    let sd = t.dark_noise_e.value;
    let snr: Vec<(f64, f64)> = pts
        .iter()
        .enumerate()
        .filter(|(i, p)| below(*i) && p.photons_per_pixel > 0.0)
        .map(|(_, p)| {
            (
                p.photons_per_pixel.log10(),
                (p.signal_dn() / p.bright.var_dn2.sqrt()).max(1e-3).log10(),
            )
        })
        .collect();
    let model: Vec<(f64, f64)> = snr
        .iter()
        .map(|&(x, _)| (x, snr_model(10f64.powf(x), eta, sd, k).log10()))
        .collect();
    plots::line_plot(
        &out.join("snr.png"),
        "SNR",
        &[("measured".into(), snr), ("model".into(), model)],
        ("log10 μ_p (photons)", "log10 SNR"),
    )?;
    figs.push((
        "snr.png".into(),
        "SNR against irradiation, with the model curve".into(),
    ));
    // Linearity and deviation.
    let resp: Vec<(f64, f64)> = pts
        .iter()
        .map(|p| (p.photons_per_pixel, p.signal_dn()))
        .collect();
    plots::line_plot(
        &out.join("linearity.png"),
        "Linearity",
        &[("μ_y − μ_y.dark".into(), resp)],
        ("μ_p (photons)", "μ_y − μ_y.dark (DN)"),
    )?;
    figs.push(("linearity.png".into(), "Response (linearity)".into()));
    if let Some(l) = &t.linearity {
        let dev: Vec<(f64, f64)> = pts
            .iter()
            .zip(&l.deviation_percent)
            .enumerate()
            .filter(|(i, _)| *i >= l.range.0 && *i <= l.range.1)
            .map(|(_, (p, d))| (p.photons_per_pixel, *d))
            .collect();
        plots::line_plot(
            &out.join("deviation_linearity.png"),
            "Deviation from linearity",
            &[("δ_y".into(), dev)],
            ("μ_p (photons)", "deviation (%)"),
        )?;
        figs.push((
            "deviation_linearity.png".into(),
            "Deviation from linearity (5–95 %)".into(),
        ));
    }
    // Dark mean and variance against exposure time.
    let dm: Vec<(f64, f64)> = pts
        .iter()
        .map(|p| (p.exposure_s * 1e3, p.dark.mean_dn))
        .collect();
    let dv: Vec<(f64, f64)> = pts
        .iter()
        .map(|p| (p.exposure_s * 1e3, p.dark.var_dn2))
        .collect();
    plots::line_plot(
        &out.join("dark_mean.png"),
        "Dark signal against exposure time",
        &[("μ_y.dark".into(), dm)],
        ("exposure (ms)", "μ_y.dark (DN)"),
    )?;
    plots::line_plot(
        &out.join("dark_variance.png"),
        "Dark variance against exposure time",
        &[("σ²_y.dark".into(), dv)],
        ("exposure (ms)", "σ²_y.dark (DN²)"),
    )?;
    figs.push(("dark_mean.png".into(), "Dark current from the mean".into()));
    figs.push((
        "dark_variance.png".into(),
        "Dark current from the variance".into(),
    ));
    if let Some(s) = &r.spatial {
        let signal = s.bright.mean_dn - s.dark.mean_dn;
        for (name, title, dsnu, spec) in [
            (
                "spectrogram_dsnu_h.png",
                "Horizontal spectrogram DSNU",
                true,
                &s.dsnu_spectrogram_h,
            ),
            (
                "spectrogram_dsnu_v.png",
                "Vertical spectrogram DSNU",
                true,
                &s.dsnu_spectrogram_v,
            ),
            (
                "spectrogram_prnu_h.png",
                "Horizontal spectrogram PRNU",
                false,
                &s.prnu_spectrogram_h,
            ),
            (
                "spectrogram_prnu_v.png",
                "Vertical spectrogram PRNU",
                false,
                &s.prnu_spectrogram_v,
            ),
        ] {
            let dark_spec = if name.ends_with("_h.png") {
                &s.dsnu_spectrogram_h
            } else {
                &s.dsnu_spectrogram_v
            };
            let ser: Vec<(f64, f64)> = spec
                .frequency_per_px
                .iter()
                .zip(&spec.power_dn2)
                .zip(&dark_spec.power_dn2)
                .skip(1)
                .map(|((f, p), pd)| {
                    if dsnu {
                        (*f, p.sqrt() / k)
                    } else {
                        (*f, 100.0 * (p - pd).max(0.0).sqrt() / signal)
                    }
                })
                .collect();
            let unit = if dsnu { "DSNU (e⁻)" } else { "PRNU (%)" };
            plots::line_plot(
                &out.join(name),
                title,
                &[(unit.into(), ser)],
                ("frequency (cycles/pixel)", unit),
            )?;
            figs.push((name.into(), title.into()));
        }
        for (name, title, h, unit) in [
            (
                "histogram_dsnu.png",
                "DSNU histogram",
                &s.dsnu_histogram_e,
                "dark signal − mean (e⁻)",
            ),
            (
                "histogram_prnu.png",
                "PRNU histogram (5×5 high-pass)",
                &s.prnu_histogram_percent,
                "deviation (%)",
            ),
        ] {
            let ser: Vec<(f64, f64)> = h
                .bin_lower
                .iter()
                .zip(&h.counts)
                .map(|(b, c)| (*b, (*c as f64 + 1.0).log10()))
                .collect();
            plots::line_plot(
                &out.join(name),
                title,
                &[("log10(1 + count)".into(), ser)],
                (unit, "log10(1 + pixels)"),
            )?;
            figs.push((name.into(), title.into()));
        }
    }
    Ok(figs)
}

fn report_html(r: &Emva1288Report, figs: &[(String, String)]) -> String {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>EMVA 1288 datasheet</title>");
    h.push_str("<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}figure{display:inline-block;margin:8px;vertical-align:top}figure img{max-width:520px;border:1px solid #ccc}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}</style></head><body>");
    let _ = write!(
        h,
        "<h1>EMVA 1288 datasheet</h1><p>Release 4.0 Linear, computed by camsim from {} ({} bit).</p>",
        html_escape(&r.source),
        r.bits
    );
    if let Some(s) = &r.setup {
        let _ = write!(
            h,
            "<p>Simulated series: channel {}, {:.1} nm, {:.4e} µW/cm², {}×{} pixels, pixel area {:.3} µm², spatial stacks of {} frames at {:.3} ms, seed {}.</p>",
            html_escape(&s.channel), s.wavelength_nm, s.irradiance_uw_per_cm2, s.rows, s.cols, s.pixel_area_um2, s.spatial_frames, s.spatial_exposure_s * 1e3, s.seed
        );
    }
    h.push_str("<table><tr><th>quantity</th><th>symbol (emva1288 name)</th><th>value</th><th>uncertainty</th><th>unit</th></tr>");
    for (k, v) in &r.values {
        let (_, unit, short) = reference_meta(k);
        let u = if v.uncertainty.is_finite() {
            format!("{:.4e}", v.uncertainty)
        } else {
            "–".into()
        };
        let _ = write!(
            h,
            "<tr><td style=\"text-align:left\">{}</td><td>{}</td><td>{:.6e}</td><td>{u}</td><td>{}</td></tr>",
            html_escape(short),
            html_escape(k),
            v.value,
            html_escape(unit)
        );
    }
    h.push_str("</table>");
    if let Some(c) = &r.configured {
        let _ = write!(
            h,
            "<h2>Configured camera</h2><table><tr><th>η</th><th>K (DN/e⁻)</th><th>σ_d (e⁻, read noise)</th><th>μ_e.sat (e⁻)</th><th>dark current (e⁻/s)</th><th>DSNU (e⁻)</th><th>PRNU (%)</th></tr><tr><td>{:.4}</td><td>{:.5}</td><td>{:.3}</td><td>{:.1}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td></tr></table>",
            c.quantum_efficiency, c.system_gain_dn_per_e, c.dark_noise_e, c.saturation_e, c.dark_current_e_per_s, c.dsnu_e, c.prnu_percent
        );
    }
    h.push_str("<h2>Plots</h2>");
    for (f, cap) in figs {
        let _ = write!(
            h,
            "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
            html_escape(f),
            html_escape(cap),
            html_escape(cap)
        );
    }
    h.push_str("</body></html>\n");
    h
}

/// One block of a descriptor file: a bright (`b exposure_ns photons`) or dark
/// (`d exposure_ns`) point and its image files.
#[derive(Debug, Clone, PartialEq)]
pub struct DescriptorBlock {
    /// Exposure time (s).
    pub exposure_s: f64,
    /// Photons per pixel (0 for dark).
    pub photons_per_pixel: f64,
    /// Image paths (resolved against the descriptor's folder).
    pub images: Vec<PathBuf>,
}

/// A parsed descriptor file.
#[derive(Debug, Clone, PartialEq)]
pub struct Descriptor {
    /// ADC bits.
    pub bits: u32,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Blocks in file order.
    pub blocks: Vec<DescriptorBlock>,
}

/// Parses the reference implementation's descriptor format: `#` comments, `v version`,
/// `n bits width height`, `b exposure_ns photons` / `d exposure_ns` each followed by
/// `i relative/path` lines (2 images = a photon-transfer pair, more = a spatial stack;
/// `\` separators accepted).
pub fn parse_descriptor(path: &Path) -> Result<Descriptor, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::input(path, format!("cannot read: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut fmt: Option<(u32, usize, usize)> = None;
    let mut blocks: Vec<DescriptorBlock> = Vec::new();
    let num = |s: &str, line: usize, what: &str| -> Result<f64, CliError> {
        s.replace(',', ".")
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| {
                CliError::input(
                    path,
                    format!("line {line}: {what} \"{s}\" is not a number ≥ 0"),
                )
            })
    };
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        let ln = i + 1;
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        match f[0] {
            "v" => {}
            "n" => {
                if f.len() != 4 {
                    return Err(CliError::input(
                        path,
                        format!("line {ln}: expected \"n bits width height\", got \"{line}\""),
                    ));
                }
                let p = |s: &str| s.parse::<usize>().ok().filter(|&v| v > 0);
                match (p(f[1]), p(f[2]), p(f[3])) {
                    (Some(b), Some(w), Some(h)) if b <= 16 => fmt = Some((b as u32, w, h)),
                    _ => {
                        return Err(CliError::input(
                            path,
                            format!(
                                "line {ln}: \"{line}\": bits must be 1–16, width and height ≥ 1"
                            ),
                        ))
                    }
                }
            }
            "b" | "d" => {
                let want = if f[0] == "b" { 3 } else { 2 };
                if f.len() != want {
                    return Err(CliError::input(
                        path,
                        format!(
                            "line {ln}: expected \"{}\", got \"{line}\"",
                            if want == 3 {
                                "b exposure_ns photons"
                            } else {
                                "d exposure_ns"
                            }
                        ),
                    ));
                }
                let t = num(f[1], ln, "exposure")? * 1e-9;
                let p = if want == 3 {
                    num(f[2], ln, "photon count")?
                } else {
                    0.0
                };
                blocks.push(DescriptorBlock {
                    exposure_s: t,
                    photons_per_pixel: p,
                    images: Vec::new(),
                });
            }
            "i" => {
                let Some(b) = blocks.last_mut() else {
                    return Err(CliError::input(
                        path,
                        format!("line {ln}: image line before any \"b\" or \"d\" line"),
                    ));
                };
                if f.len() != 2 {
                    return Err(CliError::input(
                        path,
                        format!("line {ln}: expected \"i path\", got \"{line}\""),
                    ));
                }
                b.images.push(dir.join(f[1].replace('\\', "/")));
            }
            other => {
                return Err(CliError::input(
                    path,
                    format!("line {ln}: unknown command \"{other}\""),
                ))
            }
        }
    }
    let (bits, width, height) =
        fmt.ok_or_else(|| CliError::input(path, "no \"n bits width height\" line"))?;
    if let Some(b) = blocks.iter().find(|b| b.images.len() < 2) {
        return Err(CliError::input(
            path,
            format!(
                "the block at {} ns has {} image(s); at least 2 are needed",
                b.exposure_s * 1e9,
                b.images.len()
            ),
        ));
    }
    Ok(Descriptor {
        bits,
        width,
        height,
        blocks,
    })
}

/// Reads an 8- or 16-bit greyscale image as DN (values as stored, not rescaled) into `dn`
/// (resized; its capacity is reused). A 16-bit PNG of stored deflate blocks, as camsim writes
/// them, is read by [`decode_stored_gray16`] from the file's bytes (held in a per-thread
/// buffer that is reused too); any other image goes to the general decoder.
fn read_gray_into(path: &Path, d: &Descriptor, dn: &mut Vec<u16>) -> Result<(), CliError> {
    thread_local! {
        static FILE_BYTES: std::cell::Cell<Vec<u8>> = const { std::cell::Cell::new(Vec::new()) };
    }
    let cannot =
        |e: &dyn std::fmt::Display| CliError::input(path, format!("cannot read image: {e}"));
    // Taken out of the thread's slot for the duration, so no borrow is held.
    let mut bytes = FILE_BYTES.take();
    bytes.clear();
    let read = std::fs::File::open(path).and_then(|mut f| {
        use std::io::Read;
        f.read_to_end(&mut bytes)
    });
    let fast = match read {
        Ok(_) => decode_stored_gray16(&bytes, dn),
        Err(e) => {
            FILE_BYTES.set(bytes);
            return Err(cannot(&e));
        }
    };
    FILE_BYTES.set(bytes);
    let (w, h) = match fast {
        Some(size) => size,
        None => {
            let img = image::open(path).map_err(|e| cannot(&e))?;
            let size = (img.width() as usize, img.height() as usize);
            match img {
                image::DynamicImage::ImageLuma8(b) => {
                    dn.clear();
                    dn.extend(b.as_raw().iter().map(|&v| u16::from(v)));
                }
                image::DynamicImage::ImageLuma16(b) => {
                    dn.clear();
                    dn.extend_from_slice(b.as_raw());
                }
                _ => {
                    return Err(CliError::input(
                        path,
                        "expected a single-channel 8- or 16-bit image",
                    ))
                }
            }
            size
        }
    };
    if (w, h) != (d.width, d.height) {
        return Err(CliError::input(
            path,
            format!(
                "image is {w}×{h}, the descriptor says {}×{}",
                d.width, d.height
            ),
        ));
    }
    let max = ((1u32 << d.bits) - 1) as u16;
    // Any bit above the range shows in the OR of all values (vectorises, unlike a search).
    if dn.iter().fold(0u16, |a, &v| a | v) & !max != 0 {
        if let Some(v) = dn.iter().find(|&&v| v > max) {
            return Err(CliError::input(
                path,
                format!("value {v} DN exceeds the descriptor's {}-bit range", d.bits),
            ));
        }
    }
    Ok(())
}

/// Frames of a spatial stack read (in parallel) and added to the sums at a time: 8 frames of
/// a 1 MP sensor are 16 MB of buffers.
const STACK_CHUNK: usize = 8;

/// Analyses the series of a descriptor file (`camsim calibrate --emva1288`) and writes the
/// same outputs as `camsim emva1288` into `out`.
pub fn run_descriptor(path: &Path, out: &Path) -> Result<Emva1288Report, CliError> {
    let d = parse_descriptor(path)?;
    let mut b = SeriesBuilder {
        bright: Vec::new(),
        dark: Vec::new(),
        stack_bright: None,
        stack_dark: None,
    };
    // The temporal pairs, read and reduced in parallel (each pair's statistics are computed
    // alone, so the result does not depend on the thread count).
    let pair_stats_by_block: Vec<Option<_>> = d
        .blocks
        .par_iter()
        .map(|blk| -> Result<Option<_>, CliError> {
            if blk.images.len() != 2 {
                return Ok(None);
            }
            thread_local! {
                static PAIR: std::cell::Cell<[Vec<u16>; 2]> =
                    const { std::cell::Cell::new([Vec::new(), Vec::new()]) };
            }
            let [mut a, mut c] = PAIR.take();
            let read = read_gray_into(&blk.images[0], &d, &mut a)
                .and_then(|_| read_gray_into(&blk.images[1], &d, &mut c));
            let stats = read.map(|_| pair_stats(&a, &c));
            PAIR.set([a, c]);
            Ok(Some(stats?))
        })
        .collect::<Vec<_>>()
        .into_iter()
        .collect::<Result<_, CliError>>()?; // the first error in file order
    for (blk, stats) in d.blocks.iter().zip(pair_stats_by_block) {
        if let Some(s) = stats {
            if blk.photons_per_pixel == 0.0 {
                b.dark.push((blk.exposure_s, s));
            } else {
                b.bright.push((blk.exposure_s, blk.photons_per_pixel, s));
            }
        } else {
            // Frames are read in parallel a chunk at a time into reused buffers, then the
            // chunk is added to the sums (integer sums: the order does not matter).
            let mut acc = StackAccumulator::new(d.height, d.width);
            let mut buffers: Vec<Vec<u16>> = vec![Vec::new(); STACK_CHUNK.min(blk.images.len())];
            for chunk in blk.images.chunks(STACK_CHUNK) {
                // The first error in file order, whatever the scheduling.
                let read: Vec<Result<(), CliError>> = buffers
                    .par_iter_mut()
                    .zip(chunk.par_iter())
                    .map(|(buf, p)| read_gray_into(p, &d, buf))
                    .collect();
                read.into_iter().collect::<Result<(), CliError>>()?;
                let frames: Vec<&[u16]> = buffers[..chunk.len()]
                    .iter()
                    .map(|b| b.as_slice())
                    .collect();
                acc.add_frames(&frames)
                    .map_err(|e| CliError::input(&chunk[0], e))?;
            }
            let slot = if blk.photons_per_pixel == 0.0 {
                &mut b.stack_dark
            } else {
                &mut b.stack_bright
            };
            if slot.is_some() {
                return Err(CliError::input(
                    path,
                    "more than one bright or dark spatial stack",
                ));
            }
            *slot = Some(acc);
        }
    }
    // With a single exposure time (irradiance series) every bright point uses that dark pair.
    let report =
        analyse(&b, &path.display().to_string(), d.bits).map_err(|e| CliError::input(path, e))?;
    write_outputs(&report, out)?;
    Ok(report)
}
