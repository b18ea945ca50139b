//! The one chain of camsim: scene → irradiance → electrons → frame → image → display, for the
//! shots of a capture set. Every command (`run`, `simulate`, `validate`, `scene`, `demo`,
//! `study`, `diagnose`) goes through these functions; none chains the stages itself.
//!
//! | step | function | stage call |
//! |---|---|---|
//! | scene radiance of a shot (field of view, distance, illuminant swap) | [`shot_scene`] | [`camsim_core::scene_view::render_target_in_view`], [`camsim_core::illuminant::swap_illuminant`] |
//! | a shot's scene rendered straight onto the sensor channels' planes (whole or grid rows; bit for bit the channel planes of the scene) | [`shot_channel_scene_rows`], [`channel_scene`] | [`camsim_core::scene::render_target_projected_rows`], [`camsim_sensor::channel_weights`] |
//! | grid rows of a shot's scene by themselves (bit for bit the whole scene's rows; the luminance factor from the whole scene or computed by row strips) | [`shot_scene_rows`], [`shot_scene_by_rows`], [`shot_scene_and_factor`], [`shot_scene_luminance_factor`], [`shot_scene_factor_key`] | [`camsim_core::scene_view::render_target_in_view_rows`], [`camsim_core::scene::LuminanceSum`] |
//! | scene radiance of a `gltf` target (path-traced with depth on the shot's grid, cached per scene file and settings; `camsim run`'s `render` section) | [`shot_scene`], [`shot_scene_cached`], [`render_gltf_on_grid`] (camera policy: pinhole when the camera defocuses by depth, else the glTF camera's own) | [`crate::gltf_target::render_gltf_target`] → [`crate::animated::grid_render_job`], [`crate::animated::render_job_radiance`] |
//! | optics | [`shot_irradiance`], [`shot_irradiance_of_scene`] (on a scene kept per [`shot_sampling_grid`]), [`irradiance_of`], [`irradiance_and_blur_of`] (depth-aware for scenes with depth), [`optical_image`] | [`camsim_optics::form_image`]; with `optics.uncropped_optical_image`, [`camsim_optics::form_image_uncropped_window`]; [`camsim_render::depth_optics::defocus_by_depth`] |
//! | pixel integration | [`shot_electron_rate`] | [`camsim_sensor::electron_rate`] |
//! | a band of pixel rows by itself (the optics on the band's scene rows plus margin, at their true field coordinates; the whole field's glare) | [`RowBand`], [`band_core_rows`], [`band_scene_rows`], [`scene_rows`], [`band_irradiance`], [`shot_glare_sums`], [`band_sensor`] | [`camsim_optics::form_image_rows`], [`camsim_optics::glare_sums`] |
//! | pixel optics (`sensor.pixel_optics`: CRA shading, optical crosstalk) | [`apply_pixel_optics`] (inside [`shot_electron_rate`]) | [`camsim_sensor::pixel_optics::apply_pixel_optics`] |
//! | exposure | [`shot_exposure`] | [`camsim_sensor::auto_exposure_s`] |
//! | time within the exposure (rolling shutter, PWM light, motion) | [`shot_time_rate`], [`shot_time_rate_from`] (frame k of a video) | [`camsim_sensor::time_averaged_rate`], [`camsim_sensor::time_averaged_rate_from`] |
//! | an animated glTF scene through each row's window (renders at time nodes → optics → pixels → per-row time integral) | [`animated_shot_rate`] | [`camsim_render::job::prepare_at_time`], [`camsim_sensor::NodeIntegrator`] |
//! | expected frame (DN) | [`expected_frame`] | [`camsim_sensor::expected_dn`] |
//! | noisy frame (DN) | [`simulate_frame`] | [`camsim_sensor::expose_with`] |
//! | frame of a capture set (drift, RTN by frame index; dark current at the shot's temperature) | [`simulate_frame_at`], [`frame_index`], [`shot_sensor`] | [`camsim_sensor::expose_frame`], [`camsim_sensor::dark_voltage_at`] |
//! | HDR readouts (split pixel, DCG, bracketing; DN) | [`hdr_model`], [`hdr_readout_models`], [`simulate_hdr_frame`] | [`camsim_sensor::expose_hdr`] |
//! | HDR merge (linear exposure, e⁻) | [`merge_hdr`] | [`camsim_isp::hdr_merge()`] |
//! | contrast autofocus (lens position of the sharpest region) | [`crate::autofocus::contrast_autofocus`] | the steps above per position |
//! | dual pixel (left/right pupil-half images, half-photodiode readout) | [`dual_pixel_irradiance`], [`dual_pixel_rates`], [`expected_dual_pixel_frames`]; phase-detection AF: [`crate::pdaf::phase_detection_autofocus`] | [`camsim_optics::half_pupil_psf`] (thin lens) or [`camsim_render::depth_path::LensDualPixelDefocus`] (real lens) by depth slab ([`camsim_render::depth_path::defocus_layered_with`]), [`camsim_optics::form_image`], [`camsim_sensor::DualPixel::photodiode_rates`], [`camsim_sensor::expected_dual_pixel_dn`] |
use crate::config::{Camera, CaptureSet, Exposure};
use crate::error::CliError;
use camsim_core::image::{Plane, RawFrame, SceneRadiance, SensorIrradiance};
use camsim_core::spectrum::WavelengthGrid;
use camsim_sensor::{
    ElectronRate, HdrFrame, HdrModel, HdrReadoutModel, PatternSource, SensorModel, Shot, TimeModel,
};
use std::borrow::Cow;
use std::path::Path;

pub use crate::simulate::{
    sampling_for, shot_electron_rate, shot_electron_rate_cached, shot_irradiance,
    shot_irradiance_cached, shot_irradiance_of_scene, shot_sampling_grid, shot_scene,
    shot_scene_and_factor, shot_scene_by_rows, shot_scene_cached, shot_scene_factor_key,
    shot_scene_luminance_factor, shot_scene_rows, wavelength_grid,
};

/// The optics stage of the set's camera applied to a scene that does not come from a shot's
/// target (a glTF render, an image): [`irradiance_and_blur_of`] without the blur map.
pub fn irradiance_of(
    set: &CaptureSet,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<SensorIrradiance, CliError> {
    irradiance_and_blur_of(set, scene, grid).map(|o| o.irradiance)
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
    camera_optical_image(&set.camera, &set.camera_path, scene, grid, extent_m)
}

/// [`optical_image`] for a camera on its own (`camera_path` names its file in errors): what
/// the Python package's stage-by-stage `irradiance` calls.
pub fn camera_optical_image(
    camera: &Camera,
    camera_path: &Path,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
    extent_m: Option<(f64, f64)>,
) -> Result<SensorIrradiance, CliError> {
    let optics = &camera.optics;
    let result = if camera.uncropped_optical_image {
        let s = &camera.sensor;
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
    result.map_err(|e| CliError::input(camera_path, format!("optics: {e}")))
}

/// The optics stage of a shot on its sensor channels' planes: with [`ChannelIrradiance`] the
/// optics act on one plane per CFA channel instead of one per basis term of the scene (25
/// for a colour chart, 33 once split into bands).
pub struct ChannelIrradiance {
    /// Channel index of each irradiance plane.
    pub channels: Vec<usize>,
    /// The irradiance whose plane j is `∫ QE'_c(λ) E(x, λ) dλ` of channel `channels[j]`
    /// (its basis is a placeholder: the planes are spectral integrals already).
    pub irradiance: SensorIrradiance,
}

/// Whether the camera's optics act alike at every wavelength, so that they commute with the
/// spectral sum of pixel integration ([`camsim_sensor::ChannelPlanes`]): the default optics
/// path (not the uncropped ISETCam image), a Gaussian, pillbox or no blur, no lateral colour,
/// a constant transmittance. The camera equation, relative illumination, fall-off,
/// distortion, the diffuser, defocus and veiling glare act on every plane alike.
pub fn optics_alike_at_every_wavelength(camera: &Camera) -> bool {
    use camsim_optics::Blur;
    let o = &camera.optics;
    !camera.uncropped_optical_image
        && matches!(
            o.blur,
            Blur::None | Blur::Gaussian { .. } | Blur::Pillbox { .. }
        )
        && o.effects.lateral_color.is_none()
        && matches!(
            o.transmittance,
            camsim_core::Spectrum::Affine { slope_per_nm, .. } if slope_per_nm == 0.0
        )
}

/// [`shot_irradiance_of_scene`] on the channel planes of `scene` (the same optics stage, on
/// [`camsim_sensor::channel_planes`] of the scene radiance for the camera's sensor) when the
/// optics act alike at every wavelength ([`optics_alike_at_every_wavelength`]) and the scene
/// has no depth; `None` otherwise. The pixel average of plane j, times p²·FF, is the electron
/// rate of channel `channels[j]` ([`camsim_sensor::electron_rate_from_channel_planes`]),
/// equal to [`shot_electron_rate`]'s without pixel optics within f32 rounding (linearity).
pub fn shot_channel_irradiance_of_scene(
    set: &CaptureSet,
    shot_index: usize,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<Option<ChannelIrradiance>, CliError> {
    if scene.depth_m.is_some() || !optics_alike_at_every_wavelength(&set.camera) {
        return Ok(None);
    }
    let (channels, channel_scene) = channel_scene(set, scene)?;
    let irradiance = shot_irradiance_of_scene(set, shot_index, &channel_scene, grid)?;
    Ok(Some(ChannelIrradiance {
        channels,
        irradiance,
    }))
}

/// The scene on the sensor channels' planes ([`camsim_sensor::channel_planes`]: plane j is
/// `∫ QE'_c(λ) L(x, λ) dλ` of channel `channels[j]`), the input of the optics when they act
/// alike at every wavelength ([`shot_channel_irradiance_of_scene`], and a row band's
/// [`band_irradiance`] of these planes' rows). Returns the channels and the scene.
pub fn channel_scene(
    set: &CaptureSet,
    scene: &SceneRadiance,
) -> Result<(Vec<usize>, SceneRadiance), CliError> {
    let ch = camsim_sensor::channel_planes(&set.camera.sensor, &scene.radiance);
    let planes = crate::simulate::ProjectedScene {
        planes: ch.planes,
        rows: scene.radiance.rows,
        cols: scene.radiance.cols,
        sample_pitch_m: scene.sample_pitch_m,
        object_distance_m: scene.object_distance_m,
        sample_aperture: scene.sample_aperture,
    };
    Ok((ch.channels, channel_scene_of_planes(set, planes)?))
}

/// The grid rows `rows` of [`channel_scene`] of shot `shot_index`'s scene with the luminance
/// factor `factor` ([`crate::simulate::shot_scene_rows`]'s), rendered straight onto the
/// channel planes ([`crate::simulate::shot_scene_projected_rows`] with
/// [`camsim_sensor::channel_weights`]): the same planes bit for bit, without the scene's
/// basis-term planes. Only for [`crate::simulate::shot_scene_by_rows`] shots.
pub fn shot_channel_scene_rows(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    rows: std::ops::Range<usize>,
    factor: f64,
) -> Result<(Vec<usize>, SceneRadiance), CliError> {
    let mut channels = Vec::new();
    let planes =
        crate::simulate::shot_scene_projected_rows(set, shot_index, grid, rows, factor, |b| {
            let w = camsim_sensor::channel_weights(&set.camera.sensor, b);
            channels = w.channels;
            w.weights
        })?;
    Ok((channels, channel_scene_of_planes(set, planes)?))
}

/// The scene whose basis terms are the channel planes `p` (spectra 1: the planes are already
/// the channels' spectral integrals).
fn channel_scene_of_planes(
    set: &CaptureSet,
    p: crate::simulate::ProjectedScene,
) -> Result<SceneRadiance, CliError> {
    let n = p.planes.len();
    let radiance = camsim_core::SpectralImage::new(
        p.rows,
        p.cols,
        camsim_core::image::SpectralBasis::Spectra(vec![camsim_core::Spectrum::constant(1.0); n]),
        p.planes,
    )
    .map_err(|e| CliError::input(&set.camera_path, format!("channel planes: {e}")))?;
    Ok(SceneRadiance {
        radiance,
        sample_pitch_m: p.sample_pitch_m,
        object_distance_m: p.object_distance_m,
        illuminant: None,
        depth_m: None,
        sample_aperture: p.sample_aperture,
    })
}

/// Depth-layered compositing slabs of the depth-aware optics (uniform in 1/z).
pub const DEPTH_LAYERS: usize = 16;
/// Field nodes of the real-lens depth-aware optics: placed where the PSF changes with field
/// height ([`camsim_render::depth_optics::FieldNodes::Adaptive`], its defaults), each pixel's
/// PSF interpolated between the four around it.
pub const DEPTH_FIELD_NODES: camsim_render::depth_optics::FieldNodes =
    camsim_render::depth_optics::ADAPTIVE_FIELD_NODES;

/// What the optics stage did with a scene's depth.
#[derive(Debug, Clone)]
pub struct DepthOptics {
    /// `"thin_lens"` or `"lens"`.
    pub kernels: &'static str,
    /// Focus distance (m; thin lens: from the lens; real lens: from the first vertex;
    /// `None` = infinity).
    pub focus_distance_m: Option<f64>,
    /// Compositing slabs.
    pub layers: usize,
    /// PSF nodes in the field: [columns, rows] ([1, 1]: one PSF per depth for the whole
    /// frame, as for the thin lens).
    pub field_nodes: [usize; 2],
    /// PSF RMS radius (µm on the sensor) applied at every scene sample.
    pub blur_rms_radius_um: Plane,
}

/// The optics stage's result: the irradiance, and the depth-aware blur when one was applied.
#[derive(Debug, Clone)]
pub struct OpticsOutcome {
    /// Sensor irradiance on the scene's grid.
    pub irradiance: SensorIrradiance,
    /// `Some` when the scene's depth was used.
    pub depth: Option<DepthOptics>,
}

/// The optics stage: [`camsim_optics::form_image`] with the camera's optics, made
/// **depth-aware** when the scene has depth (`SceneRadiance::depth_m`: a glTF render) and the
/// camera has a lens that defocuses by depth:
/// * `optics.focus_distance_m` (thin lens): every slab of depth is blurred with the pillbox of
///   its circle of confusion ([`camsim_render::depth_optics::thin_lens_for_camera`]), then the
///   camera's own optics (camera equation, relative illumination, its blur, e.g. diffraction)
///   apply as for any scene;
/// * `blur.kind = "lens"`: the lens's geometric PSFs by field tile × wavelength × object
///   distance, focused by the camera's focus settings
///   ([`camsim_render::depth_optics::LensDepthKernels`]), on the scene split into the grid's
///   bands, then the lens's distortion and relative illumination (its field model without
///   PSFs).
///
/// Both defocus by depth-layered compositing ([`camsim_render::depth_optics::defocus_by_depth`],
/// [`DEPTH_LAYERS`] slabs). Any other case (no depth, or a camera without focus) is the
/// shift-invariant path, unchanged.
pub fn irradiance_and_blur_of(
    set: &CaptureSet,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<OpticsOutcome, CliError> {
    camera_irradiance_and_blur(&set.camera, &set.camera_path, scene, grid)
}

/// [`irradiance_and_blur_of`] for a camera on its own (`camera_path` names its file in
/// errors): what the Python package's stage-by-stage `irradiance` calls.
pub fn camera_irradiance_and_blur(
    cam: &Camera,
    camera_path: &Path,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<OpticsOutcome, CliError> {
    use camsim_render::depth_optics::{
        defocus_by_depth, thin_lens_for_camera, DepthKernels, LensDepthKernels, LensDepthOptions,
    };
    let optics_err =
        |e: &dyn std::fmt::Display| CliError::input(camera_path, format!("optics: {e}"));
    let lens_focus = match &cam.optics.blur {
        camsim_optics::Blur::Lens(lb) => lb.focus.clone(),
        _ => None,
    };
    let depth = match &scene.depth_m {
        Some(d) if cam.thin_lens_focus_m.is_some() || lens_focus.is_some() => d,
        _ => {
            return Ok(OpticsOutcome {
                irradiance: camera_optical_image(cam, camera_path, scene, grid, None)?,
                depth: None,
            })
        }
    };
    let (w, h) = (scene.radiance.cols, scene.radiance.rows);
    if depth.rows != h || depth.cols != w {
        return Err(optics_err(&format!(
            "the scene's depth is {}×{} but its radiance {h}×{w}",
            depth.rows, depth.cols
        )));
    }
    let dx = scene.sample_pitch_m;
    let mut optics = cam.optics.clone();
    let (kernels, radiance, focus_distance_m, tiles) = match &lens_focus {
        None => {
            let f = cam.thin_lens_focus_m;
            let t = thin_lens_for_camera(optics.focal_length_m, optics.f_number, f, dx)
                .map_err(|e| optics_err(&e))?;
            (DepthKernels::Thin(t), scene.radiance.clone(), f, [1, 1])
        }
        Some(focus) => {
            let camsim_optics::Blur::Lens(lb) = &mut optics.blur else {
                unreachable!("lens_focus comes from a lens blur")
            };
            let bands = scene.radiance.to_bands(grid);
            let lk = LensDepthKernels::new(
                focus,
                &LensDepthOptions {
                    sample_pitch_mm: dx * 1e3,
                    width: w,
                    height: h,
                    wavelengths_nm: lb.model.wavelengths_nm.clone(),
                    pupil_n: 32,
                    field_nodes: DEPTH_FIELD_NODES,
                },
                &camsim_render::depth_path::slab_inverse_depths(&depth.data, DEPTH_LAYERS),
            )
            .map_err(|e| optics_err(&e))?;
            // the PSFs are applied here; the lens model keeps distortion and illumination
            lb.apply_psf = false;
            let nodes = [lk.node_x_px.len(), lk.node_y_px.len()];
            (
                DepthKernels::Lens(lk),
                bands,
                focus.focus_distance_mm.map(|d| d * 1e-3),
                nodes,
            )
        }
    };
    let band_nm: Vec<f64> = match &radiance.basis {
        camsim_core::image::SpectralBasis::Bands(g) => g.wavelength_nm.clone(),
        _ => vec![550.0; radiance.planes.len()],
    };
    let d = defocus_by_depth(
        &radiance.planes,
        &band_nm,
        &depth.data,
        w,
        h,
        DEPTH_LAYERS,
        &kernels,
    );
    let mut defocused = scene.clone();
    defocused.radiance = camsim_core::image::SpectralImage {
        planes: d.planes,
        ..radiance
    };
    let irradiance =
        camsim_optics::form_image(&optics, &defocused, grid).map_err(|e| optics_err(&e))?;
    Ok(OpticsOutcome {
        irradiance,
        depth: Some(DepthOptics {
            kernels: match kernels {
                DepthKernels::Thin(_) => "thin_lens",
                DepthKernels::Lens(_) => "lens",
            },
            focus_distance_m,
            layers: DEPTH_LAYERS,
            field_nodes: tiles,
            blur_rms_radius_um: Plane {
                rows: h,
                cols: w,
                data: d
                    .blur_rms_radius_px
                    .iter()
                    .map(|r| (*r as f64 * dx * 1e6) as f32)
                    .collect(),
            },
        }),
    })
}

/// The pixel-optics stage (`sensor.pixel_optics`, issue 21): each pixel's light, as
/// integrated over the pixel by [`camsim_sensor::electron_rate`], is shared between its own
/// photodiode (pixel vignetting / CRA shading) and its neighbours' (angle-dependent optical
/// crosstalk) by the camera's response map ([`camsim_sensor::pixel_optics`]). Without the
/// block `rate` is untouched (same bits). Applied once, after the pixel integration (and after
/// its `crosstalk` block: both are linear, the order matters only at second order), by
/// [`shot_electron_rate`] and `camsim run`.
pub fn apply_pixel_optics(camera: &Camera, rate: &mut ElectronRate) {
    if let Some(po) = &camera.pixel_optics {
        let map = po.response_map(rate.rows, rate.cols);
        camsim_sensor::pixel_optics::apply_pixel_optics(&map, rate);
    }
}

/// A band of the sensor's pixel rows, `start..end`, through the chain by itself: the optics
/// stage on the band's scene rows plus the optics' margin ([`band_scene_rows`]) at their true
/// field coordinates ([`band_irradiance`]), then the pixel integration of the band
/// ([`band_sensor`]). `start` is a multiple of the CFA tile's rows, so the band's pixels keep
/// their colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RowBand {
    /// First pixel row.
    pub start: usize,
    /// One past the last pixel row.
    pub end: usize,
}

impl RowBand {
    /// Pixel rows in the band.
    pub fn rows(&self) -> usize {
        self.end - self.start
    }
}

/// Why `set`'s camera cannot run `band` by itself (`None`: it can): the optics must be local
/// ([`camsim_optics::form_image_rows`]: no diffraction, wavefront, PSF or lens blur, not the
/// uncropped image), no pixel optics (their response map is the whole sensor's), no glTF target
/// with depth-aware optics (its defocus by depth acts on the whole field), and the band must lie
/// on the sensor starting at a CFA tile row.
pub fn band_refusal(set: &CaptureSet, band: RowBand) -> Option<String> {
    use camsim_optics::Blur;
    let cam = &set.camera;
    let s = &cam.sensor;
    if !matches!(
        cam.optics.blur,
        Blur::None | Blur::Gaussian { .. } | Blur::Pillbox { .. }
    ) {
        return Some("a row band needs a local blur (none, gaussian, pillbox)".into());
    }
    if cam.uncropped_optical_image {
        return Some("a row band of an uncropped optical image".into());
    }
    if cam.pixel_optics.is_some() {
        return Some("a row band with sensor.pixel_optics".into());
    }
    // a glTF scene keeps its depth (depth-aware defocus acts on the whole field)
    if set
        .shots
        .iter()
        .any(|sh| sh.target.gltf.as_ref().is_some_and(|g| g.depth_optics))
    {
        return Some("a row band of a glTF target with depth_optics".into());
    }
    if band.start >= band.end || band.end > s.rows || band.start % s.cfa.tile_rows() != 0 {
        return Some(format!(
            "row band {}..{} of a {}-row sensor (start a multiple of the CFA tile's {} rows)",
            band.start,
            band.end,
            s.rows,
            s.cfa.tile_rows()
        ));
    }
    None
}

/// The rows `r0..r1` of the scene sampling grid ([`shot_sampling_grid`]) whose optical image
/// `band` integrates, with the blur's reach: its pixel rows plus, on each side, the margin the
/// camera's optics would have without their warp blocks ([`sampling_for`]: the blur's, the
/// diffuser's and the defocus block's reach). The whole grid's rows are
/// `(rows + 2·margin)·os`, with the margin a warp adds (its largest outward displacement, at
/// the field's corner): a band does not need those rows, only its own rows' sources, which
/// [`band_warp_widening`] adds. [`band_irradiance`] returns these rows; the pixel integration
/// ([`band_sensor`]) centres the band's pixels in them as the whole sensor's in the grid.
pub fn band_core_rows(set: &CaptureSet, grid: &WavelengthGrid, band: RowBand) -> (usize, usize) {
    let cam = &set.camera;
    let (os, margin) = sampling_for(&cam.optics, &cam.sensor, grid, set.simulation.oversample);
    let mut unwarped = cam.optics.clone();
    unwarped.effects.distortion = None;
    unwarped.effects.lateral_color = None;
    let reach = sampling_for(&unwarped, &cam.sensor, grid, set.simulation.oversample)
        .1
        .min(margin);
    (
        (band.start + margin - reach) * os,
        (band.end + margin + reach) * os,
    )
}

/// How many scene-grid rows the optics stage of a row band must read beyond its
/// [`band_core_rows`] on each side to hold every source of a warp ([`band_warp_widening`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct BandWidening {
    /// Rows above the core rows (towards row 0).
    pub above: usize,
    /// Rows below the core rows.
    pub below: usize,
}

/// The rows a row band must be widened by to hold every source of a warp (0 without one): a
/// warped sample at field offset (x, y) from the grid's centre takes the scene at
/// (g·x, g·y), `g = r_s / r` ([`camsim_optics::OpticsEffects::warp_ratio_range`] over the
/// image radii the band's core rows reach), so a core row at offset y reads rows
/// `y·[g_lo, g_hi]`; over the core rows `y ∈ [y₀, y₁]` the sources lie within the extremes of
/// the four products, and the bilinear taps read the row below each source too. A pincushion
/// warp's sources lie towards the centre, a barrel warp's away from it, by `|y|·|1 − g|`:
/// little near the axis, most at the sensor's top and bottom edges. One row more each side
/// than the exact bound covers the inverse table's interpolation (its error is ≪ 10⁻³ of a
/// sample). When the ratio's range cannot be found (a map that folds over, which the optics
/// refuse anyway) the whole field's largest displacement
/// ([`camsim_optics::OpticsEffects::max_warp_displacement_m`], + 2 samples) on both sides.
pub fn band_warp_widening(set: &CaptureSet, grid: &WavelengthGrid, band: RowBand) -> BandWidening {
    let cam = &set.camera;
    let fx = &cam.optics.effects;
    if !fx.has_warp() {
        return BandWidening::default();
    }
    let (os, margin) = sampling_for(&cam.optics, &cam.sensor, grid, set.simulation.oversample);
    let full_rows = (cam.sensor.rows + 2 * margin) * os;
    let dx = cam.sensor.pixel_pitch_m / os as f64;
    let full_cols = (cam.sensor.cols + 2 * margin) * os;
    let (yc, xc) = (
        (full_rows as f64 - 1.0) / 2.0,
        (full_cols as f64 - 1.0) / 2.0,
    );
    let (c0, c1) = band_core_rows(set, grid, band);
    let c1 = c1.min(full_rows);
    // the core rows' offsets from the centre (samples)
    let (y0, y1) = (c0 as f64 - yc, c1 as f64 - 1.0 - yc);
    let y_far = y0.abs().max(y1.abs());
    let y_near = if y0 <= 0.0 && y1 >= 0.0 {
        0.0
    } else {
        y0.abs().min(y1.abs())
    };
    let r_lo = dx * y_near;
    let r_hi = dx * y_far.hypot(xc);
    match fx.warp_ratio_range(r_lo, r_hi, Some(&grid.wavelength_nm)) {
        Some((g_lo, g_hi)) => {
            let p = [y0 * g_lo, y0 * g_hi, y1 * g_lo, y1 * g_hi];
            let s_lo = p.iter().cloned().fold(f64::INFINITY, f64::min) + yc;
            let s_hi = p.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + yc;
            // first row read: floor(s_lo), less one; one past the last: floor(s_hi) + 1 (the
            // tap's second row) + 1, plus one
            let first = s_lo.floor() - 1.0;
            let end = s_hi.floor() + 3.0;
            BandWidening {
                above: (c0 as f64 - first).max(0.0).ceil() as usize,
                below: (end - c1 as f64).max(0.0).ceil() as usize,
            }
        }
        None => {
            let r_max = dx * (yc * yc + xc * xc).sqrt() * 1.001;
            let d = fx.max_warp_displacement_m(r_max, Some(&grid.wavelength_nm));
            let w = ((d / dx).ceil() as usize).saturating_add(2);
            BandWidening { above: w, below: w }
        }
    }
}

/// The rows of the scene grid the optics stage of `band` reads ([`band_irradiance`]): its
/// [`band_core_rows`] widened by `widen` ([`band_warp_widening`]), within the grid.
pub fn band_scene_rows(
    set: &CaptureSet,
    grid: &WavelengthGrid,
    band: RowBand,
    widen: BandWidening,
) -> (usize, usize) {
    let cam = &set.camera;
    let (os, margin) = sampling_for(&cam.optics, &cam.sensor, grid, set.simulation.oversample);
    let (r0, r1) = band_core_rows(set, grid, band);
    let full_rows = (cam.sensor.rows + 2 * margin) * os;
    (
        r0.saturating_sub(widen.above),
        r1.saturating_add(widen.below).min(full_rows),
    )
}

/// Rows `r0..r1` of a scene (the band a [`band_scene_rows`] names).
pub fn scene_rows(scene: &SceneRadiance, r0: usize, r1: usize) -> SceneRadiance {
    let cols = scene.radiance.cols;
    let crop = |p: &Vec<f32>| p[r0 * cols..r1 * cols].to_vec();
    SceneRadiance {
        radiance: camsim_core::image::SpectralImage {
            rows: r1 - r0,
            cols,
            basis: scene.radiance.basis.clone(),
            planes: scene.radiance.planes.iter().map(crop).collect(),
        },
        sample_pitch_m: scene.sample_pitch_m,
        object_distance_m: scene.object_distance_m,
        illuminant: scene.illuminant.clone(),
        depth_m: scene.depth_m.as_ref().map(|d| Plane {
            rows: r1 - r0,
            cols,
            data: d.data[r0 * cols..r1 * cols].to_vec(),
        }),
        sample_aperture: scene.sample_aperture,
    }
}

/// What the veiling-glare block of `set`'s camera adds to the optical image of a shot's whole
/// `scene` ([`camsim_optics::glare_sums`]); `None` without the block. A band's glare is the
/// whole field's ([`band_irradiance`]).
pub fn shot_glare_sums(
    set: &CaptureSet,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<Option<camsim_optics::GlareSums>, CliError> {
    camsim_optics::glare_sums(&set.camera.optics, scene, grid)
        .map_err(|e| CliError::input(&set.camera_path, format!("optics: {e}")))
}

/// Most samples on the short side of a [`decimated_glare_field`]'s sensor: a few hundred, so a
/// chart's coarse run costs milliseconds (the 12 MP sensor's 3000 rows become 375).
pub const GLARE_FIELD_MAX_SHORT_SIDE: usize = 400;
/// Fewest samples on the short side of a [`decimated_glare_field`]'s sensor: a coarser field
/// is not taken (the exact whole-field run instead).
pub const GLARE_FIELD_MIN_SHORT_SIDE: usize = 200;

/// The capture set whose camera sees the same field as `set`'s on a coarse grid: the same
/// physical sensor (its size, hence every field coordinate, and its channels) and optics, but
/// `rows/k × cols/k` pixels of pitch `k·p` and oversampling 1 (`simulation.oversample`), so
/// its scene sampling grid ([`shot_sampling_grid`]) has `(k·os)²` times fewer samples than
/// `set`'s. The whole-field means of the optical image of a target ([`shot_glare_sums`]) on
/// it approximate the full grid's: the chart renders cell averages (each coarse sample is
/// the mean of the radiance over its cell, so the coarse sum over the sensor is the same
/// integral), and the optics' field maps (relative illumination, fall-off) and warps are
/// smooth on the coarse pitch; what the coarse grid misses is what the blur moves across the
/// sensor's edge below its pitch. `k` is the smallest divisor of both `rows` and `cols`
/// (the size stays exact) that puts the short side at most at
/// [`GLARE_FIELD_MAX_SHORT_SIDE`]; `None` when that leaves fewer than
/// [`GLARE_FIELD_MIN_SHORT_SIDE`] pixels on the short side, when `k` would be 1 (the sensor is
/// small already), or when the camera cannot run its rows as bands ([`band_refusal`]: the
/// only caller is the bands' glare). Returns the set and `k`.
pub fn decimated_glare_field(set: &CaptureSet) -> Option<(CaptureSet, usize)> {
    let s = &set.camera.sensor;
    if band_refusal(
        set,
        RowBand {
            start: 0,
            end: s.rows,
        },
    )
    .is_some()
    {
        return None;
    }
    let short = s.rows.min(s.cols);
    let k = (2..=short)
        .find(|&k| s.rows % k == 0 && s.cols % k == 0 && short / k <= GLARE_FIELD_MAX_SHORT_SIDE)?;
    if short / k < GLARE_FIELD_MIN_SHORT_SIDE {
        return None;
    }
    let mut coarse = set.clone();
    let c = &mut coarse.camera.sensor;
    c.rows = s.rows / k;
    c.cols = s.cols / k;
    c.pixel_pitch_m = s.pixel_pitch_m * k as f64;
    coarse.simulation.oversample = Some(1);
    Some((coarse, k))
}

/// [`shot_glare_sums`] of shot `shot_index`'s target on a [`decimated_glare_field`] `coarse`
/// (its camera carrying the optics whose sums are wanted): the chain's own steps on the coarse
/// grid — [`shot_scene`], on the sensor channels' planes ([`channel_scene`]) when `channels`,
/// then [`shot_glare_sums`] — the coarse scene being kept by the caller (`scene`, rendered when
/// `None`). Returns the sums and the coarse scene.
pub fn decimated_glare_sums(
    coarse: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    channels: bool,
    scene: Option<std::sync::Arc<SceneRadiance>>,
) -> Result<(camsim_optics::GlareSums, std::sync::Arc<SceneRadiance>), CliError> {
    let scene = match scene {
        Some(s) => s,
        None => std::sync::Arc::new(shot_scene(coarse, shot_index, grid)?),
    };
    let sums = if channels {
        let (_, chs) = channel_scene(coarse, &scene)?;
        shot_glare_sums(coarse, &chs, grid)?
    } else {
        shot_glare_sums(coarse, &scene, grid)?
    };
    let sums = sums.ok_or_else(|| {
        CliError::input(
            &coarse.camera_path,
            "optics: decimated glare sums of a camera without veiling glare",
        )
    })?;
    Ok((sums, scene))
}

/// The optics stage ([`shot_irradiance_of_scene`]) of `band` alone, on its
/// [`band_core_rows`]: `scene_band` is the shot's scene on the grid rows [`band_scene_rows`]
/// names ([`scene_rows`]), `glare` the whole
/// field's [`shot_glare_sums`] when the camera has veiling glare. The pixel integration of the
/// result with [`band_sensor`] gives the band's pixels of the whole sensor's electron rate
/// (within f32 rounding: test `chain::tests::band_rates_equal_the_whole_sensor_rates`).
pub fn band_irradiance(
    set: &CaptureSet,
    scene_band: &SceneRadiance,
    grid: &WavelengthGrid,
    band: RowBand,
    widen: BandWidening,
    glare: Option<&camsim_optics::GlareSums>,
) -> Result<SensorIrradiance, CliError> {
    band_irradiance_with(set, scene_band, grid, band, widen, glare, None)
}

/// [`band_irradiance`] on the sensor channels' planes when the optics depend on wavelength
/// (lateral colour, a non-flat transmittance: [`optics_alike_at_every_wavelength`] is false,
/// so the scene cannot be projected onto the channels before the optics as
/// [`channel_scene`] does): the optics project each wavelength band's plane onto the
/// channels' effective QE ([`camsim_sensor::channel_weights`] of the split image's basis)
/// right after the lateral-colour warp ([`camsim_optics::form_image_rows_projected`]), and
/// the blur, fall-off's successors and glare act on the channels' planes. Plane j is
/// `∫ QE'_c(λ) E(x, λ) dλ` of channel `channels[j]`; the pixel integration of the result
/// gives [`band_irradiance`]'s electron rates within f32 rounding (test
/// `diagnose_cmd::band_tests::band_channel_irradiance_is_the_band_irradiance_projected`).
pub fn band_channel_irradiance(
    set: &CaptureSet,
    scene_band: &SceneRadiance,
    grid: &WavelengthGrid,
    band: RowBand,
    widen: BandWidening,
    glare: Option<&camsim_optics::GlareSums>,
) -> Result<ChannelIrradiance, CliError> {
    let sensor = &set.camera.sensor;
    let channels = std::sync::Mutex::new(Vec::new());
    let project = |b: &camsim_core::image::SpectralBasis| {
        let w = camsim_sensor::channel_weights(sensor, b);
        if let Ok(mut c) = channels.lock() {
            *c = w.channels;
        }
        w.weights
    };
    let irradiance =
        band_irradiance_with(set, scene_band, grid, band, widen, glare, Some(&project))?;
    let channels = channels.into_inner().unwrap_or_default();
    Ok(ChannelIrradiance {
        channels,
        irradiance,
    })
}

/// [`band_irradiance`], projected onto `project`'s weights when given
/// ([`camsim_optics::form_image_rows_projected`]).
fn band_irradiance_with(
    set: &CaptureSet,
    scene_band: &SceneRadiance,
    grid: &WavelengthGrid,
    band: RowBand,
    widen: BandWidening,
    glare: Option<&camsim_optics::GlareSums>,
    project: Option<camsim_optics::PlaneProjection>,
) -> Result<SensorIrradiance, CliError> {
    let err = |e: String| CliError::input(&set.camera_path, format!("optics: {e}"));
    if let Some(r) = band_refusal(set, band) {
        return Err(err(r));
    }
    if scene_band.depth_m.is_some() {
        return Err(err("a row band of a scene with depth".into()));
    }
    let cam = &set.camera;
    let (os, margin) = sampling_for(&cam.optics, &cam.sensor, grid, set.simulation.oversample);
    let (r0, r1) = band_scene_rows(set, grid, band, widen);
    if scene_band.radiance.rows != r1 - r0 {
        return Err(err(format!(
            "the band's scene has {} rows, its grid rows {r0}..{r1}",
            scene_band.radiance.rows
        )));
    }
    let window = camsim_optics::RowWindow {
        row0: r0,
        full_rows: (cam.sensor.rows + 2 * margin) * os,
    };
    let mut irr = match project {
        None => camsim_optics::form_image_rows(&cam.optics, scene_band, grid, window, glare),
        Some(p) => camsim_optics::form_image_rows_projected(
            &cam.optics,
            scene_band,
            grid,
            window,
            glare,
            p,
        ),
    }
    .map_err(|e| err(e.to_string()))?;
    // the core rows, centred on the band's pixels as the pixel integration expects
    let (c0, c1) = band_core_rows(set, grid, band);
    if (c0, c1) != (r0, r1) {
        let img = &mut irr.irradiance;
        let cols = img.cols;
        for p in img.planes.iter_mut() {
            *p = p[(c0 - r0) * cols..(c1 - r0) * cols].to_vec();
        }
        img.rows = c1 - c0;
    }
    Ok(irr)
}

/// The sensor that integrates a [`band_irradiance`]: the camera's with `band`'s rows.
pub fn band_sensor(set: &CaptureSet, band: RowBand) -> SensorModel {
    SensorModel {
        rows: band.rows(),
        ..set.camera.sensor.clone()
    }
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
    shot_time_rate_from(set, shot_index, rate, shot, 0.0)
}

/// [`shot_time_rate`] of frame `frame_start_s` of a video (frame k at `k / frame_rate_hz`):
/// each row's window starts `frame_start_s` later, the light's phase and the motion carry on
/// ([`camsim_sensor::time_averaged_rate_from`]); a static shot is `rate` itself.
pub fn shot_time_rate_from<'a>(
    set: &CaptureSet,
    shot_index: usize,
    rate: &'a ElectronRate,
    shot: &Shot,
    frame_start_s: f64,
) -> Cow<'a, ElectronRate> {
    let model = shot_time_model(set, shot_index);
    if model.is_static() {
        Cow::Borrowed(rate)
    } else {
        Cow::Owned(camsim_sensor::time_averaged_rate_from(
            &set.camera.sensor,
            rate,
            shot.exposure_s,
            &model,
            frame_start_s,
        ))
    }
}

/// The electron rate of shot `shot_index` seeing the animated glTF `scene`, integrated over
/// each row's exposure window `[F + t_r, F + t_r + T]` (F = `frame_start_s`) under the shot's
/// light modulation: the scene is path-traced at time nodes `Δt` = `scene.time_step_s` apart
/// covering the frame ([`crate::animated::render_on_grid_at`]), each render goes through the
/// optics ([`irradiance_of`]) and pixel integration ([`camsim_sensor::electron_rate`]), and
/// the rows are integrated over the nodes ([`camsim_sensor::NodeIntegrator`]: exact for a rate
/// linear in time between nodes). The optics act on each instant's scene before the row
/// integration, so a blur that spreads light across rows mixes rows at each instant, as it
/// does on a real sensor. The shot's `motion` must be absent (the animation moves the scene).
/// Returns the rate and the number of renders.
pub fn animated_shot_rate(
    set: &CaptureSet,
    shot_index: usize,
    scene: &crate::animated::AnimatedScene,
    shot: &Shot,
    frame_start_s: f64,
    seed: u64,
) -> Result<(ElectronRate, usize), CliError> {
    let sensor = &set.camera.sensor;
    let model = shot_time_model(set, shot_index);
    let bad = |m: String| CliError::input(&scene.gltf, m);
    let (t0, t1) = camsim_sensor::frame_span_s(&model, sensor.rows, shot.exposure_s, frame_start_s);
    let nodes = camsim_sensor::TimeNodes::covering(t0, t1, scene.time_step_s).map_err(bad)?;
    let mut acc = camsim_sensor::NodeIntegrator::new(
        &model,
        sensor.rows,
        sensor.cols,
        shot.exposure_s,
        frame_start_s,
        &nodes,
    )
    .map_err(bad)?;
    let grid = wavelength_grid(set);
    let mut renders = 0;
    for k in 0..nodes.count {
        if !acc.needs(k) {
            continue;
        }
        let radiance =
            crate::animated::render_on_grid_at(set, scene, seed, &grid, nodes.time_s(k))?;
        let irr = irradiance_of(set, &radiance, &grid)?;
        acc.add(k, &camsim_sensor::electron_rate(sensor, &irr))
            .map_err(bad)?;
        renders += 1;
    }
    Ok((acc.finish(), renders))
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

/// [`simulate_frame`] for the frame with global index `frame_index` of its capture set
/// ([`frame_index`]): black-level drift and the RTN trap states depend on it
/// ([`camsim_sensor::expose_frame`]); without those blocks it is [`simulate_frame`].
pub fn simulate_frame_at(
    sensor: &SensorModel,
    rate: &ElectronRate,
    shot: &Shot,
    pattern: PatternSource<'_>,
    seed: u64,
    stream: &[u64],
    frame_index: u64,
) -> RawFrame {
    camsim_sensor::expose_frame(sensor, rate, shot, pattern, seed, stream, frame_index)
}

/// The global index of frame `frame` of shot `shot_index`: frames counted in capture order
/// (the shots in captures.json order, each shot's frames in order), from 0.
pub fn frame_index(set: &CaptureSet, shot_index: usize, frame: usize) -> u64 {
    (set.shots[..shot_index]
        .iter()
        .map(|s| s.frames.len())
        .sum::<usize>()
        + frame) as u64
}

/// The sensor during shot `shot_index`: the camera's, with the dark voltage of the shot's
/// `temperature_c` under the camera's doubling law ([`camsim_sensor::dark_voltage_at`];
/// unchanged without either).
pub fn shot_sensor(set: &CaptureSet, shot_index: usize) -> Cow<'_, SensorModel> {
    let s = &set.camera.sensor;
    let t = set.shots[shot_index].temperature_c;
    match (s.effects.dark_temperature, t) {
        (Some(_), Some(_)) => {
            let mut x = s.clone();
            x.dark_voltage_v_per_s = camsim_sensor::dark_voltage_at(s, t);
            Cow::Owned(x)
        }
        _ => Cow::Borrowed(s),
    }
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

/// The light of a scene through the two halves of the exit pupil ([`dual_pixel_irradiance`]).
#[derive(Debug, Clone)]
pub struct DualPixelIrradiance {
    /// Through the left pupil half (x < 0): half the light at focus.
    pub left: SensorIrradiance,
    /// Through the right pupil half.
    pub right: SensorIrradiance,
}

/// The thin-lens defocus of the camera at the scene's sample pitch `sample_pitch_m`
/// ([`camsim_render::depth_optics::thin_lens_for_camera`], focused at
/// `optics.focus_distance_m`, infinity when absent).
pub(crate) fn camera_thin_lens(
    cam: &Camera,
    camera_path: &Path,
    sample_pitch_m: f64,
) -> Result<camsim_render::depth_path::ThinLensDefocus, CliError> {
    camsim_render::depth_optics::thin_lens_for_camera(
        cam.optics.focal_length_m,
        cam.optics.f_number,
        cam.thin_lens_focus_m,
        sample_pitch_m,
    )
    .map_err(|e| CliError::input(camera_path, format!("optics: {e}")))
}

/// The signed thin-lens circle of confusion at inverse depth `inv_z_per_m` (1/m, 0 =
/// infinity) in samples of `t`: the radius of
/// [`camsim_render::depth_path::ThinLensDefocus::coc_radius_px`] with the sign of
/// `1/z − 1/D` (positive: nearer than the focus; [`camsim_optics::dual_pixel`]).
pub(crate) fn signed_coc_radius_px(
    t: &camsim_render::depth_path::ThinLensDefocus,
    inv_z_per_m: f64,
) -> f64 {
    let z = if inv_z_per_m > 0.0 {
        1.0 / inv_z_per_m
    } else {
        f64::INFINITY
    };
    let sign = if inv_z_per_m >= 1.0 / t.focus_distance_m {
        1.0
    } else {
        -1.0
    };
    sign * t.coc_radius_px(z)
}

/// The thin-lens dual-pixel disparity (pixels; right image minus left image) of an object at
/// `object_distance_m` (`None` = infinity) for the camera's focus, F-number and dual-pixel
/// separation: [`camsim_optics::dual_pixel_disparity_m`] of the signed circle of confusion in
/// pixels (the closed form the measured disparity is compared with). For a real lens
/// (`blur.kind = "lens"`) the paraxial disc of its entrance pupil at its focus
/// ([`crate::pdaf::depth_of_focus_per_m`]'s law), distances from the entrance pupil.
pub fn dual_pixel_expected_disparity_px(
    cam: &Camera,
    camera_path: &Path,
    object_distance_m: Option<f64>,
) -> Result<f64, CliError> {
    let dp = cam.dual_pixel.ok_or_else(|| {
        CliError::input(
            camera_path,
            "sensor.dual_pixel: required for dual-pixel images",
        )
    })?;
    let inv_z = object_distance_m.map_or(0.0, |z| 1.0 / z);
    if let Some((_, f)) = crate::pdaf::real_lens(cam) {
        // the paraxial disc of the real lens: entrance-pupil radius A, image-side scale H
        // (mm per unit tan θ), r = A (1/z − 1/D) H, distances from the entrance pupil
        let fo = crate::pdaf::lens_first_order(f)
            .map_err(|e| CliError::input(camera_path, format!("optics.blur: {e}")))?;
        let r_mm = camsim_lens::paraxial::paraxial_blur_radius_mm(
            fo.entrance_pupil_radius_mm,
            fo.per_tan_mm,
            inv_z,
            crate::pdaf::focus_vergence_per_m(cam),
        );
        return Ok(camsim_optics::dual_pixel_disparity_m(
            r_mm * 1e-3 / cam.sensor.pixel_pitch_m,
            dp.separation,
        ));
    }
    let t = camera_thin_lens(cam, camera_path, cam.sensor.pixel_pitch_m)?;
    let r_px = signed_coc_radius_px(&t, inv_z);
    Ok(camsim_optics::dual_pixel_disparity_m(r_px, dp.separation))
}

/// The optics stage of a dual-pixel camera (`sensor.dual_pixel`): the scene through each
/// half of the exit pupil of the camera's thin lens (focused at `optics.focus_distance_m`,
/// infinity when absent). Every slab of the scene's depth (`SceneRadiance::depth_m`; without
/// one, the plane at the scene's `object_distance_m`, infinity when absent) is blurred with the
/// half-disc PSF of its signed circle of confusion ([`camsim_optics::half_pupil_psf`]) by the
/// depth-layered compositing of the depth-aware optics ([`DEPTH_LAYERS`] slabs), weighted by ½
/// (the half pupil's share of the light), then the camera's own optics apply
/// ([`camsim_optics::form_image`]). The two halves sum to the thin-lens depth-aware image of
/// [`irradiance_and_blur_of`] (the half discs partition its pillbox). A real lens
/// (`blur.kind = "lens"`, focused by the focus model) uses its traced half-pupil PSFs instead
/// (`dual_pixel_lens_irradiance`).
pub fn dual_pixel_irradiance(
    cam: &Camera,
    camera_path: &Path,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<DualPixelIrradiance, CliError> {
    use camsim_optics::PupilHalf;
    use camsim_render::depth_path::{defocus_layered_with, Kernel};
    if cam.dual_pixel.is_none() {
        return Err(CliError::input(
            camera_path,
            "sensor.dual_pixel: required for dual-pixel images",
        ));
    }
    let (w, h) = (scene.radiance.cols, scene.radiance.rows);
    let dx = scene.sample_pitch_m;
    let plane_depth;
    let depth: &[f32] = match &scene.depth_m {
        Some(d) if d.rows == h && d.cols == w => &d.data,
        Some(d) => {
            return Err(CliError::input(
                camera_path,
                format!(
                    "optics: the scene's depth is {}×{} but its radiance {h}×{w}",
                    d.rows, d.cols
                ),
            ))
        }
        None => {
            let z = scene.object_distance_m.map_or(f32::INFINITY, |z| z as f32);
            plane_depth = vec![z; w * h];
            &plane_depth
        }
    };
    if let camsim_optics::Blur::Lens(lb) = &cam.optics.blur {
        return dual_pixel_lens_irradiance(cam, camera_path, lb, scene, depth, grid);
    }
    let t = camera_thin_lens(cam, camera_path, dx)?;
    let half_image = |half: PupilHalf| -> Result<SensorIrradiance, CliError> {
        let kernel = |inv_z: f64| {
            let psf = camsim_optics::half_pupil_psf(signed_coc_radius_px(&t, inv_z) * dx, dx, half);
            Kernel {
                radius: psf.half_rows,
                values: psf.data.iter().map(|v| *v as f32).collect(),
            }
        };
        let planes = defocus_layered_with(
            &scene.radiance.planes,
            depth,
            w,
            h,
            DEPTH_LAYERS,
            true,
            kernel,
        );
        let mut defocused = scene.clone();
        defocused.radiance.planes = planes
            .into_iter()
            .map(|p| p.into_iter().map(|v| 0.5 * v).collect())
            .collect();
        camsim_optics::form_image(&cam.optics, &defocused, grid)
            .map_err(|e| CliError::input(camera_path, format!("optics: {e}")))
    };
    Ok(DualPixelIrradiance {
        left: half_image(PupilHalf::Left)?,
        right: half_image(PupilHalf::Right)?,
    })
}

/// The half-photodiode electron rates of a scene: [`dual_pixel_irradiance`], the pixel
/// integration of each half ([`camsim_sensor::electron_rate`]), then the camera's split
/// ([`camsim_sensor::DualPixel::photodiode_rates`]).
pub fn dual_pixel_rates(
    cam: &Camera,
    camera_path: &Path,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<camsim_sensor::DualPixelRates, CliError> {
    let irr = dual_pixel_irradiance(cam, camera_path, scene, grid)?;
    let dp = cam.dual_pixel.expect("checked by dual_pixel_irradiance");
    Ok(dp.photodiode_rates(
        &camsim_sensor::electron_rate(&cam.sensor, &irr.left),
        &camsim_sensor::electron_rate(&cam.sensor, &irr.right),
    ))
}

/// The noise-free expected frames (DN, unrounded) of both half-photodiodes of `rates` under
/// `shot` ([`camsim_sensor::expected_dual_pixel_dn`]).
pub fn expected_dual_pixel_frames(
    cam: &Camera,
    rates: &camsim_sensor::DualPixelRates,
    shot: &Shot,
) -> Option<camsim_sensor::DualPixelExpected> {
    cam.dual_pixel
        .map(|dp| camsim_sensor::expected_dual_pixel_dn(&cam.sensor, &dp, rates, shot))
}

/// [`dual_pixel_irradiance`] for a real lens (`blur.kind = "lens"`): every slab of `depth_m`
/// (m, the scene's grid) is blurred with the on-axis geometric PSFs of the left and the right
/// entrance-pupil half of the lens as the focus model focused it, at the slab's object distance
/// and the tabulated wavelength nearest each band
/// ([`camsim_render::depth_path::LensDualPixelDefocus`], the scene split into the grid's
/// bands), by the same depth-layered compositing, weighted by ½; then the lens's distortion and
/// relative illumination (its field model without PSFs), as [`irradiance_and_blur_of`] does
/// for the normal pixel. The two halves sum to the on-axis depth-aware real-lens image.
fn dual_pixel_lens_irradiance(
    cam: &Camera,
    camera_path: &Path,
    lb: &camsim_optics::LensBlur,
    scene: &SceneRadiance,
    depth: &[f32],
    grid: &WavelengthGrid,
) -> Result<DualPixelIrradiance, CliError> {
    use camsim_render::depth_path::{
        defocus_layered_with, slab_inverse_depths, LensDualPixelDefocus,
    };
    let optics_err =
        |e: &dyn std::fmt::Display| CliError::input(camera_path, format!("optics: {e}"));
    let focus = lb.focus.as_ref().ok_or_else(|| {
        CliError::input(
            camera_path,
            "sensor.dual_pixel: blur kind \"lens\" needs a prescription (optics.blur.lens_file) focused by the focus model, not a loaded field model",
        )
    })?;
    let (w, h) = (scene.radiance.cols, scene.radiance.rows);
    let dx = scene.sample_pitch_m;
    let dp = LensDualPixelDefocus::new(
        focus,
        dx * 1e3,
        &lb.model.wavelengths_nm,
        32,
        &slab_inverse_depths(depth, DEPTH_LAYERS),
    )
    .map_err(|e| optics_err(&e))?;
    let bands = scene.radiance.to_bands(grid);
    let band_nm: Vec<f64> = match &bands.basis {
        camsim_core::image::SpectralBasis::Bands(g) => g.wavelength_nm.clone(),
        _ => vec![550.0; bands.planes.len()],
    };
    let groups: Vec<usize> = band_nm
        .iter()
        .map(|wl| dp.nearest_wavelength(*wl))
        .collect();
    let mut optics = cam.optics.clone();
    if let camsim_optics::Blur::Lens(l) = &mut optics.blur {
        // the PSFs are applied here; the lens model keeps distortion and illumination
        l.apply_psf = false;
    }
    let half_image = |right: bool| -> Result<SensorIrradiance, CliError> {
        let mut planes = vec![Vec::new(); bands.planes.len()];
        let mut gl = groups.clone();
        gl.sort_unstable();
        gl.dedup();
        for g in gl {
            let idx: Vec<usize> = (0..planes.len()).filter(|b| groups[*b] == g).collect();
            let sub: Vec<Vec<f32>> = idx.iter().map(|b| bands.planes[*b].clone()).collect();
            let out = defocus_layered_with(&sub, depth, w, h, DEPTH_LAYERS, true, |iz| {
                let (l, r) = dp.kernels(g, iz);
                if right {
                    r
                } else {
                    l
                }
            });
            for (b, p) in idx.into_iter().zip(out) {
                planes[b] = p.into_iter().map(|v| 0.5 * v).collect();
            }
        }
        let mut defocused = scene.clone();
        defocused.radiance = camsim_core::image::SpectralImage {
            planes,
            ..bands.clone()
        };
        camsim_optics::form_image(&optics, &defocused, grid).map_err(|e| optics_err(&e))
    };
    Ok(DualPixelIrradiance {
        left: half_image(false)?,
        right: half_image(true)?,
    })
}

/// Whether `cam`'s optics defocus a scene by its depth ([`irradiance_and_blur_of`]): a thin
/// lens focused somewhere (`optics.focus_distance_m`) or a lens blur with a focus.
pub fn camera_defocuses_by_depth(cam: &Camera) -> bool {
    cam.thin_lens_focus_m.is_some()
        || matches!(&cam.optics.blur, camsim_optics::Blur::Lens(l) if l.focus.is_some())
}

/// Which field of view a glTF render on the sensor's grid covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FieldOfView {
    /// The glTF camera's own `yfov` spans the grid (the framing set in the scene).
    #[default]
    Camera,
    /// The field the camera's optics image onto the grid ([`optics_yfov_rad`]): what a sensor
    /// behind that lens would see.
    Optics,
}

impl FieldOfView {
    /// From the configuration value `"camera"` or `"optics"` (error: what was expected).
    pub fn parse(v: &str) -> Result<Self, String> {
        match v {
            "camera" => Ok(FieldOfView::Camera),
            "optics" => Ok(FieldOfView::Optics),
            _ => Err(format!("\"{v}\": expected \"camera\" or \"optics\"")),
        }
    }
}

/// The vertical field of view (rad) that `cam`'s optics image onto a grid of `rows` samples
/// of pitch `sample_pitch_m` ([`camsim_render::depth_optics::pinhole_yfov_rad`] with the
/// image-side scale H: the focused prescription's paraxial H of a lens blur with a focus,
/// else the thin lens's image distance v at `optics.focus_distance_m`, or its focal length
/// when focused at infinity), so that the radiance (by angle) and the PSFs, distortion and
/// illumination (by position on the sensor) share one mapping.
pub fn optics_yfov_rad(cam: &Camera, rows: usize, sample_pitch_m: f64) -> Result<f64, String> {
    use camsim_render::depth_optics::{pinhole_yfov_rad, thin_lens_for_camera};
    let pitch_mm = sample_pitch_m * 1e3;
    let h_mm = match &cam.optics.blur {
        camsim_optics::Blur::Lens(lb) if lb.focus.is_some() => {
            let f = lb.focus.as_ref().expect("checked");
            f.lens
                .paraxial_image_mm_per_tan(f.lens.primary_nm)
                .map_err(|e| e.to_string())?
        }
        _ => {
            let t = thin_lens_for_camera(
                cam.optics.focal_length_m,
                cam.optics.f_number,
                cam.thin_lens_focus_m,
                sample_pitch_m,
            )?;
            t.pixels_per_tan() * pitch_mm
        }
    };
    Ok(pinhole_yfov_rad(h_mm, rows, pitch_mm))
}

/// A glTF scene to path-trace on a shot's scene sampling grid ([`render_gltf_on_grid`]).
#[derive(Debug, Clone)]
pub struct GltfOnGrid<'a> {
    /// The glTF 2.0 file (.gltf or .glb).
    pub scene: &'a Path,
    /// The glTF camera (node or camera name; None: the first).
    pub camera_name: Option<String>,
    /// The render camera asked for (`pinhole`, `thinlens`, `lens:FILE`, …; None: the policy
    /// of [`render_gltf_on_grid`]).
    pub camera: Option<&'a str>,
    /// Path-tracing samples per scene sample.
    pub spp: u32,
    /// Longest path (Mitsuba's convention, −1 = unlimited).
    pub max_depth: i32,
    /// Seed of the render.
    pub seed: u64,
    /// Render bands (band centres; None: the simulation grid); the render is resampled onto
    /// the simulation grid.
    pub bands: Option<&'a WavelengthGrid>,
    /// The field the render covers (default: the glTF camera's).
    pub field_of_view: FieldOfView,
}

/// The scene radiance of a glTF scene path-traced on the scene sampling grid of `set`'s
/// sensor ((rows + 2·margin)·os × (cols + 2·margin)·os samples of pitch pixel_pitch/os, the
/// margin and os of [`sampling_for`]; the field of [`GltfOnGrid::field_of_view`] spans the grid;
/// [`crate::animated::grid_render_job`], [`crate::animated::render_job_radiance`]), on the
/// simulation wavelengths `grid`, with the render's planar depth: the scene of `camsim run`'s
/// `render` section and of a `gltf` capture target alike.
///
/// Camera policy: when the camera defocuses by depth ([`camera_defocuses_by_depth`]) the
/// render is a pinhole one (the optics stage defocuses it) and a thin-lens render camera is
/// refused (it would defocus twice); otherwise the render camera is the glTF camera's own
/// (`CameraChoice::Auto`: a camera with `extras.thinlens` renders thin-lens). `r.camera`
/// overrides the choice.
///
/// The samples are cell averages ([`camsim_core::sample_aperture::SampleAperture::Cell`]): the tracer's
/// samples are uniform over each sample's cell, whatever `simulation.sample_aperture` says
/// (that setting chooses how closed-form targets are sampled).
pub fn render_gltf_on_grid(
    set: &CaptureSet,
    r: &GltfOnGrid,
    grid: &WavelengthGrid,
) -> Result<SceneRadiance, CliError> {
    use camsim_render::job::CameraChoice;
    let cam = &set.camera;
    let sensor = &cam.sensor;
    let depth_aware = camera_defocuses_by_depth(cam);
    let camera: CameraChoice = match r.camera {
        None if depth_aware => CameraChoice::Pinhole,
        None => CameraChoice::Auto,
        Some(c) => c.parse().map_err(|e: String| CliError::input(r.scene, e))?,
    };
    if depth_aware && matches!(camera, CameraChoice::ThinLens) {
        return Err(CliError::input(
            r.scene,
            "render.camera \"thinlens\": the camera's optics already defocus by depth \
             (optics.focus_distance_m or blur kind \"lens\"); render with \"pinhole\"",
        ));
    }
    let (os, margin) = sampling_for(&cam.optics, sensor, grid, set.simulation.oversample);
    let render_grid = r.bands.unwrap_or(grid);
    let yfov_rad = match r.field_of_view {
        FieldOfView::Camera => None,
        FieldOfView::Optics => Some(
            optics_yfov_rad(
                cam,
                (sensor.rows + 2 * margin) * os,
                sensor.pixel_pitch_m / os as f64,
            )
            .map_err(|e| CliError::input(&set.camera_path, format!("optics: {e}")))?,
        ),
    };
    let g = crate::animated::GridRender {
        camera_name: r.camera_name.clone(),
        camera,
        sensor,
        oversample: os,
        margin_px: margin,
        spp: r.spp,
        max_depth: r.max_depth,
        yfov_rad,
    };
    let job = crate::animated::grid_render_job(r.scene, &g, r.seed, render_grid)?;
    let mut scene = crate::guard::guarded(r.scene, || {
        crate::animated::render_job_radiance(
            &job,
            None,
            sensor.pixel_pitch_m / os as f64,
            render_grid,
        )
    })?;
    if r.bands.is_some() {
        scene.radiance = scene.radiance.to_bands(grid);
    }
    scene.sample_aperture = camsim_core::sample_aperture::SampleAperture::Cell;
    Ok(scene)
}
