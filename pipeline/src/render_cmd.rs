//! `camsim render SCENE.gltf …`: spectral path tracing of a glTF 2.0 scene into a spectral
//! OpenEXR (Fichet 2021 layout, band-averaged radiance, `Z` planar depth), docs/render.md.
use crate::error::CliError;
use camsim_render::job::{prepare, CameraChoice, RenderJob};
use camsim_render::output::{write_exr, ExrChannels};
use camsim_render::{Bands, RenderError, RenderSettings};
use clap::Args;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Arguments of `camsim render`.
#[derive(Debug, Clone, Args)]
pub struct RenderArgs {
    /// The glTF 2.0 scene (.gltf or .glb).
    pub scene: PathBuf,
    /// Film width (pixels).
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    /// Film height (pixels); default: width / the camera's aspectRatio.
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples (camera paths) per pixel.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Seed of the random streams.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output bands LO:HI:STEP in nm (band edges; each channel is the band-averaged radiance).
    #[arg(long, default_value = "380:780:10")]
    pub bands: String,
    /// Camera model: pinhole | thinlens | lens:FILE | lightfield:CONFIG (default: thin lens
    /// when the glTF camera has extras.thinlens, else pinhole).
    #[arg(long)]
    pub camera: Option<String>,
    /// Which glTF camera (node or camera name); default the first.
    #[arg(long)]
    pub camera_name: Option<String>,
    /// Thin-lens aperture radius (m); overrides extras.thinlens.
    #[arg(long)]
    pub aperture_radius: Option<f64>,
    /// Thin-lens (or real-lens) focus distance (m); overrides extras.thinlens.
    #[arg(long)]
    pub focus_distance: Option<f64>,
    /// Longest path in segments, Mitsuba's convention (1 = emitters only, 2 = direct light,
    /// −1 = unlimited, with Russian roulette from the second bounce).
    #[arg(long, default_value_t = -1, allow_hyphen_values = true)]
    pub max_depth: i32,
    /// Depth (bounces) from which Russian roulette terminates paths (Mitsuba's `rr_depth`,
    /// whose default is 5; camsim's default 2 is faster per path, slightly noisier).
    #[arg(long, default_value_t = camsim_render::RenderSettings::default().rr_depth)]
    pub rr_depth: u32,
    /// Also write the variance of each pixel estimate (channels variance.S0.<λ>nm).
    #[arg(long)]
    pub variance: bool,
    /// Also write the Mitsuba harness's channel names (band_LLLL_HHHH, depth.T, depth_center.T).
    #[arg(long)]
    pub mitsuba_channels: bool,
    /// Environment lighting: an equirectangular OpenEXR (linear RGB, Mitsuba's `envmap`
    /// orientation, y up); overrides the scene's extras.camsim_environment_exr.
    #[arg(long)]
    pub environment: Option<PathBuf>,
    /// Multiplier of the environment map's values.
    #[arg(long, default_value_t = 1.0)]
    pub environment_strength: f64,
    /// Rotation of the environment map about +y (degrees).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub environment_rotation_deg: f64,
    /// Jittered rays per pixel for depth.T (with --mitsuba-channels).
    #[arg(long, default_value_t = 16)]
    pub depth_spp: u32,
    /// Light field: depths (m) to refocus at, comma separated (default: the focus distance).
    #[arg(long, value_delimiter = ',')]
    pub refocus_m: Vec<f64>,
    /// Output EXR (a light field also writes OUT_STEM.views.exr and OUT_STEM.refocus_Zm.exr, Z the refocus depth in m).
    #[arg(long)]
    pub out: PathBuf,
}

fn render_err(scene: &Path, e: RenderError) -> CliError {
    match e {
        RenderError::Scene { path, msg } => CliError::input(Path::new(&path), msg),
        RenderError::Output { path, msg } => CliError::output(Path::new(&path), msg),
        RenderError::Settings(m) => CliError::input(scene, m),
    }
}

/// The render job of the arguments.
pub fn job_from_args(a: &RenderArgs) -> Result<RenderJob, CliError> {
    let bands = Bands::parse(&a.bands).map_err(CliError::Other)?;
    let camera: CameraChoice = match &a.camera {
        None => CameraChoice::Auto,
        Some(s) => s.parse().map_err(CliError::Other)?,
    };
    Ok(RenderJob {
        scene: a.scene.clone(),
        camera_name: a.camera_name.clone(),
        camera,
        width: a.width,
        height: a.height,
        aperture_radius_m: a.aperture_radius,
        focus_distance_m: a.focus_distance,
        yfov_rad: None,
        settings: RenderSettings {
            spp: a.spp,
            seed: a.seed,
            bands,
            max_depth: a.max_depth,
            rr_depth: a.rr_depth,
            variance: a.variance,
            depth_spp: if a.mitsuba_channels { a.depth_spp } else { 0 },
            environment: a
                .environment
                .as_ref()
                .map(|f| camsim_render::envmap::EnvironmentSpec {
                    exr: f.clone(),
                    strength: a.environment_strength,
                    rotation_y_deg: a.environment_rotation_deg,
                }),
        },
    })
}

/// Run `camsim render`; returns the summary printed on stdout.
pub fn run_render(a: &RenderArgs, progress: bool) -> Result<Value, CliError> {
    let job = job_from_args(a)?;
    if a.out.extension().and_then(|e| e.to_str()) != Some("exr") {
        return Err(CliError::output(&a.out, "the output must be an .exr file"));
    }
    // Scene loading (glTF parse, spectral upsampling, BVH build), timed apart from the render.
    let t_load = std::time::Instant::now();
    let prepared = prepare(&job).map_err(|e| render_err(&a.scene, e))?;
    let load_s = t_load.elapsed().as_secs_f64();
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        // Like the folder outputs of the other commands, missing parent folders are created.
        std::fs::create_dir_all(dir).map_err(|e| {
            CliError::output(&a.out, format!("cannot create the output folder: {e}"))
        })?;
    }
    let (w, h) = prepared.camera.film_size_px();
    {
        // Band planes (+ variance), depth planes and the per-row accumulators, f32.
        let px = w as f64 * h as f64;
        let planes = job.settings.bands.count as f64 * (1.0 + a.variance as u8 as f64) * 2.0 + 4.0;
        let what = format!("{w}×{h} pixels");
        crate::budget::check_memory(
            Some(&a.scene),
            "--width/--height (or the camera's aspectRatio)",
            crate::budget::f32_bytes(px * planes, 1.0),
            &format!("{what} × {planes} f32 planes"),
        )?;
        crate::budget::check_work(
            Some(&a.scene),
            "--spp",
            px * a.spp as f64,
            &format!("{what} × {} samples", a.spp),
        )?;
    }
    let bar = crate::progress::bar(
        progress,
        h as u64,
        "{spinner} render [{bar:30}] {pos}/{len} rows {elapsed_precise} (eta {eta})",
    );
    let cb = |_rows: usize| bar.inc(1);
    let out = camsim_render::render(
        &prepared.scene,
        prepared.camera.as_ref(),
        prepared.camera_to_world,
        &job.settings,
        Some(&cb),
    );
    bar.finish_and_clear();
    write_exr(
        &a.out,
        &out,
        ExrChannels {
            mitsuba: a.mitsuba_channels,
            variance: a.variance,
        },
    )
    .map_err(|e| render_err(&a.scene, e))?;
    let mut extra_files = Vec::new();
    if let Some(lf) = &prepared.lightfield {
        extra_files = write_lightfield_products(a, lf, &out)?;
    }
    Ok(json!({
        "scene": a.scene.display().to_string(),
        "camera": prepared.camera_description,
        "width": w,
        "height": h,
        "spp": out.spp,
        "bands": a.bands,
        "triangles": prepared.scene.tris.len(),
        "load_s": load_s,
        "render_s": out.render_s,
        "samples_per_s": out.samples_per_s(),
        "out": a.out.display().to_string(),
        "lightfield_files": extra_files,
    }))
}

/// Sub-aperture views (one EXR, channels `u<u>v<v>.S0.<λ>nm`) and shift-and-add refocused
/// images (one spectral EXR per depth) of a light-field render.
fn write_lightfield_products(
    a: &RenderArgs,
    lf: &camsim_render::camera::lightfield::LightFieldCamera,
    out: &camsim_render::RenderOutput,
) -> Result<Vec<String>, CliError> {
    use camsim_core::exr_io::{channel_name, IRRADIANCE_UNITS};
    use camsim_render::camera::lightfield::refocus;
    let n = lf.info().n as usize;
    let (vw, vh) = (out.width / n, out.height / n);
    let stem = a.out.with_extension("");
    let mut files = Vec::new();
    let views: Vec<Vec<Vec<f32>>> = out
        .band_planes
        .iter()
        .map(|p| lf.sub_aperture_views(p))
        .collect();
    let mut planes = Vec::new();
    for (b, vb) in views.iter().enumerate() {
        let c = channel_name(out.bands.center_nm(b));
        for v in 0..n {
            for u in 0..n {
                planes.push((format!("u{u}v{v}.{c}"), vb[v * n + u].clone()));
            }
        }
    }
    let p = PathBuf::from(format!("{}.views.exr", stem.display()));
    camsim_render::output::write_planes_exr(&p, vw, vh, planes, IRRADIANCE_UNITS)
        .map_err(|e| render_err(&a.scene, e))?;
    files.push(p.display().to_string());
    let depths = if a.refocus_m.is_empty() {
        vec![lf.info().focus_distance_m]
    } else {
        a.refocus_m.clone()
    };
    for z in depths {
        if !(z > 0.0 && z.is_finite()) {
            return Err(CliError::Other(format!(
                "--refocus-m {z}: must be a positive distance in m"
            )));
        }
        let shift = lf.disparity_per_view(z);
        let planes: Vec<(String, Vec<f32>)> = views
            .iter()
            .enumerate()
            .map(|(b, vb)| {
                (
                    channel_name(out.bands.center_nm(b)),
                    refocus(vb, n, vw, vh, shift),
                )
            })
            .collect();
        let p = PathBuf::from(format!("{}.refocus_{z}m.exr", stem.display()));
        camsim_render::output::write_planes_exr(&p, vw, vh, planes, IRRADIANCE_UNITS)
            .map_err(|e| render_err(&a.scene, e))?;
        files.push(p.display().to_string());
    }
    Ok(files)
}
