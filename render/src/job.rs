//! One render request as the CLI and `camsim run` give it: a glTF file, a camera model, film
//! size and settings → a prepared scene + camera, ready for [`crate::integrator::render`].
use crate::camera::lightfield::LightFieldCamera;
use crate::camera::real_lens::RealLensCamera;
use crate::camera::{Camera, Pinhole, ThinLens};
use crate::error::RenderError;
use crate::gltf_load::{load_gltf, pick_camera};
use crate::integrator::RenderSettings;
use crate::scene::Scene;
use glam::Mat4;
use std::path::PathBuf;
use std::sync::Arc;

/// The camera model to render with.
#[derive(Debug, Clone, PartialEq)]
pub enum CameraChoice {
    /// Thin lens when the glTF camera has `extras.thinlens` (or an aperture/focus is given),
    /// else pinhole — what the Mitsuba harness does.
    Auto,
    /// Ideal pinhole.
    Pinhole,
    /// Thin lens (aperture and focus from the options, else the camera's `extras.thinlens`).
    ThinLens,
    /// Real lens: a `lens` prescription or a real-lens configuration file.
    Lens(PathBuf),
    /// Light field: a light-field configuration file.
    LightField(PathBuf),
}

impl std::str::FromStr for CameraChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "auto" => CameraChoice::Auto,
            "pinhole" => CameraChoice::Pinhole,
            "thinlens" | "thin_lens" => CameraChoice::ThinLens,
            _ => {
                if let Some(f) = s.strip_prefix("lens:").filter(|f| !f.is_empty()) {
                    CameraChoice::Lens(PathBuf::from(f))
                } else if let Some(f) = s.strip_prefix("lightfield:").filter(|f| !f.is_empty()) {
                    CameraChoice::LightField(PathBuf::from(f))
                } else {
                    return Err(format!(
                        "--camera \"{s}\": expected pinhole, thinlens, lens:FILE or lightfield:CONFIG"
                    ));
                }
            }
        })
    }
}

/// A render request.
#[derive(Debug, Clone)]
pub struct RenderJob {
    /// The glTF scene (.gltf or .glb).
    pub scene: PathBuf,
    /// Camera node/camera name; None = the first camera.
    pub camera_name: Option<String>,
    /// Camera model.
    pub camera: CameraChoice,
    /// Film width (px).
    pub width: u32,
    /// Film height (px); None = width / aspectRatio (or square).
    pub height: Option<u32>,
    /// Thin-lens aperture radius override (m).
    pub aperture_radius_m: Option<f64>,
    /// Thin-lens focus distance override (m).
    pub focus_distance_m: Option<f64>,
    /// Vertical field of view override (rad) of the pinhole and thin-lens perspective (and of
    /// the film a `lens:FILE` camera without a pixel pitch fits); `None` = the glTF camera's
    /// `yfov`. The camera chain sets it to the field its depth-aware optics image onto the
    /// render grid ([`crate::depth_optics::pinhole_yfov_rad`]).
    pub yfov_rad: Option<f64>,
    /// Integrator settings.
    pub settings: RenderSettings,
}

/// A loaded scene with its camera, ready to render.
pub struct PreparedJob {
    /// The scene.
    pub scene: Scene,
    /// The camera model.
    pub camera: Arc<dyn Camera>,
    /// The same camera when it is a light-field camera (for views and refocusing).
    pub lightfield: Option<Arc<LightFieldCamera>>,
    /// Camera-to-world transform.
    pub camera_to_world: Mat4,
    /// A one-line description of the camera (for logs and summaries).
    pub camera_description: String,
}

fn settings_err(msg: String) -> RenderError {
    RenderError::Settings(msg)
}

/// The film size (width, height in px) and the perspective of `job` seen from the glTF
/// camera `sc`: the height from the job, else from the camera's aspect ratio (else square);
/// the vertical field from the job's override, else the camera's `yfov`.
fn job_perspective(
    job: &RenderJob,
    sc: &crate::scene::SceneCamera,
) -> Result<(u32, u32, crate::camera::Perspective), RenderError> {
    let width = job.width;
    let height = job.height.unwrap_or_else(|| match sc.aspect_ratio {
        Some(a) if a > 0.0 => ((width as f32 / a).round() as u32).max(1),
        _ => width,
    });
    let mut persp = sc.perspective(width, height);
    if let Some(y) = job.yfov_rad {
        // checked as the f32 the perspective keeps (a value just below π rounds up to it)
        let y32 = y as f32;
        if !(y32.is_finite() && y32 > 0.0 && y32 < std::f32::consts::PI) {
            return Err(settings_err(format!(
                "vertical field of view {y} rad: must lie in (0, π)"
            )));
        }
        persp.yfov_rad = y32;
    }
    Ok((width, height, persp))
}

/// Load the scene and build the camera.
pub fn prepare(job: &RenderJob) -> Result<PreparedJob, RenderError> {
    prepare_at_time(job, None)
}

/// [`prepare`] with the scene's animations taken at `time_s` (s; None: the nodes' own
/// transforms, animations ignored): the objects and the camera where they are at that instant
/// ([`crate::gltf_load::load_gltf_at_time`]).
pub fn prepare_at_time(job: &RenderJob, time_s: Option<f64>) -> Result<PreparedJob, RenderError> {
    if job.width == 0 || job.width > 16384 {
        return Err(settings_err(format!(
            "--width {}: must be 1–16384 pixels",
            job.width
        )));
    }
    if let Some(h) = job.height {
        if h == 0 || h > 16384 {
            return Err(settings_err(format!(
                "--height {h}: must be 1–16384 pixels"
            )));
        }
    }
    if job.settings.spp == 0 {
        return Err(settings_err(
            "--spp 0: need at least one sample per pixel".into(),
        ));
    }
    if job.settings.max_depth == 0 || job.settings.max_depth < -1 {
        return Err(settings_err(format!(
            "--max-depth {}: must be ≥ 1, or −1 for unlimited",
            job.settings.max_depth
        )));
    }
    for (name, v) in [
        ("--aperture-radius", job.aperture_radius_m),
        ("--focus-distance", job.focus_distance_m),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v >= 0.0) || (name == "--focus-distance" && v <= 0.0) {
                return Err(settings_err(format!(
                    "{name} {v}: must be a positive number of metres"
                )));
            }
        }
    }
    let scene = match (&job.settings.environment, time_s) {
        (Some(env), t) => crate::gltf_load::load_gltf_with_environment(&job.scene, t, env)?,
        (None, None) => load_gltf(&job.scene)?,
        (None, Some(t)) => crate::gltf_load::load_gltf_at_time(&job.scene, t)?,
    };
    let sc = pick_camera(&scene, job.camera_name.as_deref()).map_err(|m| RenderError::Scene {
        path: job.scene.display().to_string(),
        msg: m,
    })?;
    let (width, height, persp) = job_perspective(job, sc)?;
    let thin = || -> Option<(f32, f32)> {
        let (a, f) = sc.thinlens.unzip();
        let a = job.aperture_radius_m.map(|v| v as f32).or(a)?;
        let f = job.focus_distance_m.map(|v| v as f32).or(f)?;
        Some((a, f))
    };
    let mut lightfield = None;
    let (camera, desc): (Arc<dyn Camera>, String) = match &job.camera {
        CameraChoice::Pinhole => (
            Arc::new(Pinhole { perspective: persp }),
            format!("pinhole \"{}\"", sc.name),
        ),
        CameraChoice::Auto | CameraChoice::ThinLens => match thin() {
            Some((a, f)) => (
                Arc::new(ThinLens {
                    perspective: persp,
                    aperture_radius_m: a,
                    focus_distance_m: f,
                }),
                format!("thin lens \"{}\" (aperture radius {a} m, focus {f} m)", sc.name),
            ),
            None if job.camera == CameraChoice::Auto => (
                Arc::new(Pinhole { perspective: persp }),
                format!("pinhole \"{}\"", sc.name),
            ),
            None => {
                return Err(settings_err(format!(
                    "--camera thinlens: camera \"{}\" has no extras.thinlens; give --aperture-radius and --focus-distance",
                    sc.name
                )))
            }
        },
        CameraChoice::Lens(file) => {
            let cam = RealLensCamera::from_file(
                file,
                width,
                height,
                persp.yfov_rad as f64,
                job.focus_distance_m.or(sc.thinlens.map(|t| t.1 as f64)),
            )
            .map_err(|e| settings_err(e.to_string()))?;
            (
                Arc::new(cam),
                format!("real lens {} at \"{}\"", file.display(), sc.name),
            )
        }
        CameraChoice::LightField(file) => {
            let cam = Arc::new(
                LightFieldCamera::from_file(file, width, height)
                    .map_err(|e| settings_err(e.to_string()))?,
            );
            lightfield = Some(cam.clone());
            (
                cam as Arc<dyn Camera>,
                format!("light field {} at \"{}\"", file.display(), sc.name),
            )
        }
    };
    Ok(PreparedJob {
        camera_to_world: sc.to_world,
        scene,
        camera,
        lightfield,
        camera_description: desc,
    })
}

/// Where the origin of the node named `node_name` projects on the film of `job` (px, film
/// coordinates: x right from the left edge, y down from the top edge; pixel centres at
/// half-integers) at time `time_s`, through the job's camera node taken at the same time —
/// the pinhole projection ([`crate::camera::Perspective::project`]) of the glTF camera
/// (glTF 2.0 §3.10.3), so both an animated object and an animated camera move the point.
pub fn node_film_position_px(
    job: &RenderJob,
    node_name: &str,
    time_s: f64,
) -> Result<[f64; 2], RenderError> {
    let scene_err = |msg: String| RenderError::Scene {
        path: job.scene.display().to_string(),
        msg,
    };
    let (scene, nodes) = crate::gltf_load::load_gltf_nodes_at_time(&job.scene, time_s)?;
    let sc = pick_camera(&scene, job.camera_name.as_deref()).map_err(scene_err)?;
    let node = nodes
        .iter()
        .find(|n| n.name.as_deref() == Some(node_name))
        .ok_or_else(|| scene_err(format!("no node named \"{node_name}\"")))?;
    let world = node.to_world.transform_point3(glam::DVec3::ZERO);
    let cam = sc.to_world.as_dmat4().inverse().transform_point3(world);
    let p = job_perspective(job, sc)?
        .2
        .project(cam.as_vec3())
        .ok_or_else(|| scene_err(format!("node \"{node_name}\" is behind the camera")))?;
    Ok([p.x as f64, p.y as f64])
}
