//! The one chain of camsim: scene → irradiance → electrons → frame → image → display, for the
//! shots of a capture set. Every command (`run`, `simulate`, `validate`, `scene`, `demo`,
//! `study`, `diagnose`) goes through these functions; none chains the stages itself.
//!
//! | step | function | stage call |
//! |---|---|---|
//! | scene radiance of a shot (field of view, distance, illuminant swap) | [`shot_scene`] | [`camsim_core::scene_view::render_target_in_view`], [`camsim_core::illuminant::swap_illuminant`] |
//! | optics | [`shot_irradiance`], [`irradiance_of`], [`optical_image`] | [`camsim_optics::form_image`]; with `optics.uncropped_optical_image`, [`camsim_optics::form_image_uncropped_window`] |
//! | pixel integration | [`shot_electron_rate`] | [`camsim_sensor::electron_rate`] |
//! | exposure | [`shot_exposure`] | [`camsim_sensor::auto_exposure_s`] |
//! | time within the exposure (rolling shutter, PWM light, motion) | [`shot_time_rate`] | [`camsim_sensor::time_averaged_rate`] |
//! | expected frame (DN) | [`expected_frame`] | [`camsim_sensor::expected_dn`] |
//! | noisy frame (DN) | [`simulate_frame`] | [`camsim_sensor::expose_with`] |
//! | HDR readouts (split pixel, DCG, bracketing; DN) | [`hdr_model`], [`hdr_readout_models`], [`simulate_hdr_frame`] | [`camsim_sensor::expose_hdr`] |
//! | HDR merge (linear exposure, e⁻) | [`merge_hdr`] | [`camsim_isp::hdr_merge()`] |
//! | contrast autofocus (lens position of the sharpest region) | [`crate::autofocus::contrast_autofocus`] | the steps above per position |
use crate::config::{Camera, CaptureSet, Exposure};
use crate::error::CliError;
use camsim_core::image::{Plane, RawFrame, SceneRadiance, SensorIrradiance};
use camsim_core::spectrum::WavelengthGrid;
use camsim_sensor::{
    ElectronRate, HdrFrame, HdrModel, HdrReadoutModel, PatternSource, SensorModel, Shot, TimeModel,
};
use std::borrow::Cow;

pub use crate::simulate::{
    sampling_for, shot_electron_rate, shot_irradiance, shot_scene, wavelength_grid,
};

/// The optics stage of the set's camera applied to a scene that does not come from a shot's
/// target (a glTF render, an image): [`optical_image`] with the sensor as the scene image.
pub fn irradiance_of(
    set: &CaptureSet,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<SensorIrradiance, CliError> {
    optical_image(set, scene, grid, None)
}

/// The optics stage: scene radiance (on the simulation grid: the sensor plus its margin) →
/// sensor irradiance on the same grid.
///
/// * Default (`optics.uncropped_optical_image` false, the spec's optics):
///   [`camsim_optics::form_image`] of the whole grid.
/// * `optics.uncropped_optical_image: true` (ISETCam `oiCompute` with `crop = false`, issue 17
///   §4): the scene image is the part of the grid the target covers, `extent_m` = (W, H) in
///   the image plane (a target with `fov_deg`; `None`: the target fills the sensor, the scene
///   image is the sensor), widened to whole samples ([`camsim_optics::centred_window`]). Its
///   optical image is formed ISETCam's way — zero-padded by round(n/8) each side, FFT blur,
///   the padded ring kept — and placed back on the grid
///   ([`camsim_optics::form_image_uncropped_window`]), so a sensor larger than the scene
///   image reads the blurred ring of light around it and zero beyond.
pub fn optical_image(
    set: &CaptureSet,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
    extent_m: Option<(f64, f64)>,
) -> Result<SensorIrradiance, CliError> {
    let optics = &set.camera.optics;
    let result = if set.camera.uncropped_optical_image {
        let s = &set.camera.sensor;
        let (w, h) = extent_m.unwrap_or((
            s.cols as f64 * s.pixel_pitch_m,
            s.rows as f64 * s.pixel_pitch_m,
        ));
        let dx = scene.sample_pitch_m;
        let (r0, r1) = camsim_optics::centred_window(scene.radiance.rows, h / dx);
        let (c0, c1) = camsim_optics::centred_window(scene.radiance.cols, w / dx);
        camsim_optics::form_image_uncropped_window(optics, scene, grid, r1 - r0, c1 - c0)
    } else {
        camsim_optics::form_image(optics, scene, grid)
    };
    result.map_err(|e| CliError::input(&set.camera_path, format!("optics: {e}")))
}

/// The exposure and gain of shot `shot_index`: its fixed exposure, or the auto exposure that
/// puts the brightest channel mean at the stated fraction of full scale for `rate`.
pub fn shot_exposure(set: &CaptureSet, shot_index: usize, rate: &ElectronRate) -> Shot {
    let shot = &set.shots[shot_index];
    let exposure_s = match shot.exposure {
        Exposure::Fixed(t) => t,
        Exposure::Auto(f) => camsim_sensor::auto_exposure_s(&set.camera.sensor, rate, f),
    };
    Shot {
        exposure_s,
        analog_gain: shot.analog_gain,
    }
}

/// The time model of shot `shot_index`: the camera's readout with the shot's light
/// modulation and motion.
pub fn shot_time_model(set: &CaptureSet, shot_index: usize) -> TimeModel {
    let shot = &set.shots[shot_index];
    TimeModel {
        readout: set.camera.readout,
        light: shot.light,
        motion: shot.motion,
    }
}

/// The electron rate of shot `shot_index` averaged over each row's exposure window under
/// `shot` (rolling shutter, PWM light, motion: [`camsim_sensor::time_averaged_rate`]); `rate`
/// itself, untouched, when the shot has neither light modulation nor motion.
pub fn shot_time_rate<'a>(
    set: &CaptureSet,
    shot_index: usize,
    rate: &'a ElectronRate,
    shot: &Shot,
) -> Cow<'a, ElectronRate> {
    let model = shot_time_model(set, shot_index);
    if model.is_static() {
        Cow::Borrowed(rate)
    } else {
        Cow::Owned(camsim_sensor::time_averaged_rate(
            &set.camera.sensor,
            rate,
            shot.exposure_s,
            &model,
        ))
    }
}

/// The noise-free expected frame (DN, before quantisation) of `rate` under `shot`.
pub fn expected_frame(sensor: &SensorModel, rate: &ElectronRate, shot: &Shot) -> Plane {
    Plane {
        rows: sensor.rows,
        cols: sensor.cols,
        data: camsim_sensor::expected_dn(sensor, rate, shot),
    }
}

/// One noisy frame (DN as stored) of `rate` under `shot`: fixed patterns from `pattern`, the
/// temporal noise from the stream `(seed, stream)` — the same frame for the same arguments,
/// whatever the thread count.
pub fn simulate_frame(
    sensor: &SensorModel,
    rate: &ElectronRate,
    shot: &Shot,
    pattern: PatternSource<'_>,
    seed: u64,
    stream: &[u64],
) -> RawFrame {
    camsim_sensor::expose_with(sensor, rate, shot, pattern, seed, stream)
}

/// The camera's HDR pixel (`sensor.hdr`), or its standard pixel as a one-readout HDR model
/// ([`HdrModel::standard`]) when it has none.
pub fn hdr_model(camera: &Camera) -> HdrModel {
    camera
        .hdr
        .clone()
        .unwrap_or_else(|| HdrModel::standard(&camera.sensor))
}

/// The noise model of every readout of the camera's HDR pixel under `shot`.
pub fn hdr_readout_models(camera: &Camera, shot: &Shot) -> Vec<HdrReadoutModel> {
    hdr_model(camera).readout_models(&camera.sensor, shot)
}

/// The readouts (DN) of one HDR shot of `rate` ([`camsim_sensor::expose_hdr`]), temporal
/// noise from the stream `(seed, stream)`.
pub fn simulate_hdr_frame(
    camera: &Camera,
    rate: &ElectronRate,
    shot: &Shot,
    seed: u64,
    stream: &[u64],
) -> HdrFrame {
    camsim_sensor::expose_hdr(&camera.sensor, &hdr_model(camera), rate, shot, seed, stream)
}

/// The ISP's HDR merge of `frame` into one linear plane of the exposure (photo-electrons of
/// the camera's pixel; [`camsim_isp::hdr_merge()`]).
pub fn merge_hdr(
    camera_path: &std::path::Path,
    models: &[HdrReadoutModel],
    frame: &HdrFrame,
) -> Result<Plane, CliError> {
    camsim_isp::hdr_merge(frame, models)
        .map_err(|e| CliError::input(camera_path, format!("sensor.hdr: {e}")))
}
