//! glTF 2.0 (.gltf + .bin / data URIs, and .glb) → [`Scene`], with the conventions of the
//! Mitsuba reference harness (../shared/tools/mitsuba_ref/README.md), so that both renderers
//! read one file the same way:
//!
//! * nodes: world = parent · (matrix | T·R·S), baked into the vertices; normals by the inverse
//!   transpose; winding flipped where det < 0;
//! * cameras: perspective, `yfov` vertical, looking down −Z; `extras.thinlens =
//!   {aperture_radius, focus_distance}` on the camera node or the camera;
//! * materials: `extras.mitsuba_bsdf` (a Mitsuba BSDF dict) as given; otherwise
//!   KHR_materials_transmission > 0 → (rough) dielectric with KHR_materials_ior,
//!   metallicFactor ≥ 0.5 → (rough) conductor `material: none` with α = roughness², else
//!   diffuse; reflectance `extras.spectral_reflectance` or baseColorFactor (RGB upsampled,
//!   × baseColorTexture when present); `doubleSided` → two-sided; roughness ≤ 1e-3 → smooth;
//! * emission: `extras.spectral_emission` (W m⁻² sr⁻¹ nm⁻¹) or emissiveFactor ×
//!   KHR_materials_emissive_strength as RGB × unit-luminance D65; one-sided (CCW front);
//! * KHR_lights_punctual: `extras.spectral_intensity` (W sr⁻¹ nm⁻¹; point/spot) or
//!   `extras.spectral_irradiance` (W m⁻² nm⁻¹; directional), else colour × intensity
//!   (cd or lx) converted with 683 lm/W over a D65-shaped spectrum.
//!
//! camsim extensions: `extras.dispersion = {abbe_number}` | `{cauchy_a, cauchy_b_um2}` |
//! `{sellmeier_b, sellmeier_c_um2}` on a transmissive material (or KHR_materials_dispersion)
//! makes the dielectric dispersive.
use crate::bsdf::{self, Bsdf, Ggx, Ior, Lobe};
use crate::error::RenderError;
use crate::scene::{Material, PunctualLight, Scene, SceneCamera, SpectralTexture, TriShading};
use crate::spectral::{self, SigmoidPoly, TabulatedSpectrum};
use camsim_core::spectrum::Spectrum;
use glam::{DMat3, DMat4, DVec3, Mat4, Vec2, Vec3, Vec4};
use serde_json::Value;
use std::collections::HashMap;
use std::path::Path;

/// Extensions this loader implements (a file that *requires* another one is refused).
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_materials_dispersion",
];

/// The Mitsuba `lookup_ior` names this loader knows (values at 589 nm).
const IOR_NAMES: &[(&str, f64)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

struct Ctx<'a> {
    path: &'a Path,
}

impl Ctx<'_> {
    fn err(&self, msg: impl Into<String>) -> RenderError {
        RenderError::Scene {
            path: self.path.display().to_string(),
            msg: msg.into(),
        }
    }
}

fn extras_json(e: &gltf::json::Extras) -> Option<Value> {
    e.as_ref()
        .and_then(|raw| serde_json::from_str::<Value>(raw.get()).ok())
        .filter(|v| v.is_object())
}

/// Load a glTF 2.0 file (.gltf or .glb) into a render scene.
///
/// A glTF whose indices point outside their arrays can make the `gltf` crate's own validation
/// panic (gltf-json 1.4); that panic is caught (silently) and reported as one error line.
pub fn load_gltf(path: &Path) -> Result<Scene, RenderError> {
    guarded(path, || {
        load_gltf_unguarded(path, None, None).map(|(s, _)| s)
    })
}

/// [`load_gltf`] (or [`load_gltf_at_time`] when `time_s` is given) lit by `environment`
/// instead of the environment named in the scene's extras: the extras' map is then not
/// read at all, so an override also works when the scene names a missing or invalid file.
pub fn load_gltf_with_environment(
    path: &Path,
    time_s: Option<f64>,
    environment: &crate::envmap::EnvironmentSpec,
) -> Result<Scene, RenderError> {
    if let Some(t) = time_s {
        finite_time(path, t)?;
    }
    guarded(path, || {
        load_gltf_unguarded(path, time_s, Some(environment)).map(|(s, _)| s)
    })
}

fn finite_time(path: &Path, time_s: f64) -> Result<(), RenderError> {
    if time_s.is_finite() {
        Ok(())
    } else {
        Err(RenderError::Scene {
            path: path.display().to_string(),
            msg: format!("animation time {time_s} s: must be finite"),
        })
    }
}

/// The world transform of one node of a loaded scene.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeWorld {
    /// Node index in the file.
    pub index: usize,
    /// Node name, when it has one.
    pub name: Option<String>,
    /// Node-to-world transform.
    pub to_world: DMat4,
}

/// [`load_gltf`] with every node translation animated by the file's animations taken at time
/// `time_s` (s; [`crate::animation`]): objects and the camera where they are at that instant.
pub fn load_gltf_at_time(path: &Path, time_s: f64) -> Result<Scene, RenderError> {
    load_gltf_nodes_at_time(path, time_s).map(|(s, _)| s)
}

/// [`load_gltf_at_time`] with the world transform of every node of the default scene.
pub fn load_gltf_nodes_at_time(
    path: &Path,
    time_s: f64,
) -> Result<(Scene, Vec<NodeWorld>), RenderError> {
    finite_time(path, time_s)?;
    guarded(path, || load_gltf_unguarded(path, Some(time_s), None))
}

/// Runs a loader, turning a panic of the `gltf` crate's validation into one error line.
fn guarded<T>(
    path: &Path,
    load: impl FnOnce() -> Result<T, RenderError>,
) -> Result<T, RenderError> {
    thread_local! {
        static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    }
    // A panic hook installed once that stays silent only on a thread inside this call (other
    // threads' panics still reach the previous hook).
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(|q| q.get()) {
                prev(info)
            }
        }));
    });
    QUIET.with(|q| q.set(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(load));
    QUIET.with(|q| q.set(false));
    match r {
        Ok(r) => r,
        Err(p) => {
            let why = p
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| p.downcast_ref::<&str>().copied())
                .unwrap_or("malformed file");
            Err(RenderError::Scene {
                path: path.display().to_string(),
                msg: format!(
                    "invalid glTF 2.0 (an index or size is out of range: {})",
                    why.split_whitespace().collect::<Vec<_>>().join(" ")
                ),
            })
        }
    }
}

fn load_gltf_unguarded(
    path: &Path,
    time_s: Option<f64>,
    environment: Option<&crate::envmap::EnvironmentSpec>,
) -> Result<(Scene, Vec<NodeWorld>), RenderError> {
    let cx = Ctx { path };
    let bytes = std::fs::read(path).map_err(|e| cx.err(format!("cannot read: {e}")))?;
    // 1. required extensions, with a message naming them (before validation, which would
    //    only say "Unsupported")
    let raw = gltf::Gltf::from_slice_without_validation(&bytes)
        .map_err(|e| cx.err(format!("not a valid glTF 2.0 file: {e}")))?;
    for ext in raw.document.extensions_required() {
        if !SUPPORTED_EXTENSIONS.contains(&ext) {
            return Err(cx.err(format!(
                "extensionsRequired lists \"{ext}\", which camsim does not implement (supported: {})",
                SUPPORTED_EXTENSIONS.join(", ")
            )));
        }
    }
    drop(raw);
    let gltf =
        gltf::Gltf::from_slice(&bytes).map_err(|e| cx.err(format!("invalid glTF 2.0: {e}")))?;
    let base = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    // 2. buffers
    let mut blob = gltf.blob.clone();
    let mut buffers: Vec<gltf::buffer::Data> = Vec::new();
    for b in gltf.document.buffers() {
        let what = match b.source() {
            gltf::buffer::Source::Uri(u) if u.starts_with("data:") => {
                format!("buffer {} (data URI)", b.index())
            }
            gltf::buffer::Source::Uri(u) => {
                format!("buffer {} (\"{}\")", b.index(), base.join(u).display())
            }
            gltf::buffer::Source::Bin => format!("buffer {} (GLB BIN chunk)", b.index()),
        };
        let data = gltf::buffer::Data::from_source_and_blob(b.source(), Some(base), &mut blob)
            .map_err(|e| cx.err(format!("{what}: cannot load: {e}")))?;
        if data.0.len() < b.length() {
            return Err(cx.err(format!(
                "{what}: has {} bytes, byteLength says {}",
                data.0.len(),
                b.length()
            )));
        }
        buffers.push(data);
    }
    let doc = &gltf.document;
    // animated node translations at the requested time
    let animated = match time_s {
        Some(t) => crate::animation::translations_at(
            &crate::animation::translation_tracks(path, doc, &buffers)?,
            t,
        ),
        None => HashMap::new(),
    };
    let mut node_worlds: Vec<NodeWorld> = Vec::new();
    // 3. materials (index len = default material)
    let mut materials: Vec<Material> = Vec::new();
    let mut texture_cache: HashMap<usize, (u32, u32, Vec<[f32; 3]>)> = HashMap::new();
    for m in doc.materials() {
        materials.push(convert_material(
            &cx,
            &m,
            base,
            &buffers,
            &mut texture_cache,
        )?);
    }
    let default_material = materials.len();
    materials.push(Material {
        name: "<default>".into(),
        // glTF default material: metallic 1, roughness 1, white → rough mirror conductor
        bsdf: Bsdf {
            lobe: Lobe::Conductor {
                distr: Some(Ggx::new(1.0)),
                eta_k: None,
            },
            two_sided: false,
        },
        reflectance: SpectralTexture::Constant(TabulatedSpectrum::constant(1.0)),
        emission: None,
        emission_texture: None,
        normal_map: None,
    });
    // 4. nodes
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| cx.err("no scene in the file"))?;
    let mut tris: Vec<[Vec3; 3]> = Vec::new();
    let mut shading: Vec<TriShading> = Vec::new();
    let mut cameras: Vec<SceneCamera> = Vec::new();
    let mut punctual: Vec<PunctualLight> = Vec::new();
    let mut tangents: Vec<[Vec4; 3]> = Vec::new();
    let mut stack: Vec<(gltf::Node, DMat4, usize)> = scene
        .nodes()
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .map(|n| (n, DMat4::IDENTITY, 0))
        .collect();
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > 256 {
            return Err(cx.err("node hierarchy deeper than 256 (a cycle?)"));
        }
        if let gltf::scene::Transform::Decomposed { rotation: q, .. } = node.transform() {
            // glTF requires a unit quaternion; a zero (or non-finite, or far from unit) one
            // would silently collapse or shear the node.
            let n2: f32 = q.iter().map(|v| v * v).sum();
            if !(n2.is_finite() && (n2 - 1.0).abs() < 1e-3) {
                return Err(cx.err(format!(
                    "node {}: rotation {q:?} is not a unit quaternion",
                    node_label(&node)
                )));
            }
        }
        let local = match animated.get(&node.index()) {
            // the animated translation replaces the node's own (glTF 2.0 §3.11)
            Some(t) => {
                let (_, r, sc) = node.transform().decomposed();
                DMat4::from_scale_rotation_translation(
                    DVec3::from_array(sc.map(|v| v as f64)),
                    glam::DQuat::from_array(r.map(|v| v as f64)).normalize(),
                    DVec3::from_array(*t),
                )
            }
            None => {
                DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(|v| v as f64)))
            }
        };
        let world = parent * local;
        if !world.is_finite() {
            return Err(cx.err(format!(
                "node {}: transform is not finite",
                node_label(&node)
            )));
        }
        node_worlds.push(NodeWorld {
            index: node.index(),
            name: node.name().map(str::to_string),
            to_world: world,
        });
        if let Some(cam) = node.camera() {
            cameras.push(convert_camera(&cx, &node, &cam, &world)?);
        }
        if let Some(light) = node.light() {
            punctual.push(convert_light(&cx, &light, &world)?);
        }
        if let Some(mesh) = node.mesh() {
            add_mesh(
                &cx,
                &node,
                &mesh,
                &world,
                &buffers,
                default_material,
                &mut tris,
                &mut shading,
                &mut tangents,
            )?;
        }
        let kids: Vec<_> = node.children().collect();
        for c in kids.into_iter().rev() {
            stack.push((c, world, depth + 1));
        }
    }
    if cameras.is_empty() {
        return Err(cx.err(
            "no camera: the scene needs a node with a perspective camera (glTF \"cameras\")",
        ));
    }
    let mut built = Scene::build(tris, shading, materials, punctual, cameras);
    built.tangents = tangents;
    // environment lighting: the caller's override, else the one named in the scene's extras
    // (Blender: custom properties of the scene, exported with "Include → Custom Properties")
    let spec = match environment {
        Some(e) => Some(e.clone()),
        None => environment_extras(&cx, &scene, base)?,
    };
    if let Some(spec) = spec {
        built.set_environment(Some(crate::envmap::load_environment(&spec)?));
    }
    Ok((built, node_worlds))
}

/// `extras.camsim_environment_exr` (a path relative to the glTF file),
/// `extras.camsim_environment_strength` (default 1) and
/// `extras.camsim_environment_rotation_deg` (about +y, default 0) of the glTF scene.
fn environment_extras(
    cx: &Ctx,
    scene: &gltf::Scene,
    base: &Path,
) -> Result<Option<crate::envmap::EnvironmentSpec>, RenderError> {
    let Some(e) = extras_json(scene.extras()) else {
        return Ok(None);
    };
    let Some(f) = e.get("camsim_environment_exr") else {
        return Ok(None);
    };
    let f = f.as_str().filter(|s| !s.is_empty()).ok_or_else(|| {
        cx.err(format!(
            "scene extras.camsim_environment_exr = {f}: expected a file name (string)"
        ))
    })?;
    let num = |key: &str, default: f64| -> Result<f64, RenderError> {
        match e.get(key) {
            None => Ok(default),
            Some(v) => v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                cx.err(format!(
                    "scene extras.{key} = {v}: expected a finite number"
                ))
            }),
        }
    };
    Ok(Some(crate::envmap::EnvironmentSpec {
        exr: base.join(f),
        strength: num("camsim_environment_strength", 1.0)?,
        rotation_y_deg: num("camsim_environment_rotation_deg", 0.0)?,
    }))
}

fn node_label(n: &gltf::Node) -> String {
    match n.name() {
        Some(s) => format!("{} (\"{s}\")", n.index()),
        None => n.index().to_string(),
    }
}

fn convert_camera(
    cx: &Ctx,
    node: &gltf::Node,
    cam: &gltf::Camera,
    world: &DMat4,
) -> Result<SceneCamera, RenderError> {
    let p = match cam.projection() {
        gltf::camera::Projection::Perspective(p) => p,
        gltf::camera::Projection::Orthographic(_) => {
            return Err(cx.err(format!(
                "camera {}: orthographic cameras are not supported (use a perspective camera)",
                cam.index()
            )))
        }
    };
    if let Some(a) = p.aspect_ratio() {
        if !(a.is_finite() && (1e-4..=1e4).contains(&a)) {
            return Err(cx.err(format!(
                "camera {}: aspectRatio = {a}, expected a width/height ratio in [1e-4, 1e4]",
                cam.index()
            )));
        }
    }
    let yfov = p.yfov();
    if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(cx.err(format!(
            "camera {}: yfov = {yfov} rad, expected 0 < yfov < π",
            cam.index()
        )));
    }
    // remove the scale from the camera frame (as the harness does)
    let mut m = *world;
    for c in 0..3 {
        let col = m.col(c).truncate();
        let l = col.length();
        if !(l > 0.0) {
            return Err(cx.err(format!(
                "camera node {}: singular transform",
                node_label(node)
            )));
        }
        *m.col_mut(c) = (col / l).extend(0.0);
    }
    let tl = [extras_json(node.extras()), extras_json(cam.extras())]
        .into_iter()
        .flatten()
        .find_map(|e| e.get("thinlens").cloned());
    let thinlens = match tl {
        None => None,
        Some(v) => {
            let a = v.get("aperture_radius").and_then(Value::as_f64);
            let f = v.get("focus_distance").and_then(Value::as_f64);
            match (a, f) {
                (Some(a), Some(f)) if a >= 0.0 && f > 0.0 && a.is_finite() && f.is_finite() => {
                    Some((a as f32, f as f32))
                }
                _ => {
                    return Err(cx.err(format!(
                        "camera {}: extras.thinlens must be {{\"aperture_radius\": ≥ 0, \"focus_distance\": > 0}} (m), got {v}",
                        cam.index()
                    )))
                }
            }
        }
    };
    let name = node
        .name()
        .or(cam.name())
        .map(str::to_string)
        .unwrap_or_else(|| format!("camera{}", cam.index()));
    Ok(SceneCamera {
        name,
        to_world: m.as_mat4(),
        yfov_rad: yfov,
        aspect_ratio: p.aspect_ratio(),
        znear_m: p.znear().max(0.0),
        zfar_m: p.zfar(),
        thinlens,
    })
}

/// The largest spectral value (emission W m⁻² sr⁻¹ nm⁻¹, or reflectance) a glTF extra may
/// give: f32 holds 3.4e38, and the path weights multiply it by up to ~1e8.
const MAX_SPECTRAL_VALUE: f64 = 1e30;

fn spectral_extra(cx: &Ctx, what: &str, v: &Value) -> Result<Spectrum, RenderError> {
    let arr =
        |k: &str| -> Option<Vec<f64>> { v.get(k)?.as_array()?.iter().map(Value::as_f64).collect() };
    let w = arr("wavelength_nm").or_else(|| arr("wavelengths_nm"));
    let vals = arr("values");
    match (w, vals) {
        (Some(w), Some(vals)) => {
            let s = Spectrum::sampled(w, vals).map_err(|e| cx.err(format!("{what}: {e}")))?;
            if let Some((w, x)) = s.first_negative() {
                return Err(cx.err(format!("{what}: negative value {x} at {w} nm")));
            }
            // The renderer works in f32: a larger value would become +∞ and its light NaN.
            if let Spectrum::Sampled {
                wavelength_nm,
                values,
            } = &s
            {
                if let Some((w, x)) = wavelength_nm
                    .iter()
                    .zip(values)
                    .find(|(_, x)| !(x.abs() <= MAX_SPECTRAL_VALUE))
                {
                    return Err(cx.err(format!(
                        "{what}: value {x} at {w} nm is over {MAX_SPECTRAL_VALUE:e} (the \
                         renderer's f32 range with headroom)"
                    )));
                }
            }
            Ok(s)
        }
        _ => Err(cx.err(format!(
            "{what}: expected {{\"wavelength_nm\": [...], \"values\": [...]}} with numbers"
        ))),
    }
}

fn convert_light(
    cx: &Ctx,
    light: &gltf::khr_lights_punctual::Light,
    world: &DMat4,
) -> Result<PunctualLight, RenderError> {
    use gltf::khr_lights_punctual::Kind;
    let what = format!("KHR_lights_punctual light {}", light.index());
    let extras = extras_json(light.extras());
    let pos = world.transform_point3(DVec3::ZERO).as_vec3();
    let dir = world.transform_vector3(-DVec3::Z).normalize().as_vec3();
    let photometric = |per: &str| -> Result<TabulatedSpectrum, RenderError> {
        let c = light.color().map(|v| v as f64);
        let i = light.intensity() as f64;
        if !(i >= 0.0 && i.is_finite()) || c.iter().any(|v| !(*v >= 0.0)) {
            return Err(cx.err(format!("{what}: intensity and color must be ≥ 0")));
        }
        // S(λ) = E_rgb(λ) · I / (683 lm/W · ∫ ȳ): a white light of I cd (lx) has I cd (lx)
        let ybar: f64 = spectral::cmf_table().iter().map(|(_, c)| c[1]).sum();
        let e = spectral::rgb_emission(c);
        let k = i / (camsim_core::constants::LUMINOUS_EFFICACY_LM_PER_W * ybar);
        let _ = per;
        Ok(TabulatedSpectrum::from_fn(300.0, 830.0, |w| {
            e.eval(w as f32) as f64 * k
        }))
    };
    Ok(match light.kind() {
        Kind::Directional => {
            let irr = match extras.as_ref().and_then(|e| e.get("spectral_irradiance")) {
                Some(v) => TabulatedSpectrum::from_spectrum(&spectral_extra(
                    cx,
                    &format!("{what}: extras.spectral_irradiance"),
                    v,
                )?),
                None => photometric("lx")?,
            };
            PunctualLight::Directional {
                direction: dir,
                irradiance: irr,
            }
        }
        k => {
            let inten = match extras.as_ref().and_then(|e| e.get("spectral_intensity")) {
                Some(v) => TabulatedSpectrum::from_spectrum(&spectral_extra(
                    cx,
                    &format!("{what}: extras.spectral_intensity"),
                    v,
                )?),
                None => photometric("cd")?,
            };
            let spot = match k {
                Kind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => Some((dir, inner_cone_angle.cos(), outer_cone_angle.cos())),
                _ => None,
            };
            PunctualLight::Point {
                position_m: pos,
                intensity: inten,
                spot,
            }
        }
    })
}

/// Check that an accessor's bytes lie inside its buffer (so reading cannot go out of bounds).
fn check_accessor(
    cx: &Ctx,
    a: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
    what: &str,
) -> Result<(), RenderError> {
    if a.sparse().is_some() {
        return Err(cx.err(format!("{what}: sparse accessors are not supported")));
    }
    let view = a
        .view()
        .ok_or_else(|| cx.err(format!("{what}: accessor {} has no bufferView", a.index())))?;
    let buf = &buffers[view.buffer().index()];
    if view.offset() + view.length() > buf.len() {
        return Err(cx.err(format!(
            "{what}: bufferView {} ends at byte {} but buffer {} has {} bytes",
            view.index(),
            view.offset() + view.length(),
            view.buffer().index(),
            buf.len()
        )));
    }
    let elem = a.size();
    let stride = view.stride().unwrap_or(elem);
    if a.count() > 0 && a.offset() + stride * (a.count() - 1) + elem > view.length() {
        return Err(cx.err(format!(
            "{what}: accessor {} ({} elements) runs past the end of bufferView {}",
            a.index(),
            a.count(),
            view.index()
        )));
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn add_mesh(
    cx: &Ctx,
    node: &gltf::Node,
    mesh: &gltf::Mesh,
    world: &DMat4,
    buffers: &[gltf::buffer::Data],
    default_material: usize,
    tris: &mut Vec<[Vec3; 3]>,
    shading: &mut Vec<TriShading>,
    tangents: &mut Vec<[Vec4; 3]>,
) -> Result<(), RenderError> {
    let m3 = DMat3::from_mat4(*world);
    let nmat = m3.inverse().transpose();
    let flip = m3.determinant() < 0.0;
    for prim in mesh.primitives() {
        let what = format!(
            "node {} mesh {} primitive {}",
            node_label(node),
            mesh.name()
                .map(|s| format!("\"{s}\""))
                .unwrap_or_else(|| mesh.index().to_string()),
            prim.index()
        );
        if prim.mode() != gltf::mesh::Mode::Triangles {
            continue; // points and lines have no area (the harness skips them too)
        }
        let pos_acc = prim
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| cx.err(format!("{what}: no POSITION attribute")))?;
        check_accessor(cx, &pos_acc, buffers, &format!("{what} POSITION"))?;
        let normal_acc = prim.get(&gltf::Semantic::Normals);
        if let Some(a) = &normal_acc {
            check_accessor(cx, a, buffers, &format!("{what} NORMAL"))?;
        }
        let mat_index = prim.material().index();
        let material = mat_index.unwrap_or(default_material);
        let pm = prim.material();
        let normal_mapped = pm.normal_texture().is_some();
        // one TEXCOORD set per material: base colour's, else the normal map's, else the
        // emissive texture's
        let sets: Vec<(&str, u32)> = [
            (
                "baseColorTexture",
                pm.pbr_metallic_roughness()
                    .base_color_texture()
                    .map(|t| t.tex_coord()),
            ),
            ("normalTexture", pm.normal_texture().map(|t| t.tex_coord())),
            (
                "emissiveTexture",
                pm.emissive_texture().map(|t| t.tex_coord()),
            ),
        ]
        .into_iter()
        .filter_map(|(n, s)| s.map(|s| (n, s)))
        .collect();
        if let Some((n, s)) = sets.iter().find(|(_, s)| *s != sets[0].1) {
            return Err(cx.err(format!(
                "{what}: {n} uses TEXCOORD_{s} but {} uses TEXCOORD_{}; camsim needs one texture coordinate set per material",
                sets[0].0, sets[0].1
            )));
        }
        let tex_set = sets.first().map(|(_, s)| *s);
        let uv_acc = tex_set.and_then(|s| prim.get(&gltf::Semantic::TexCoords(s)));
        if let Some(a) = &uv_acc {
            check_accessor(cx, a, buffers, &format!("{what} TEXCOORD"))?;
        }
        if let Some(a) = prim.indices() {
            check_accessor(cx, &a, buffers, &format!("{what} indices"))?;
        }
        let reader = prim.reader(|b| Some(&buffers[b.index()][..]));
        let pos: Vec<DVec3> = reader
            .read_positions()
            .ok_or_else(|| cx.err(format!("{what}: cannot read POSITION")))?
            .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .collect();
        if let Some(i) = pos.iter().position(|p| !p.is_finite()) {
            return Err(cx.err(format!(
                "{what}: POSITION[{i}] = {:?} is not finite",
                pos[i]
            )));
        }
        let pos: Vec<Vec3> = pos
            .iter()
            .map(|p| world.transform_point3(*p).as_vec3())
            .collect();
        let normals: Option<Vec<Vec3>> = match reader.read_normals() {
            Some(it) => {
                let n: Vec<[f32; 3]> = it.collect();
                if n.len() != pos.len() {
                    return Err(cx.err(format!(
                        "{what}: NORMAL has {} entries, POSITION {}",
                        n.len(),
                        pos.len()
                    )));
                }
                if let Some(i) = n.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
                    return Err(cx.err(format!("{what}: NORMAL[{i}] is not finite")));
                }
                Some(
                    n.iter()
                        .map(|v| {
                            (nmat * DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
                                .normalize_or_zero()
                                .as_vec3()
                        })
                        .collect(),
                )
            }
            None => None,
        };
        let uvs: Option<Vec<Vec2>> = match (tex_set, &uv_acc) {
            (Some(s), Some(_)) => reader
                .read_tex_coords(s)
                .map(|it| it.into_f32().map(|v| Vec2::new(v[0], v[1])).collect()),
            _ => None,
        };
        let tangent_attr: Option<Vec<Vec4>> = match (normal_mapped, reader.read_tangents()) {
            (true, Some(it)) => {
                let t: Vec<[f32; 4]> = it.collect();
                if t.len() != pos.len() {
                    return Err(cx.err(format!(
                        "{what}: TANGENT has {} entries, POSITION {}",
                        t.len(),
                        pos.len()
                    )));
                }
                if let Some(i) = t.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
                    return Err(cx.err(format!("{what}: TANGENT[{i}] is not finite")));
                }
                // tangents transform as vectors; a mirroring transform flips the handedness
                let sign = if flip { -1.0 } else { 1.0 };
                Some(
                    t.iter()
                        .map(|v| {
                            let x = (m3 * DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
                                .normalize_or_zero()
                                .as_vec3();
                            x.extend(if v[3] < 0.0 { -sign } else { sign })
                        })
                        .collect(),
                )
            }
            _ => None,
        };
        let idx: Vec<u32> = match reader.read_indices() {
            Some(it) => it.into_u32().collect(),
            None => (0..pos.len() as u32).collect(),
        };
        if let Some(i) = idx.iter().position(|&i| i as usize >= pos.len()) {
            return Err(cx.err(format!(
                "{what}: index {} at position {i} is out of range ({} vertices)",
                idx[i],
                pos.len()
            )));
        }
        if idx.len() % 3 != 0 {
            return Err(cx.err(format!(
                "{what}: {} indices is not a multiple of 3",
                idx.len()
            )));
        }
        for t in idx.chunks_exact(3) {
            let (a, b, c) = if flip {
                (t[0], t[2], t[1])
            } else {
                (t[0], t[1], t[2])
            };
            let v = [pos[a as usize], pos[b as usize], pos[c as usize]];
            let cross = (v[1] - v[0]).cross(v[2] - v[0]);
            let area2 = cross.length();
            if !(area2 > 0.0) || !area2.is_finite() {
                continue; // degenerate: no area, never hit
            }
            let ng = cross / area2;
            let n = match &normals {
                Some(n) => {
                    let k = [n[a as usize], n[b as usize], n[c as usize]];
                    k.map(|x| if x == Vec3::ZERO { ng } else { x })
                }
                None => [ng; 3],
            };
            let uv = match &uvs {
                Some(u) if u.len() == pos.len() => [u[a as usize], u[b as usize], u[c as usize]],
                _ => [Vec2::ZERO; 3],
            };
            let mut tangent = u32::MAX;
            if normal_mapped {
                let tv = match &tangent_attr {
                    Some(t) => Some([t[a as usize], t[b as usize], t[c as usize]]),
                    None => {
                        // handedness on the side the vertex normals face (the shading frame
                        // is B = w·(N × T) with the interpolated N)
                        let side = if (n[0] + n[1] + n[2]).dot(ng) < 0.0 {
                            -ng
                        } else {
                            ng
                        };
                        crate::normal_map::triangle_tangent(v, uv, side).map(|t| [t; 3])
                    }
                };
                if let Some(tv) = tv {
                    tangent = tangents.len() as u32;
                    tangents.push(tv);
                }
            }
            tris.push(v);
            shading.push(TriShading {
                ng,
                n,
                uv,
                material: material as u32,
                light: u32::MAX,
                area: 0.5 * area2,
                tangent,
            });
        }
    }
    Ok(())
}

/// A spectrum from a Mitsuba dict value: a number, {"type":"rgb","value":[r,g,b]},
/// {"type":"spectrum","value": number | [[λ, v], …]}, {"type":"regular"/"irregular", …} is not
/// supported.
fn mitsuba_spectrum(
    cx: &Ctx,
    what: &str,
    v: &Value,
    emission: bool,
) -> Result<TabulatedSpectrum, RenderError> {
    if let Some(x) = v.as_f64() {
        return Ok(TabulatedSpectrum::constant(x as f32));
    }
    let ty = v.get("type").and_then(Value::as_str).unwrap_or("");
    let val = v.get("value");
    match (ty, val) {
        ("rgb", Some(Value::Array(a))) if a.len() == 3 => {
            let c: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
            if c.len() != 3 {
                return Err(cx.err(format!("{what}: rgb value must be 3 numbers")));
            }
            let c = [c[0], c[1], c[2]];
            Ok(if emission {
                spectral::rgb_emission(c)
            } else {
                spectral::rgb_reflectance(c)
            })
        }
        ("spectrum", Some(x)) if x.is_number() => {
            Ok(TabulatedSpectrum::constant(x.as_f64().unwrap_or(0.0) as f32))
        }
        ("spectrum", Some(Value::Array(pairs))) => {
            let mut w = Vec::new();
            let mut y = Vec::new();
            for p in pairs {
                let pr = p.as_array().filter(|a| a.len() == 2);
                match pr.map(|a| (a[0].as_f64(), a[1].as_f64())) {
                    Some((Some(a), Some(b))) => {
                        w.push(a);
                        y.push(b);
                    }
                    _ => return Err(cx.err(format!("{what}: spectrum value must be [[λ_nm, v], …]"))),
                }
            }
            let s = Spectrum::sampled(w, y).map_err(|e| cx.err(format!("{what}: {e}")))?;
            Ok(TabulatedSpectrum::from_spectrum(&s))
        }
        _ => Err(cx.err(format!(
            "{what}: expected a number, {{\"type\": \"rgb\", \"value\": [r, g, b]}} or {{\"type\": \"spectrum\", \"value\": [[λ, v], …]}}, got {v}"
        ))),
    }
}

fn ior_value(cx: &Ctx, what: &str, v: Option<&Value>, default: f64) -> Result<f64, RenderError> {
    match v {
        None => Ok(default),
        Some(Value::Number(n)) => n
            .as_f64()
            .filter(|x| *x > 0.0)
            .ok_or_else(|| cx.err(format!("{what}: must be > 0"))),
        Some(Value::String(s)) => IOR_NAMES
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(s))
            .map(|(_, v)| *v)
            .ok_or_else(|| {
                cx.err(format!(
                    "{what}: unknown index name \"{s}\" (known: {})",
                    IOR_NAMES
                        .iter()
                        .map(|(n, _)| *n)
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            }),
        Some(v) => Err(cx.err(format!("{what}: expected a number or a name, got {v}"))),
    }
}

fn alpha_of(cx: &Ctx, what: &str, d: &serde_json::Map<String, Value>) -> Result<f32, RenderError> {
    match d.get("distribution").and_then(Value::as_str) {
        Some("ggx") => {}
        Some(other) => {
            return Err(cx.err(format!(
                "{what}.distribution: \"{other}\" is not implemented (camsim has \"ggx\")"
            )))
        }
        None => {
            return Err(cx.err(format!(
                "{what}: give \"distribution\": \"ggx\" (Mitsuba's default is beckmann, which camsim does not implement)"
            )))
        }
    }
    if d.contains_key("alpha_u") || d.contains_key("alpha_v") {
        return Err(cx.err(format!(
            "{what}: anisotropic alpha_u/alpha_v is not supported; give alpha"
        )));
    }
    let a = match d.get("alpha") {
        None => 0.1,
        Some(v) => v
            .as_f64()
            .ok_or_else(|| cx.err(format!("{what}.alpha: must be a number")))?,
    };
    if !(a > 0.0 && a <= 4.0) {
        return Err(cx.err(format!("{what}.alpha: must be in (0, 4], got {a}")));
    }
    Ok(a as f32)
}

/// A Mitsuba BSDF dict → (lobe, reflectance, two-sided).
fn mitsuba_bsdf(
    cx: &Ctx,
    what: &str,
    v: &Value,
) -> Result<(Lobe, TabulatedSpectrum, bool), RenderError> {
    let d = v
        .as_object()
        .ok_or_else(|| cx.err(format!("{what}: must be an object")))?;
    let ty = d
        .get("type")
        .and_then(Value::as_str)
        .ok_or_else(|| cx.err(format!("{what}: no \"type\"")))?;
    let spec = |key: &str, default: f32| -> Result<TabulatedSpectrum, RenderError> {
        match d.get(key) {
            None => Ok(TabulatedSpectrum::constant(default)),
            Some(x) => mitsuba_spectrum(cx, &format!("{what}.{key}"), x, false),
        }
    };
    Ok(match ty {
        "twosided" => {
            let inner = d
                .get("material")
                .or_else(|| d.get("bsdf"))
                .ok_or_else(|| cx.err(format!("{what}: twosided needs \"material\"")))?;
            let (l, r, _) = mitsuba_bsdf(cx, &format!("{what}.material"), inner)?;
            (l, r, true)
        }
        "diffuse" => (Lobe::Diffuse, spec("reflectance", 0.5)?, false),
        "conductor" | "roughconductor" => {
            let distr = if ty == "roughconductor" {
                Some(Ggx::new(alpha_of(cx, what, d)?))
            } else {
                None
            };
            let ext = ior_value(cx, &format!("{what}.ext_eta"), d.get("ext_eta"), 1.000277)?;
            let material = d.get("material").and_then(Value::as_str);
            let eta_k = match (material, d.get("eta"), d.get("k")) {
                (_, Some(e), Some(k)) => {
                    let e = mitsuba_spectrum(cx, &format!("{what}.eta"), e, false)?;
                    let k = mitsuba_spectrum(cx, &format!("{what}.k"), k, false)?;
                    let s = 1.0 / ext as f32;
                    Some((
                        TabulatedSpectrum::from_fn(300.0, 830.0, |w| (e.eval(w as f32) * s) as f64),
                        TabulatedSpectrum::from_fn(300.0, 830.0, |w| (k.eval(w as f32) * s) as f64),
                    ))
                }
                (None | Some("none"), None, None) => None,
                (Some(name), None, None) => Some(bsdf::metals::metal(name, ext).ok_or_else(|| {
                    cx.err(format!(
                        "{what}.material: unknown metal \"{name}\" (known: none, {}; or give eta and k)",
                        bsdf::metals::NAMES.join(", ")
                    ))
                })?),
                _ => return Err(cx.err(format!("{what}: give both eta and k, or a material name"))),
            };
            (
                Lobe::Conductor { distr, eta_k },
                spec("specular_reflectance", 1.0)?,
                false,
            )
        }
        "dielectric" | "roughdielectric" => {
            let distr = if ty == "roughdielectric" {
                Some(Ggx::new(alpha_of(cx, what, d)?))
            } else {
                None
            };
            let int = ior_value(cx, &format!("{what}.int_ior"), d.get("int_ior"), 1.5046)?;
            let ext = ior_value(cx, &format!("{what}.ext_ior"), d.get("ext_ior"), 1.000277)?;
            if int == ext {
                return Err(cx.err(format!("{what}: int_ior and ext_ior must differ")));
            }
            (
                Lobe::Dielectric {
                    distr,
                    int_ior: Ior::Constant(int as f32),
                    ext_ior: ext as f32,
                },
                TabulatedSpectrum::constant(1.0),
                false,
            )
        }
        "roughplastic" => {
            let alpha = alpha_of(cx, what, d)?;
            let int = ior_value(cx, &format!("{what}.int_ior"), d.get("int_ior"), 1.49)?;
            let ext = ior_value(cx, &format!("{what}.ext_ior"), d.get("ext_ior"), 1.000277)?;
            if int == ext {
                return Err(cx.err(format!("{what}: int_ior and ext_ior must differ")));
            }
            if d.contains_key("specular_reflectance") {
                return Err(cx.err(format!("{what}.specular_reflectance: not supported (leave it at 1)")));
            }
            let diffuse = spec("diffuse_reflectance", 0.5)?;
            let nonlinear = d.get("nonlinear").and_then(Value::as_bool).unwrap_or(false);
            let mean = diffuse.mean_over(360.0, 830.0);
            (
                bsdf::rough_plastic(alpha, (int / ext) as f32, mean, nonlinear),
                diffuse,
                false,
            )
        }
        other => {
            return Err(cx.err(format!(
                "{what}.type: \"{other}\" is not implemented (camsim has diffuse, conductor, roughconductor, dielectric, roughdielectric, roughplastic, twosided)"
            )))
        }
    })
}

fn dispersion_of(
    cx: &Ctx,
    what: &str,
    m: &gltf::Material,
    extras: &Option<Value>,
    n_d: f32,
) -> Result<Ior, RenderError> {
    if let Some(dv) = extras.as_ref().and_then(|e| e.get("dispersion")) {
        let num = |k: &str| dv.get(k).and_then(Value::as_f64);
        let arr3 = |k: &str| -> Option<[f32; 3]> {
            let a: Vec<f32> = dv
                .get(k)?
                .as_array()?
                .iter()
                .filter_map(Value::as_f64)
                .map(|x| x as f32)
                .collect();
            (a.len() == 3).then(|| [a[0], a[1], a[2]])
        };
        if let Some(v) = num("abbe_number") {
            if !(v > 0.0) {
                return Err(cx.err(format!("{what}: extras.dispersion.abbe_number must be > 0")));
            }
            return Ok(Ior::from_abbe(n_d, v as f32));
        }
        if let (Some(a), Some(b)) = (num("cauchy_a"), num("cauchy_b_um2")) {
            return Ok(Ior::Cauchy {
                a: a as f32,
                b_um2: b as f32,
            });
        }
        if let (Some(b), Some(c)) = (arr3("sellmeier_b"), arr3("sellmeier_c_um2")) {
            return Ok(Ior::Sellmeier { b, c_um2: c });
        }
        return Err(cx.err(format!(
            "{what}: extras.dispersion must be {{\"abbe_number\": V}}, {{\"cauchy_a\", \"cauchy_b_um2\"}} or {{\"sellmeier_b\": [3], \"sellmeier_c_um2\": [3]}}"
        )));
    }
    if let Some(d) = m
        .extensions()
        .and_then(|e| e.get("KHR_materials_dispersion"))
        .and_then(|v| v.get("dispersion"))
        .and_then(Value::as_f64)
    {
        if d > 0.0 {
            // KHR_materials_dispersion: dispersion = 20 / V_d
            return Ok(Ior::from_abbe(n_d, (20.0 / d) as f32));
        }
    }
    Ok(Ior::Constant(n_d))
}

fn convert_material(
    cx: &Ctx,
    m: &gltf::Material,
    base: &Path,
    buffers: &[gltf::buffer::Data],
    textures: &mut HashMap<usize, (u32, u32, Vec<[f32; 3]>)>,
) -> Result<Material, RenderError> {
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
    let what = format!("material {} (\"{name}\")", m.index().unwrap_or(0));
    let extras = extras_json(m.extras());
    let pbr = m.pbr_metallic_roughness();
    let base_rgb = pbr.base_color_factor();
    let spectral_refl = match extras.as_ref().and_then(|e| e.get("spectral_reflectance")) {
        Some(v) => Some(TabulatedSpectrum::from_spectrum(&spectral_extra(
            cx,
            &format!("{what}: extras.spectral_reflectance"),
            v,
        )?)),
        None => None,
    };
    let rough = pbr.roughness_factor();
    let metallic = pbr.metallic_factor();
    let (lobe, mut reflectance, mut two_sided) = if let Some(mb) =
        extras.as_ref().and_then(|e| e.get("mitsuba_bsdf"))
    {
        let (l, r, ts) = mitsuba_bsdf(cx, &format!("{what}: extras.mitsuba_bsdf"), mb)?;
        (l, SpectralTexture::Constant(r), ts)
    } else {
        let refl_const = spectral_refl.clone().unwrap_or_else(|| {
            spectral::rgb_reflectance([base_rgb[0] as f64, base_rgb[1] as f64, base_rgb[2] as f64])
        });
        let mut refl = SpectralTexture::Constant(refl_const);
        if spectral_refl.is_none() {
            if let Some(info) = pbr.base_color_texture() {
                refl = image_texture(
                    cx,
                    &what,
                    &info,
                    base,
                    buffers,
                    textures,
                    [base_rgb[0], base_rgb[1], base_rgb[2]],
                )?;
            }
        }
        let trans = m
            .transmission()
            .map(|t| t.transmission_factor())
            .unwrap_or(0.0);
        let alpha = rough * rough;
        let distr = (rough > 1e-3).then(|| Ggx::new(alpha));
        if trans > 0.0 {
            let n_d = m.ior().unwrap_or(1.5);
            if !(n_d >= 1.0) {
                return Err(cx.err(format!(
                    "{what}: KHR_materials_ior.ior = {n_d}, expected ≥ 1"
                )));
            }
            let ior = dispersion_of(cx, &what, m, &extras, n_d)?;
            (
                Lobe::Dielectric {
                    distr,
                    int_ior: ior,
                    ext_ior: 1.0,
                },
                SpectralTexture::Constant(TabulatedSpectrum::constant(1.0)),
                false,
            )
        } else if metallic >= 0.5 {
            (Lobe::Conductor { distr, eta_k: None }, refl, false)
        } else {
            (Lobe::Diffuse, refl, false)
        }
    };
    if m.double_sided() && !matches!(lobe, Lobe::Dielectric { .. }) {
        two_sided = true;
    }
    if let (Lobe::RoughPlastic { .. }, SpectralTexture::Image { .. }) = (&lobe, &reflectance) {
        reflectance = SpectralTexture::Constant(TabulatedSpectrum::constant(0.5));
    }
    // emission
    let mut emission = match extras.as_ref().and_then(|e| e.get("spectral_emission")) {
        Some(v) => Some(TabulatedSpectrum::from_spectrum(&spectral_extra(
            cx,
            &format!("{what}: extras.spectral_emission"),
            v,
        )?)),
        None => {
            let s = m.emissive_strength().unwrap_or(1.0);
            let e = m.emissive_factor().map(|v| (v * s) as f64);
            if e.iter().any(|v| !v.is_finite() || *v < 0.0) {
                return Err(cx.err(format!(
                    "{what}: emissiveFactor × emissiveStrength must be finite and ≥ 0"
                )));
            }
            e.iter()
                .any(|v| *v > 0.0)
                .then(|| spectral::rgb_emission(e))
        }
    };
    // emissive texture × emissiveFactor × strength (sRGB-decoded), unless a spectral emission
    // is given
    let mut emission_texture = None;
    let has_spectral_emission = extras
        .as_ref()
        .is_some_and(|e| e.get("spectral_emission").is_some());
    if let (Some(info), false) = (m.emissive_texture(), has_spectral_emission) {
        let s = m.emissive_strength().unwrap_or(1.0);
        let f = m.emissive_factor().map(|v| v * s);
        let (w, h, px) = raw_image(cx, &what, "emissiveTexture", &info.texture(), base, buffers)?;
        let rgb: Vec<[f32; 3]> = px
            .iter()
            .map(|p| [0, 1, 2].map(|k| srgb_to_linear(p[k] as f64 / 255.0) as f32 * f[k]))
            .collect();
        let image = crate::envmap::RadianceImage::from_rgb(w, h, &rgb);
        let t = crate::envmap::EmissionTexture::new(image, wrap_modes(&info.texture()));
        if t.max_value > 0.0 {
            emission_texture = Some(t);
        }
        // glTF: emission = factor × texture, so a black texture emits nothing (not the factor)
        emission = None;
    }
    let normal_map = match m.normal_texture() {
        Some(nt) => {
            let scale = nt.scale();
            if !scale.is_finite() {
                return Err(cx.err(format!(
                    "{what}: normalTexture.scale = {scale}: expected a finite number"
                )));
            }
            let (w, h, px) = raw_image(cx, &what, "normalTexture", &nt.texture(), base, buffers)?;
            Some(crate::normal_map::NormalMap {
                width: w,
                height: h,
                normals: px
                    .iter()
                    .map(|p| crate::normal_map::decode_texel(*p, scale))
                    .collect(),
                repeat: wrap_modes(&nt.texture()),
            })
        }
        None => None,
    };
    Ok(Material {
        name,
        bsdf: Bsdf { lobe, two_sided },
        reflectance,
        emission,
        emission_texture,
        normal_map,
    })
}

/// Coefficient table for texture upsampling: 17³ fits on a grid uniform in sRGB-encoded
/// values, interpolated trilinearly (Jakob & Hanika 2019 use a table the same way).
fn coefficient_table() -> &'static Vec<[f32; 3]> {
    use rayon::prelude::*;
    static T: std::sync::OnceLock<Vec<[f32; 3]>> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        const N: usize = 17;
        (0..N * N * N)
            .into_par_iter()
            .map(|i| {
                let (r, g, b) = (i / (N * N), (i / N) % N, i % N);
                let lin =
                    |k: usize| srgb_to_linear((k as f64 / (N - 1) as f64).clamp(0.004, 0.996));
                spectral::fit_rgb([lin(r), lin(g), lin(b)]).c
            })
            .collect()
    })
}

use camsim_core::colorimetry::{srgb_decode as srgb_to_linear, srgb_encode as linear_to_srgb};

/// Sigmoid-polynomial coefficients of a linear-RGB reflectance in [0, 1]³ from the loader's
/// 17³ coefficient table (trilinear; the upsampling of every texture, also emissive ones and
/// environment maps, [`crate::envmap`]).
pub fn rgb_to_poly(rgb: [f64; 3]) -> SigmoidPoly {
    table_lookup(rgb)
}

/// Coefficients for a linear-RGB colour from the table.
fn table_lookup(rgb: [f64; 3]) -> SigmoidPoly {
    const N: usize = 17;
    let t = coefficient_table();
    let x = rgb.map(|v| linear_to_srgb(v.clamp(0.0, 1.0)) * (N - 1) as f64);
    let i = x.map(|v| (v as usize).min(N - 2));
    let f = [x[0] - i[0] as f64, x[1] - i[1] as f64, x[2] - i[2] as f64];
    let mut c = [0.0f64; 3];
    for corner in 0..8 {
        let d = [(corner >> 2) & 1, (corner >> 1) & 1, corner & 1];
        let mut w = 1.0;
        for k in 0..3 {
            w *= if d[k] == 1 { f[k] } else { 1.0 - f[k] };
        }
        let idx = ((i[0] + d[0]) * N + (i[1] + d[1])) * N + (i[2] + d[2]);
        for k in 0..3 {
            c[k] += w * t[idx][k] as f64;
        }
    }
    SigmoidPoly {
        c: c.map(|v| v as f32),
    }
}

fn image_texture(
    cx: &Ctx,
    what: &str,
    info: &gltf::texture::Info,
    base: &Path,
    buffers: &[gltf::buffer::Data],
    cache: &mut HashMap<usize, (u32, u32, Vec<[f32; 3]>)>,
    factor: [f32; 3],
) -> Result<SpectralTexture, RenderError> {
    let tex = info.texture();
    let img = tex.source();
    let key = img.index();
    if !cache.contains_key(&key) {
        let (w, h, px) = raw_image(cx, what, "baseColorTexture", &tex, base, buffers)?;
        let lin = px
            .iter()
            .map(|p| p.map(|v| srgb_to_linear(v as f64 / 255.0) as f32))
            .collect();
        cache.insert(key, (w, h, lin));
    }
    let (w, h, px) = &cache[&key];
    let coeffs: Vec<SigmoidPoly> = px
        .iter()
        .map(|p| {
            table_lookup([
                (p[0] * factor[0]) as f64,
                (p[1] * factor[1]) as f64,
                (p[2] * factor[2]) as f64,
            ])
        })
        .collect();
    let mean = {
        let n = coeffs.len().max(1) as f32;
        coeffs.iter().map(|c| c.eval(560.0)).sum::<f32>() / n
    };
    Ok(SpectralTexture::Image {
        width: *w,
        height: *h,
        coeffs,
        repeat: wrap_modes(&tex),
        mean,
    })
}

/// Repeat (true) or clamp along u and v of a texture's sampler.
fn wrap_modes(tex: &gltf::Texture) -> [bool; 2] {
    use gltf::texture::WrappingMode;
    let s = tex.sampler();
    let rep = |m: WrappingMode| !matches!(m, WrappingMode::ClampToEdge);
    [rep(s.wrap_s()), rep(s.wrap_t())]
}

/// The 8-bit RGB texels of a texture's image (grey images repeated to RGB; alpha dropped).
fn raw_image(
    cx: &Ctx,
    what: &str,
    slot: &str,
    tex: &gltf::Texture,
    base: &Path,
    buffers: &[gltf::buffer::Data],
) -> Result<(u32, u32, Vec<[u8; 3]>), RenderError> {
    let img = tex.source();
    let key = img.index();
    let data = gltf::image::Data::from_source(img.source(), Some(base), buffers)
        .map_err(|e| cx.err(format!("{what}: {slot} image {key}: cannot load: {e}")))?;
    use gltf::image::Format;
    let ch = match data.format {
        Format::R8 => 1,
        Format::R8G8 => 2,
        Format::R8G8B8 => 3,
        Format::R8G8B8A8 => 4,
        f => {
            return Err(cx.err(format!(
                "{what}: {slot} image {key}: pixel format {f:?} not supported (8-bit only)"
            )))
        }
    };
    if data.width == 0 || data.height == 0 {
        return Err(cx.err(format!("{what}: {slot} image {key}: empty image")));
    }
    let px = data
        .pixels
        .chunks_exact(ch)
        .map(|p| {
            if ch >= 3 {
                [p[0], p[1], p[2]]
            } else {
                [p[0]; 3]
            }
        })
        .collect();
    Ok((data.width, data.height, px))
}

/// Resolve the camera to render: by node or camera name, else the first one.
pub fn pick_camera<'a>(scene: &'a Scene, name: Option<&str>) -> Result<&'a SceneCamera, String> {
    match name {
        None => scene.cameras.first().ok_or_else(|| "no camera".to_string()),
        Some(n) => scene.cameras.iter().find(|c| c.name == n).ok_or_else(|| {
            format!(
                "no camera named \"{n}\" (cameras: {})",
                scene
                    .cameras
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }),
    }
}

#[allow(dead_code)]
fn _assert_send_sync() {
    fn f<T: Send + Sync>() {}
    f::<Scene>();
    let _ = Mat4::IDENTITY;
}
