//! `camsim simulate`: the baseline forward model of ../spec/capture-format.md applied to every
//! shot of a capture set: target → SceneRadiance → optics → SensorIrradiance → sensor →
//! frames (or, with `--expected`, the noise-free expected image per shot).
use crate::config::{CaptureSet, Exposure};
use crate::error::CliError;
use crate::frames;
use camsim_core::constants::SI;
use camsim_core::exr_io::write_single_channel_exr;
use camsim_core::image::{Plane, SceneRadiance, SensorIrradiance};
use camsim_core::scene::{render_target, scale_to_mean_luminance, SamplingGrid};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_optics::{form_image, Blur, OpticsModel};
use camsim_sensor::{electron_rate, expected_dn, expose, fixed_pattern, ElectronRate, SensorModel, Shot};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Options of one `simulate` run.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    /// Output folder.
    pub out_dir: PathBuf,
    /// Seed of every random term.
    pub seed: u64,
    /// Write expected images instead of frames.
    pub expected: bool,
    /// Show a progress bar (on a terminal).
    pub progress: bool,
}

/// What a run produced.
#[derive(Debug, Clone, Default)]
pub struct SimulateSummary {
    /// Files written (relative to the output folder).
    pub files: Vec<PathBuf>,
    /// Exposure used per shot (s).
    pub exposures_s: Vec<(String, f64)>,
}

/// Wavelength grid for wavelength-dependent optics: the configured one, or 10 nm steps over
/// the channels' spectral support clipped to 350–1100 nm (400–700 nm if unbounded).
pub fn wavelength_grid(set: &CaptureSet) -> WavelengthGrid {
    if let Some(g) = &set.simulation.wavelength_nm {
        return WavelengthGrid::regular(g.start_nm, g.stop_nm, g.step_nm).expect("validated");
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for q in &set.camera.sensor.channel_qe {
        let (a, b) = q.support_nm();
        lo = lo.min(a);
        hi = hi.max(b);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return WavelengthGrid::default_visible();
    }
    let lo = (lo.max(350.0) / 10.0).floor() * 10.0;
    let hi = (hi.min(1100.0) / 10.0).ceil() * 10.0;
    WavelengthGrid::regular(lo, hi.max(lo + 10.0), 10.0).expect("valid grid")
}

/// Scene samples per pixel side and margin (pixels) needed by the optics' blur.
pub fn sampling_for(optics: &OpticsModel, sensor: &SensorModel, grid: &WavelengthGrid, oversample: Option<usize>) -> (usize, usize) {
    let p_um = sensor.pixel_pitch_m * 1e6;
    let lmin_um = grid.wavelength_nm[0] * 1e-3;
    let lmax_um = grid.wavelength_nm[grid.len() - 1] * 1e-3;
    let n = optics.f_number;
    let diffraction_os = (p_um / (0.5 * lmin_um * n)).ceil() as usize;
    let diffraction_margin = (5.0 * lmax_um * n / p_um).ceil() as usize + 2;
    let (os, mut margin) = match &optics.blur {
        Blur::None => (1, 0),
        Blur::Gaussian { sigma_um } => ((p_um / sigma_um.max(1e-9)).ceil() as usize, (4.0 * sigma_um / p_um).ceil() as usize + 1),
        Blur::Pillbox { width_um } => ((2.0 * p_um / width_um).ceil() as usize, (0.5 * width_um / p_um).ceil() as usize + 1),
        Blur::Diffraction | Blur::Psf(_) => (diffraction_os, diffraction_margin),
        Blur::Wavefront { defocus_um, .. } => (diffraction_os, diffraction_margin + (16.0 * defocus_um.abs() * n / p_um).ceil() as usize),
    };
    if let Some(d) = &optics.diffuser {
        margin += (2.0 * d.fwhm_um / p_um).ceil() as usize + 1;
    }
    (oversample.unwrap_or(os.clamp(1, 4)), margin)
}

/// The scene radiance of one shot's target, sampled for the camera's optics (with margin).
pub fn shot_scene(set: &CaptureSet, shot_index: usize, grid: &WavelengthGrid) -> Result<SceneRadiance, CliError> {
    let cam = &set.camera;
    let s = &cam.sensor;
    let shot = &set.shots[shot_index];
    let (os, margin) = sampling_for(&cam.optics, s, grid, set.simulation.oversample);
    let g = SamplingGrid::for_sensor(s.rows, s.cols, s.pixel_pitch_m, os, margin);
    let radiance = render_target(&shot.target.target, &g)
        .map_err(|e| CliError::input(&set.path, format!("shot {}: {e}", shot.id)))?;
    let mut scene = SceneRadiance {
        radiance,
        sample_pitch_m: g.pitch_m,
        object_distance_m: None,
        illuminant: shot.target.illuminant.clone(),
        depth_m: None,
    };
    if let Some(l) = shot.target.mean_luminance_cd_m2 {
        scale_to_mean_luminance(&mut scene, l, Some((g.sensor_width_m, g.sensor_height_m)), &SI);
    }
    Ok(scene)
}

/// Sensor irradiance of one shot (scene → optics stage).
pub fn shot_irradiance(set: &CaptureSet, shot_index: usize, grid: &WavelengthGrid) -> Result<SensorIrradiance, CliError> {
    let scene = shot_scene(set, shot_index, grid)?;
    form_image(&set.camera.optics, &scene, grid).map_err(|e| CliError::input(&set.camera_path, format!("optics: {e}")))
}

/// Mean electron rate of every pixel for one target (optics + pixel integration).
pub fn shot_electron_rate(set: &CaptureSet, shot_index: usize, grid: &WavelengthGrid) -> Result<ElectronRate, CliError> {
    Ok(electron_rate(&set.camera.sensor, &shot_irradiance(set, shot_index, grid)?))
}

/// Run the simulation and write its outputs; on any error nothing is left in the output folder.
pub fn simulate(set: &CaptureSet, opts: &SimulateOptions) -> Result<SimulateSummary, CliError> {
    let sensor = &set.camera.sensor;
    // Recorded frames that exist must fit the sensor (spec: wrong size / bit depth is bad input).
    for shot in &set.shots {
        for f in &shot.frames {
            let p = set.dir.join(f);
            if p.extension().map(|e| e.eq_ignore_ascii_case("png")).unwrap_or(false) && p.exists() {
                frames::check_frame(&p, sensor.rows, sensor.cols)?;
            }
        }
    }
    let out = &opts.out_dir;
    let created_out = !out.exists();
    std::fs::create_dir_all(out).map_err(|e| CliError::output(out, e))?;
    let staging = out.join(format!(".camsim-staging-{}", std::process::id()));
    let result = run_into(set, opts, &staging);
    let result = result.and_then(|summary| {
        for rel in &summary.files {
            let dst = out.join(rel);
            if let Some(parent) = dst.parent() {
                std::fs::create_dir_all(parent).map_err(|e| CliError::output(parent, e))?;
            }
            std::fs::rename(staging.join(rel), &dst).map_err(|e| CliError::output(&dst, e))?;
        }
        Ok(summary)
    });
    let _ = std::fs::remove_dir_all(&staging);
    if result.is_err() && created_out {
        let _ = std::fs::remove_dir_all(out);
    }
    result
}

fn run_into(set: &CaptureSet, opts: &SimulateOptions, staging: &Path) -> Result<SimulateSummary, CliError> {
    let sensor = &set.camera.sensor;
    let grid = wavelength_grid(set);
    let total: u64 = if opts.expected { set.shots.len() as u64 } else { set.shots.iter().map(|s| s.frames.len() as u64).sum() };
    let bar = if opts.progress { ProgressBar::new(total) } else { ProgressBar::hidden() };
    bar.set_style(
        ProgressStyle::with_template("{spinner} simulate [{bar:40}] {pos}/{len} {msg} ({eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let profile = std::env::var_os("CAMSIM_PROFILE").is_some();
    let mut tick = std::time::Instant::now();
    let mut lap = |what: &str| {
        if profile {
            eprintln!("camsim: {what}: {:.3} s", tick.elapsed().as_secs_f64());
            tick = std::time::Instant::now();
        }
    };
    let fixed = fixed_pattern(sensor, opts.seed);
    lap("fixed pattern");
    let mut cache: HashMap<&str, ElectronRate> = HashMap::new();
    let mut summary = SimulateSummary::default();
    std::fs::create_dir_all(staging).map_err(|e| CliError::output(staging, e))?;
    for (si, shot) in set.shots.iter().enumerate() {
        bar.set_message(shot.id.clone());
        if !cache.contains_key(shot.target_key.as_str()) {
            let rate = shot_electron_rate(set, si, &grid)?;
            lap("scene + optics + pixel integration");
            cache.insert(shot.target_key.as_str(), rate);
        }
        let rate = &cache[shot.target_key.as_str()];
        let exposure_s = match shot.exposure {
            Exposure::Fixed(t) => t,
            Exposure::Auto(f) => camsim_sensor::auto_exposure_s(sensor, rate, f),
        };
        summary.exposures_s.push((shot.id.clone(), exposure_s));
        let sh = Shot { exposure_s, analog_gain: shot.analog_gain };
        if opts.expected {
            let dn = expected_dn(sensor, rate, &sh);
            let rel = PathBuf::from(format!("{}.exr", shot.id));
            let plane = Plane { rows: sensor.rows, cols: sensor.cols, data: dn };
            write_single_channel_exr(&staging.join(&rel), "Y", &plane).map_err(|e| CliError::output(&rel, e))?;
            summary.files.push(rel);
            bar.inc(1);
        } else {
            for (fi, f) in shot.frames.iter().enumerate() {
                let frame = expose(sensor, rate, &sh, &fixed, opts.seed, &[si as u64, fi as u64]);
                lap("expose");
                let rel = PathBuf::from(f);
                let dst = staging.join(&rel);
                if let Some(parent) = dst.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| CliError::output(parent, e))?;
                }
                frames::write_png16(&dst, &frame)?;
                lap("write PNG");
                summary.files.push(rel);
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    Ok(summary)
}

/// Used by tests: the photon spectrum of a W spectrum with the baseline constants.
pub fn photons(s: &Spectrum) -> Spectrum {
    s.energy_to_photons(&SI)
}
