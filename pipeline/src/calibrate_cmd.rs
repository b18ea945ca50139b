//! `camsim calibrate CAPTURES.json --out DIR`: the paper's Appendix A and B estimators and
//! photon transfer on a capture set; writes `fitted_camera.json` (the believed camera with the
//! estimates in place), `calibration.json` (every estimate with its uncertainty, or why it
//! could not be made) and `report.html` with figures.
//!
//! `patches` shots whose patches have known radiance (e.g. a chart lit through narrowband
//! filters, at several exposures) feed Appendix B per patch ([`patch_spectral`]).
pub mod patch_spectral;

use crate::config::CaptureSet;
use crate::error::CliError;
use crate::plots;
use crate::raw_input::read_frame_with;
use crate::report::html_escape;
use crate::staging::with_staging;
use camsim_core::scene::Target;
use camsim_core::spectrum::Spectrum;
use camsim_diagnose::{
    calibrate, CalibrationOptions, CalibrationResult, CalibrationShot, Outcome, ShotKind,
};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Narrowband if the radiance spectrum spans at most this many nm.
const NARROWBAND_MAX_SPAN_NM: f64 = 60.0;

fn shot_kind(t: &Target) -> Option<ShotKind> {
    match t {
        Target::Dark => Some(ShotKind::Dark),
        Target::Uniform { radiance } => {
            let (lo, hi) = radiance.support_nm();
            if hi - lo <= NARROWBAND_MAX_SPAN_NM {
                Some(ShotKind::Narrowband {
                    radiance: radiance.clone(),
                })
            } else {
                Some(ShotKind::Flat {
                    radiance: radiance.clone(),
                })
            }
        }
        _ => None,
    }
}

/// The shots of a capture set as the calibration uses them.
pub struct LoadedShots {
    /// Dark and uniform shots.
    pub shots: Vec<CalibrationShot>,
    /// `patches` shots (for the per-patch spectral fit).
    pub patch_shots: Vec<patch_spectral::PatchShot>,
    /// Shots not used, with the reason.
    pub skipped: Vec<String>,
}

/// Load every frame of the calibration shots (dark, uniform and `patches` targets).
pub fn load_shots(set: &CaptureSet, progress: bool) -> Result<LoadedShots, CliError> {
    let n: usize = set.shots.iter().map(|s| s.frames.len()).sum();
    let bar = crate::progress::bar(
        progress,
        n as u64,
        "{spinner} reading frames [{bar:30}] {pos}/{len}",
    );
    let mut shots = Vec::new();
    let mut patch_shots = Vec::new();
    let mut skipped = Vec::new();
    for s in &set.shots {
        let kind = shot_kind(&s.target.target);
        let is_chart = matches!(s.target.target, Target::Patches { .. });
        if kind.is_none() && !is_chart {
            skipped.push(format!(
                "{}: not a dark, uniform or patches target, not used for calibration",
                s.id
            ));
            continue;
        }
        let exposure_s = match s.exposure {
            crate::config::Exposure::Fixed(t) => t,
            crate::config::Exposure::Auto(_) => {
                skipped.push(format!(
                    "{}: auto_exposure has no known exposure time, not used",
                    s.id
                ));
                continue;
            }
        };
        let mut frames = Vec::with_capacity(s.frames.len());
        for f in &s.frames {
            let path = set.dir.join(f);
            let mut frame = read_frame_with(&path, set.raw_format.as_ref())?;
            // a frame of the wrong size is one clear error (as in validate and diagnose): it
            // is not a recording of this camera
            let sensor = &set.camera.sensor;
            if (frame.rows, frame.cols) != (sensor.rows, sensor.cols) {
                return Err(CliError::input(
                    &path,
                    format!(
                        "frame is {}×{} but the camera's sensor is {}×{} (shot {})",
                        frame.rows, frame.cols, sensor.rows, sensor.cols, s.id
                    ),
                ));
            }
            // PNG/TIFF containers hold DN as stored: check they fit the camera's ADC
            let max_dn = (1u32 << set.camera.sensor.adc_bits) - 1;
            if let Some(v) = frame.dn.iter().find(|&&v| v as u32 > max_dn) {
                return Err(CliError::input(
                    &path,
                    format!(
                        "value {v} DN exceeds the camera's {}-bit ADC range (max {max_dn})",
                        set.camera.sensor.adc_bits
                    ),
                ));
            }
            frame.adc_bits = set.camera.sensor.adc_bits;
            frames.push(frame);
            bar.inc(1);
        }
        match (kind, &s.target.target) {
            (Some(kind), _) => shots.push(CalibrationShot {
                id: s.id.clone(),
                kind,
                exposure_s,
                analog_gain: s.analog_gain,
                frames,
            }),
            (
                None,
                Target::Patches {
                    rows,
                    cols,
                    patch_fraction,
                    patches,
                    ..
                },
            ) => patch_shots.push(patch_spectral::PatchShot {
                id: s.id.clone(),
                series_key: s.target_key.clone(),
                exposure_s,
                analog_gain: s.analog_gain,
                frames,
                chart_rows: *rows,
                chart_cols: *cols,
                patch_fraction: *patch_fraction,
                patches: patches.clone(),
                labels: s.target.patch_labels.clone(),
            }),
            (None, _) => {}
        }
    }
    bar.finish_and_clear();
    Ok(LoadedShots {
        shots,
        patch_shots,
        skipped,
    })
}

fn fitted_camera_json(
    camera_path: &Path,
    r: &CalibrationResult,
    chart_qe: Option<&camsim_diagnose::SpectralQe>,
    names: &[String],
) -> Result<Value, CliError> {
    let text = std::fs::read_to_string(camera_path)
        .map_err(|e| CliError::input(camera_path, format!("cannot read: {e}")))?;
    let mut cam: Value = serde_json::from_str(&text)
        .map_err(|e| CliError::input(camera_path, format!("invalid: {e}")))?;
    let s = &mut cam["sensor"];
    let mut set = |k: &str, v: Option<f64>| {
        if let Some(v) = v {
            s[k] = json!(v);
        }
    };
    set("black_level_dn", r.black_level_dn.value());
    set("dark_voltage_v_per_s", r.dark_voltage_v_per_s.value());
    set("read_noise_v", r.read_noise_v.value());
    set("dsnu_sigma_v", r.dsnu_sigma_v.value());
    set("prnu_sigma_percent", r.prnu_sigma_percent.value());
    set("conversion_gain_v_per_e", r.conversion_gain_v_per_e.value());
    set("well_capacity_e", r.full_well_e.value());
    if let Some(q) = r.channel_qe.get().or(chart_qe) {
        for ch in &q.channels {
            if names.contains(&ch.name) {
                cam["sensor"]["channels"][&ch.name] =
                    json!({"wavelength_nm": q.wavelength_nm, "values": ch.qe});
            }
        }
    }
    Ok(cam)
}

fn outcome_row(name: &str, o: &Outcome<camsim_diagnose::Estimate>) -> String {
    match o {
        Outcome::Estimated(e) => format!(
            "<tr><th style=\"text-align:left\">{name}</th><td>{:.6e}</td><td>{:.2e}</td><td>{}</td><td style=\"text-align:left\">{}</td></tr>",
            e.value, e.std_error, e.unit, html_escape(&e.method)
        ),
        Outcome::NotEstimable { reason } => format!("<tr><th style=\"text-align:left\">{name}</th><td colspan=3>not estimable</td><td style=\"text-align:left\">{}</td></tr>", html_escape(reason)),
    }
}

/// What `calibrate` reports: the estimates as typed values, and calibration.json as written.
#[derive(Debug, Clone)]
pub struct CalibrateSummary {
    /// The estimates (value ± standard error, or why not estimable).
    pub result: CalibrationResult,
    /// Shots left out before the analysis, with the reason.
    pub skipped_shots: Vec<String>,
    /// Files written into `--out` (relative paths).
    pub files: Vec<PathBuf>,
    /// calibration.json as written.
    pub json: Value,
}

/// Run the calibration and write its outputs into `out` (all or nothing).
pub fn run_calibrate(
    set: &CaptureSet,
    out: &Path,
    progress: bool,
) -> Result<CalibrateSummary, CliError> {
    let sensor = &set.camera.sensor;
    let LoadedShots {
        shots,
        patch_shots,
        skipped,
    } = load_shots(set, progress)?;
    let o = &set.camera.optics;
    let t550 = o.transmittance.eval(550.0);
    let opts = CalibrationOptions {
        // Camera equation (Eq. 1) on the axis, object at infinity, with T(550 nm).
        irradiance_per_radiance: camsim_optics::camera_equation_factor(o.f_number, 0.0) * t550,
        ..CalibrationOptions::default()
    };
    let result = calibrate(sensor, &shots, &opts);
    let chart =
        patch_spectral::patch_spectral(&patch_shots, sensor, o, &result, &opts.spectral_grid);
    let fitted = fitted_camera_json(
        &set.camera_path,
        &result,
        chart.fit.get().map(|f| &f.qe),
        &sensor.channel_names,
    )?;
    let mut summary = serde_json::to_value(&result).map_err(|e| CliError::Other(e.to_string()))?;
    // the reported uncertainty: value ± σ and the 99 % interval (value ± 2.576 σ)
    for (k, o) in [
        ("black_level_dn", &result.black_level_dn),
        ("dark_voltage_v_per_s", &result.dark_voltage_v_per_s),
        ("read_noise_v", &result.read_noise_v),
        ("dsnu_sigma_v", &result.dsnu_sigma_v),
        ("prnu_sigma_percent", &result.prnu_sigma_percent),
        ("conversion_gain_v_per_e", &result.conversion_gain_v_per_e),
        ("full_well_e", &result.full_well_e),
        ("saturation_dn", &result.saturation_dn),
        ("linearity_error_percent", &result.linearity_error_percent),
    ] {
        if let Some(e) = o.get() {
            summary[k]["interval_99"] = json!(e.interval_99());
        }
    }
    summary["chart_channel_qe"] =
        serde_json::to_value(&chart).map_err(|e| CliError::Other(e.to_string()))?;
    summary["skipped_shots"] = json!(skipped);
    let skipped_shots = skipped.clone();
    summary["fitted_camera"] = json!("fitted_camera.json");
    let files = with_staging(out, |st| {
        let mut files: Vec<PathBuf> = Vec::new();
        let mut put = |n: &str| {
            files.push(PathBuf::from(n));
            st.join(n)
        };
        let p = put("fitted_camera.json");
        std::fs::write(&p, serde_json::to_string_pretty(&fitted).expect("json"))
            .map_err(|e| CliError::output(&p, e))?;
        let p = put("calibration.json");
        std::fs::write(&p, serde_json::to_string_pretty(&summary).expect("json"))
            .map_err(|e| CliError::output(&p, e))?;
        let mut figures: Vec<(String, String)> = Vec::new();
        // photon-transfer curve per channel (unit-gain DN)
        let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
        for ch in &sensor.channel_names {
            let mut pts: Vec<(f64, f64)> = result
                .ptc
                .iter()
                .filter(|p| &p.channel == ch)
                .map(|p| (p.unit_gain_mean, p.unit_gain_variance))
                .collect();
            pts.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal));
            if pts.len() >= 2 {
                series.push((format!("channel {ch}"), pts));
            }
        }
        if !series.is_empty() {
            plots::line_plot(
                &put("photon_transfer.png"),
                "Photon transfer: temporal variance vs mean",
                &series,
                ("mean signal (DN, unit gain)", "variance (DN²)"),
            )?;
            figures.push((
                "photon_transfer.png".into(),
                "Photon-transfer curve (EMVA 1288): slope = conversion gain in DN per electron"
                    .into(),
            ));
        }
        // dark signal vs exposure
        let mut dark: Vec<(f64, f64)> = shots
            .iter()
            .filter(|s| matches!(s.kind, ShotKind::Dark) && !s.frames.is_empty())
            .map(|s| {
                let n: usize = s.frames.iter().map(|f| f.dn.len()).sum();
                let m = s
                    .frames
                    .iter()
                    .flat_map(|f| f.dn.iter())
                    .map(|&d| d as f64)
                    .sum::<f64>()
                    / n.max(1) as f64;
                (s.exposure_s, m)
            })
            .collect();
        dark.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal));
        if dark.len() >= 2 {
            plots::line_plot(
                &put("dark_signal.png"),
                "Mean dark signal vs exposure",
                &[("dark shots".into(), dark)],
                ("exposure (s)", "mean dark signal (DN)"),
            )?;
            figures.push((
                "dark_signal.png".into(),
                "Dark signal growth: slope = dark voltage (Appendix A)".into(),
            ));
        }
        // DSNU: histogram of the frame-averaged shortest dark
        if let Some(s) = shots
            .iter()
            .filter(|s| matches!(s.kind, ShotKind::Dark) && !s.frames.is_empty())
            .min_by(|a, b| {
                a.exposure_s
                    .partial_cmp(&b.exposure_s)
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
        {
            let n = s.frames.len() as f64;
            let mean: Vec<f64> = (0..s.frames[0].dn.len())
                .map(|i| s.frames.iter().map(|f| f.dn[i] as f64).sum::<f64>() / n)
                .collect();
            plots::histogram(
                &put("dsnu_histogram.png"),
                &format!("Frame-averaged dark ({}), DSNU", s.id),
                &mean,
                40,
                "DN",
            )?;
            figures.push((
                "dsnu_histogram.png".into(),
                "Fixed-pattern offsets: histogram of the frame-averaged shortest dark".into(),
            ));
            let (lo, hi) = mean
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
                    (a.0.min(*v), a.1.max(*v))
                });
            let rgb: Vec<u8> = mean
                .iter()
                .flat_map(|v| {
                    let g = (((v - lo) / (hi - lo).max(1e-12)) * 255.0).round() as u8;
                    [g, g, g]
                })
                .collect();
            plots::rgb8_png(
                &put("dsnu_map.png"),
                &rgb,
                s.frames[0].rows,
                s.frames[0].cols,
            )?;
            figures.push((
                "dsnu_map.png".into(),
                "DSNU map (frame-averaged shortest dark, stretched)".into(),
            ));
        }
        // QE curves with ±1σ bands
        if let Some(q) = result.channel_qe.get() {
            let mut series = Vec::new();
            for ch in &q.channels {
                let pts = |k: f64| {
                    q.wavelength_nm
                        .iter()
                        .zip(ch.qe.iter().zip(&ch.std_error))
                        .map(|(w, (v, e))| (*w, v + k * e))
                        .collect::<Vec<_>>()
                };
                series.push((format!("{} fitted", ch.name), pts(0.0)));
                series.push((format!("{} ±1σ", ch.name), pts(1.0)));
                series.push((format!("{} −1σ", ch.name), pts(-1.0)));
            }
            plots::line_plot(
                &put("spectral_qe.png"),
                "Channel spectral QE (Appendix B)",
                &series,
                ("wavelength (nm)", "QE (electrons / photon)"),
            )?;
            figures.push((
                "spectral_qe.png".into(),
                "Recovered combined QE per channel with ±1σ bands".into(),
            ));
        }
        // chart (per-patch) spectral efficiencies with ±1σ bands, and the fit per observation
        if let Some(f) = chart.fit.get() {
            let palette = [
                [200u8, 30, 30],
                [20, 140, 40],
                [30, 60, 200],
                [120, 60, 160],
            ];
            let colour = |name: &str, i: usize| match name {
                "r" => palette[0],
                "g" => palette[1],
                "b" => palette[2],
                _ => palette[(i + 3) % palette.len()],
            };
            // plotted relative to the highest efficiency (readable axis whatever the radiance
            // units); calibration.json keeps the absolute values
            let top =
                f.qe.channels
                    .iter()
                    .flat_map(|c| c.qe.iter().copied())
                    .fold(0.0f64, f64::max);
            let top = if top > 0.0 { top } else { 1.0 };
            let series: Vec<plots::BandSeries> = f
                .qe
                .channels
                .iter()
                .enumerate()
                .map(|(i, ch)| plots::BandSeries {
                    name: format!("{} ±1σ", ch.name),
                    colour: colour(&ch.name, i),
                    points: f
                        .qe
                        .wavelength_nm
                        .iter()
                        .zip(ch.qe.iter().zip(&ch.std_error))
                        .map(|(w, (v, e))| (*w, v / top, ((v - e) / top).max(0.0), (v + e) / top))
                        .collect(),
                    dashed: false,
                })
                .collect();
            plots::band_plot(
                &put("chart_spectral_qe.png"),
                "Channel spectral efficiency from chart patches (Appendix B)",
                &series,
                (
                    "wavelength (nm)",
                    &format!("efficiency / {top:.3e} e⁻ per photon"),
                ),
            )?;
            figures.push((
                "chart_spectral_qe.png".into(),
                "Channel efficiencies fitted to the per-patch signal rates, ±1σ".into(),
            ));
            let names: Vec<&str> = f.qe.channels.iter().map(|c| c.name.as_str()).collect();
            let (xs, ys, cs): (Vec<f64>, Vec<f64>, Vec<[u8; 3]>) = f
                .observations
                .iter()
                .map(|o| {
                    let i = names.iter().position(|n| *n == o.channel).unwrap_or(0);
                    (o.predicted, o.signal, colour(&o.channel, i))
                })
                .fold((vec![], vec![], vec![]), |mut a, (x, y, c)| {
                    a.0.push(x);
                    a.1.push(y);
                    a.2.push(c);
                    a
                });
            plots::scatter(
                &put("chart_fit.png"),
                "Patch signal rates: measured vs fitted",
                &xs,
                &ys,
                Some(&cs),
                ("fitted (electrons/s)", "measured (electrons/s)"),
                true,
            )?;
            figures.push((
                "chart_fit.png".into(),
                "Every patch × channel × series: measured signal rate against the fitted curves"
                    .into(),
            ));
        }
        // report
        let mut h = String::from("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>camsim calibration</title><style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}figure{display:inline-block;margin:8px;vertical-align:top}figure img{max-width:520px;border:1px solid #ccc}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}</style></head><body>");
        h.push_str(&format!("<h1>camsim calibrate</h1><p>Capture set: {}</p><h2>Estimates</h2><table><tr><th>quantity</th><th>value</th><th>1σ</th><th>unit</th><th>method / reason</th></tr>", html_escape(&set.path.display().to_string())));
        for (name, o) in [
            ("black level", &result.black_level_dn),
            ("dark voltage", &result.dark_voltage_v_per_s),
            ("read noise", &result.read_noise_v),
            ("DSNU σ", &result.dsnu_sigma_v),
            ("PRNU σ", &result.prnu_sigma_percent),
            ("conversion gain", &result.conversion_gain_v_per_e),
            ("full well", &result.full_well_e),
            ("saturation", &result.saturation_dn),
            ("linearity error", &result.linearity_error_percent),
        ] {
            h.push_str(&outcome_row(name, o));
        }
        h.push_str("</table>");
        match &chart.fit {
            Outcome::Estimated(f) => {
                h.push_str(&format!(
                    "<h2>Chart spectral efficiency</h2><p>{} observations in {} series; {}</p><table><tr><th>channel</th><th>CV weight α</th><th>CV χ²/observation</th></tr>",
                    f.observations.len(),
                    chart.series.len(),
                    html_escape(&f.qe.method)
                ));
                for c in &f.qe.channels {
                    h.push_str(&format!(
                        "<tr><th>{}</th><td>{:.1e}</td><td>{:.2}</td></tr>",
                        html_escape(&c.name),
                        c.alpha,
                        c.cv_chi2_per_shot
                    ));
                }
                h.push_str(&format!(
                    "</table><p>Pedestal {:.3} ± {:.3} DN ({}); median intercept of the patch lines: {}</p>",
                    chart.pedestal_dn,
                    chart.pedestal_sigma_dn,
                    html_escape(&chart.pedestal_source),
                    chart
                        .median_intercept_dn
                        .map(|v| format!("{v:.3} DN"))
                        .unwrap_or_else(|| "—".into())
                ));
            }
            Outcome::NotEstimable { reason } if !patch_shots.is_empty() => {
                h.push_str(&format!(
                    "<h2>Chart spectral efficiency</h2><p>not estimable: {}</p>",
                    html_escape(reason)
                ));
            }
            _ => {}
        }
        for n in &chart.notes {
            h.push_str(&format!("<p>Chart: {}</p>", html_escape(n)));
        }
        if let Some(hp) = result.hot_pixels.get() {
            h.push_str(&format!(
                "<p>Hot pixels: {} above {:.3e} ({})</p>",
                hp.pixels.len(),
                hp.threshold,
                html_escape(&hp.quantity)
            ));
        }
        for r in &result.rejected_shots {
            h.push_str(&format!(
                "<p>Rejected shot {}: {}</p>",
                html_escape(&r.id),
                html_escape(&r.reason)
            ));
        }
        for s in &skipped {
            h.push_str(&format!("<p>Skipped: {}</p>", html_escape(s)));
        }
        h.push_str("<h2>Figures</h2>");
        for (f, c) in &figures {
            h.push_str(&format!(
                "<figure><img src=\"{f}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>"
            ));
        }
        h.push_str("</body></html>\n");
        let p = put("report.html");
        std::fs::write(&p, h).map_err(|e| CliError::output(&p, e))?;
        Ok(files)
    })?;
    Ok(CalibrateSummary {
        result,
        skipped_shots,
        files,
        json: summary,
    })
}

/// Convenience for tests: the spectrum of a uniform target.
pub fn uniform_radiance(t: &Target) -> Option<&Spectrum> {
    match t {
        Target::Uniform { radiance } => Some(radiance),
        _ => None,
    }
}
