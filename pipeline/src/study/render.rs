//! The `"render"` point kind: glTF scenes through the render crate's cameras, measured on
//! the rendered images.
//!
//! `"task": "depth_of_field"` (study 2, docs/study_dof.md): the slanted-edge tiles of
//! [`camsim_render::dof_scene`] (one depth per tile) through a real lens at one f-number and
//! focus, rendered (a) with the real-lens camera (sensor irradiance, exit-pupil sampling) and
//! (b) with the depth path (pinhole radiance + depth → the lens's field-model PSF per depth).
//! Per tile and image the ISO 12233 MTF50 (cy/px); the depth of field is the range of
//! distances around focus where MTF50 ≥ a threshold, its ends interpolated linearly in
//! 1/MTF50 against vergence 1/z (a defocus blur's width is proportional to |1/z − 1/D|).
//!
//! ```json
//! {"kind": "render", "task": "depth_of_field",
//!  "scene": {"dof_tiles": {"depths_m": [...], "cols": 4, "yfov_deg": 2.5, "edge_angle_deg": 5}},
//!  "lens": {...prescription...}, "f_number": 4, "focus_distance_m": 2,
//!  "render": {"width_px": 128, "spp": 64, "pinhole_spp": 16, "band_nm": [500, 600], "layers": 32},
//!  "metrics": {"mtf50_threshold_cy_per_px": 0.15, "roi_fraction": 0.75}}
//! ```
use super::output::PointOutput;
use crate::error::CliError;
use camsim_core::stats::Rect;
use camsim_lens::{GlassCatalog, LensPrescription};
use camsim_metrics::slanted_edge_mtf;
use camsim_render::dof_scene::{render_dof, DofRenderOptions, DofTiles};
use serde::Deserialize;
use serde_json::{json, Value};
use std::path::Path;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct TilesDoc {
    depths_m: Vec<f64>,
    #[serde(default = "default_cols")]
    cols: usize,
    #[serde(default = "default_yfov")]
    yfov_deg: f64,
    #[serde(default = "default_angle")]
    edge_angle_deg: f64,
}
fn default_cols() -> usize {
    4
}
fn default_yfov() -> f64 {
    2.5
}
fn default_angle() -> f64 {
    5.0
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneDoc {
    dof_tiles: TilesDoc,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RenderDoc {
    #[serde(default = "default_width")]
    width_px: u32,
    #[serde(default = "default_spp")]
    spp: u32,
    #[serde(default = "default_pin_spp")]
    pinhole_spp: u32,
    #[serde(default = "default_band")]
    band_nm: [f64; 2],
    #[serde(default = "default_layers")]
    layers: usize,
}
fn default_width() -> u32 {
    128
}
fn default_spp() -> u32 {
    64
}
fn default_pin_spp() -> u32 {
    16
}
fn default_band() -> [f64; 2] {
    [500.0, 600.0]
}
fn default_layers() -> usize {
    32
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MetricsDoc {
    #[serde(default = "default_thr")]
    mtf50_threshold_cy_per_px: f64,
    #[serde(default = "default_roi")]
    roi_fraction: f64,
}
fn default_thr() -> f64 {
    0.15
}
fn default_roi() -> f64 {
    0.75
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct DofDoc {
    #[allow(dead_code)]
    kind: String,
    #[allow(dead_code)]
    task: String,
    scene: SceneDoc,
    lens: Value,
    f_number: f64,
    focus_distance_m: f64,
    /// `"best"` (default) or `"paraxial"` (camsim_lens::focus_model).
    #[serde(default)]
    focus_criterion: Option<String>,
    /// Best-focus merit frequency (cycles/mm; default half the pixel Nyquist).
    #[serde(default)]
    focus_frequency_cyc_per_mm: Option<f64>,
    /// Focusing group `[first, last]` (surfaces; default: unit focusing).
    #[serde(default)]
    focus_group_surfaces: Option<[usize; 2]>,
    #[serde(default)]
    render: Option<RenderDoc>,
    #[serde(default)]
    metrics: Option<MetricsDoc>,
    #[serde(default)]
    #[allow(dead_code)]
    seed: Option<u64>,
    #[serde(default)]
    #[allow(dead_code)]
    camsim_version: Option<String>,
}

fn parse_dof(doc: &Value) -> Result<DofDoc, String> {
    let d: DofDoc =
        serde_json::from_value(doc.clone()).map_err(|e| format!("render point: {e}"))?;
    let t = tiles_of(&d);
    t.validate().map_err(|m| format!("scene.dof_tiles: {m}"))?;
    if !(d.f_number.is_finite() && d.f_number > 0.0) {
        return Err(format!("f_number: must be > 0, got {}", d.f_number));
    }
    if !(d.focus_distance_m.is_finite() && d.focus_distance_m > 0.0) {
        return Err(format!(
            "focus_distance_m: must be > 0, got {}",
            d.focus_distance_m
        ));
    }
    let r = render_of(&d);
    if r.width_px < 16 || r.width_px > 4096 || r.spp == 0 || r.pinhole_spp == 0 {
        return Err(format!(
            "render: width_px must be 16–4096 and spp, pinhole_spp ≥ 1 (got {}, {}, {})",
            r.width_px, r.spp, r.pinhole_spp
        ));
    }
    if !(r.band_nm[0] > 0.0 && r.band_nm[1] > r.band_nm[0]) {
        return Err(format!(
            "render.band_nm: need 0 < lo < hi, got {:?}",
            r.band_nm
        ));
    }
    if r.layers == 0 || r.layers > 256 {
        return Err(format!("render.layers: must be 1–256, got {}", r.layers));
    }
    let m = metrics_of(&d);
    if !(m.mtf50_threshold_cy_per_px > 0.0 && m.mtf50_threshold_cy_per_px < 0.5) {
        return Err(format!(
            "metrics.mtf50_threshold_cy_per_px: must be in (0, 0.5), got {}",
            m.mtf50_threshold_cy_per_px
        ));
    }
    if !(m.roi_fraction > 0.2 && m.roi_fraction <= 1.0) {
        return Err(format!(
            "metrics.roi_fraction: must be in (0.2, 1], got {}",
            m.roi_fraction
        ));
    }
    lens_of(&d.lens)?;
    focus_method_of(&d)?;
    Ok(d)
}

fn focus_method_of(d: &DofDoc) -> Result<camsim_lens::FocusMethod, String> {
    camsim_lens::FocusMethod::from_keys(
        d.focus_criterion.as_deref(),
        d.focus_frequency_cyc_per_mm,
        d.focus_group_surfaces,
    )
}

fn tiles_of(d: &DofDoc) -> DofTiles {
    let t = &d.scene.dof_tiles;
    DofTiles {
        depths_m: t.depths_m.clone(),
        cols: t.cols,
        yfov_deg: t.yfov_deg,
        edge_angle_deg: t.edge_angle_deg,
    }
}
fn render_of(d: &DofDoc) -> RenderDoc {
    d.render.clone().unwrap_or(RenderDoc {
        width_px: default_width(),
        spp: default_spp(),
        pinhole_spp: default_pin_spp(),
        band_nm: default_band(),
        layers: default_layers(),
    })
}
fn metrics_of(d: &DofDoc) -> MetricsDoc {
    d.metrics.clone().unwrap_or(MetricsDoc {
        mtf50_threshold_cy_per_px: default_thr(),
        roi_fraction: default_roi(),
    })
}

fn lens_of(v: &Value) -> Result<LensPrescription, String> {
    let text = serde_json::to_string(v).expect("json");
    LensPrescription::from_json_str(&text, &GlassCatalog::bundled())
        .map_err(|e| format!("lens: {e}"))
}

/// The render tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Task {
    DepthOfField,
    LightField,
}

fn task_of(doc: &Value) -> Result<Task, String> {
    match doc.get("task").and_then(Value::as_str) {
        Some("depth_of_field") => Ok(Task::DepthOfField),
        Some("light_field") => Ok(Task::LightField),
        Some(o) => Err(format!(
            "task: unknown render task \"{o}\" (expected \"depth_of_field\" or \"light_field\")"
        )),
        None => Err("task: required (\"depth_of_field\" or \"light_field\")".into()),
    }
}

/// Check a render point document (cheap: nothing rendered).
pub fn validate(doc: &Value) -> Result<(), String> {
    match task_of(doc)? {
        Task::DepthOfField => parse_dof(doc).map(|_| ()),
        Task::LightField => lightfield::parse(doc).map(|_| ()),
    }
}

/// Evaluate a render point into `dir`.
pub fn evaluate(doc: &Value, seed: u64, dir: &Path) -> Result<PointOutput, CliError> {
    match task_of(doc).map_err(CliError::Other)? {
        Task::DepthOfField => evaluate_dof(doc, seed, dir),
        Task::LightField => lightfield::evaluate(doc, seed, dir),
    }
}

/// A depth-of-field estimate from MTF50 against depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DofRange {
    /// Near limit (m).
    pub near_m: f64,
    /// Far limit (m; ∞ when the far vergence reaches 0).
    pub far_m: f64,
    /// Width in vergence (1/m): 1/near − 1/far.
    pub width_per_m: f64,
    /// Whether a limit hit the end of the measured depths (then the range is a lower bound).
    pub censored: bool,
}

/// The depth of field from MTF50 samples (vergence 1/z in 1/m, MTF50 in cy/px; `None` = not
/// measurable (no edge found in the noise of a strongly blurred tile) → skipped): the contiguous
/// vergence interval around the sharpest sample where MTF50 ≥ `threshold`, its ends
/// interpolated linearly in 1/MTF50 (∝ blur width, linear in |Δ(1/z)| for defocus).
pub fn dof_range(samples: &[(f64, Option<f64>)], threshold: f64) -> Option<DofRange> {
    let mut s: Vec<(f64, f64)> = samples
        .iter()
        .filter_map(|(v, m)| m.map(|m| (*v, m.max(1e-6))))
        .collect();
    s.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    let best = (0..s.len()).max_by(|a, b| s[*a].1.partial_cmp(&s[*b].1).unwrap())?;
    if s[best].1 < threshold {
        return None;
    }
    let cross = |a: (f64, f64), b: (f64, f64)| {
        let (ia, ib, it) = (1.0 / a.1, 1.0 / b.1, 1.0 / threshold);
        a.0 + (it - ia) / (ib - ia) * (b.0 - a.0)
    };
    let mut censored = false;
    // towards larger vergence (nearer)
    let mut k = best;
    while k + 1 < s.len() && s[k + 1].1 >= threshold {
        k += 1;
    }
    let v_near = if k + 1 < s.len() {
        cross(s[k], s[k + 1])
    } else {
        censored = true;
        s[k].0
    };
    let mut k = best;
    while k > 0 && s[k - 1].1 >= threshold {
        k -= 1;
    }
    let v_far = if k > 0 {
        cross(s[k], s[k - 1])
    } else {
        censored = true;
        s[k].0
    };
    let v_far = v_far.max(0.0);
    Some(DofRange {
        near_m: 1.0 / v_near,
        far_m: if v_far > 0.0 {
            1.0 / v_far
        } else {
            f64::INFINITY
        },
        width_per_m: v_near - v_far,
        censored,
    })
}

/// Vergence (1/m) of the peak of MTF50 vs vergence: the vertex of the parabola through the
/// best sample and its two neighbours in vergence (the best sample itself at the ends).
fn through_focus_peak_per_m(s: &[(f64, Option<f64>)]) -> Option<f64> {
    let mut v: Vec<(f64, f64)> = s.iter().filter_map(|p| Some((p.0, p.1?))).collect();
    v.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    let k = (0..v.len()).max_by(|&a, &b| v[a].1.partial_cmp(&v[b].1).unwrap())?;
    if k == 0 || k + 1 == v.len() {
        return Some(v[k].0);
    }
    let ((x0, y0), (x1, y1), (x2, y2)) = (v[k - 1], v[k], v[k + 1]);
    // Lagrange parabola through three points; vertex where its derivative vanishes.
    let d1 = (y1 - y0) / (x1 - x0);
    let d2 = (y2 - y1) / (x2 - x1);
    let a = (d2 - d1) / (x2 - x0);
    if !(a < 0.0) {
        return Some(x1);
    }
    Some((0.5 * (x0 + x1) - d1 / (2.0 * a)).clamp(x0, x2))
}

pub(super) fn grey_png(path: &Path, img: &[f32], w: usize, h: usize) -> Result<(), CliError> {
    let max = img.iter().cloned().fold(0f32, f32::max).max(1e-30);
    let rgb: Vec<u8> = img
        .iter()
        .flat_map(|v| {
            // display gamma 1/2.2
            let g = ((v / max).clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8;
            [g, g, g]
        })
        .collect();
    crate::plots::rgb8_png(path, &rgb, h, w)
}

/// MTF50 of a 100 %-fill square pixel aperture alone: the root of sin(πf)/(πf) = ½ (cy/px).
const PIXEL_BOX_MTF50_CY_PER_PX: f64 = 0.6034;

fn evaluate_dof(doc: &Value, seed: u64, dir: &Path) -> Result<PointOutput, CliError> {
    let d = parse_dof(doc).map_err(CliError::Other)?;
    let tiles = tiles_of(&d);
    let r = render_of(&d);
    let m = metrics_of(&d);
    let lens = lens_of(&d.lens).map_err(CliError::Other)?;
    let out_r = render_dof(
        &tiles,
        &lens,
        &DofRenderOptions {
            width_px: r.width_px,
            spp_lens: r.spp,
            spp_pinhole: r.pinhole_spp,
            seed,
            band_nm: (r.band_nm[0], r.band_nm[1]),
            f_number: d.f_number,
            focus_distance_m: d.focus_distance_m,
            layers: r.layers,
            real_lens: true,
            focus_method: focus_method_of(&d).map_err(CliError::Other)?,
        },
    )
    .map_err(|e| CliError::Other(format!("render: {e}")))?;
    let (w, h) = (out_r.width, out_r.height);
    let real = out_r.real_lens.as_ref().expect("rendered");
    grey_png(&dir.join("real_lens.png"), real, w, h)?;
    grey_png(&dir.join("depth_path.png"), &out_r.depth_path, w, h)?;
    let mtf = |img: &[f32], k: usize| -> Option<f64> {
        let c = tiles.cell_px(k, w as u32, h as u32);
        let half = 0.5 * m.roi_fraction * (c.x1 - c.x0);
        let (xc, yc) = (0.5 * (c.x0 + c.x1), 0.5 * (c.y0 + c.y1));
        let roi = Rect {
            row0: (yc - half).ceil() as usize,
            row1: (yc + half).floor() as usize,
            col0: (xc - half).ceil() as usize,
            col1: (xc + half).floor() as usize,
        };
        let e = slanted_edge_mtf(img, h, w, roi).ok()?;
        // Both images integrate over the full pixel (the renderer's box filter), so the system
        // MTF is at most the pixel aperture's, sinc(f) = sin(πf)/(πf), and MTF50 cannot exceed
        // the box's 0.6034 cy/px: a larger value is the slanted-edge fit failing on the Monte
        // Carlo noise of a strongly blurred tile, i.e. not measurable.
        e.mtf50_cycles_per_pixel
            .filter(|f| *f <= PIXEL_BOX_MTF50_CY_PER_PX)
    };
    let mut per = Vec::new();
    for (k, z) in tiles.depths_m.iter().enumerate() {
        per.push((1.0 / z, mtf(real, k), mtf(&out_r.depth_path, k)));
    }
    let thr = m.mtf50_threshold_cy_per_px;
    let lens_s: Vec<(f64, Option<f64>)> = per.iter().map(|p| (p.0, p.1)).collect();
    let dp_s: Vec<(f64, Option<f64>)> = per.iter().map(|p| (p.0, p.2)).collect();
    let dl = dof_range(&lens_s, thr);
    let dd = dof_range(&dp_s, thr);
    let mut out = PointOutput::default();
    out.put("pixel_pitch_um", out_r.pixel_pitch_mm * 1e3);
    // Focus (camsim_lens::focus_model), shared by both paths.
    let fz = &out_r.focus;
    out.put(
        "focus_image_shift_mm",
        fz.image_distance_mm - fz.paraxial_image_distance_mm,
    );
    out.put("focus_group_shift_mm", fz.group_shift_mm);
    out.put("focus_mtf", fz.mtf);
    out.put("focus_mtf_paraxial", fz.mtf_paraxial);
    // Through focus: the vergence of the MTF50 peak (vertex of the parabola through the best
    // tile and its neighbours in 1/z), as an object distance, and its image-side distance from
    // the focus plane, Δs' = s'² Δv (Gauss, s' = 1/(1/f − 1/D) the image distance of the
    // focus from the principal plane). The depth of focus is ±N_w c with the circle of
    // confusion c the disc diameter at the DoF threshold, 2·0.3526/thr px (below), and the
    // working F-number N_w = N s'/f.
    let efl_mm = fz
        .lens
        .first_order(fz.lens.primary_nm)
        .map_err(|e| CliError::Other(e.to_string()))?
        .efl_mm;
    let s_img_mm = 1.0 / (1.0 / efl_mm - 1.0 / (d.focus_distance_m * 1e3));
    let coc_mm = 2.0 * 0.3526 / m.mtf50_threshold_cy_per_px * out_r.pixel_pitch_mm;
    out.put("depth_of_focus_mm", d.f_number * s_img_mm / efl_mm * coc_mm);
    for (name, s) in [("lens", &lens_s), ("depth_path", &dp_s)] {
        if let Some(v) = through_focus_peak_per_m(s) {
            out.put(&format!("focus_peak_{name}_m"), 1.0 / v);
            out.put(
                &format!("focus_peak_{name}_image_mm"),
                s_img_mm * s_img_mm * (v - 1.0 / d.focus_distance_m) * 1e-3,
            );
        }
    }
    out.put(
        "mtf50_focus_lens_cy_per_px",
        lens_s.iter().filter_map(|p| p.1).fold(0.0, f64::max),
    );
    out.put(
        "mtf50_focus_depth_path_cy_per_px",
        dp_s.iter().filter_map(|p| p.1).fold(0.0, f64::max),
    );
    out.put_opt("dof_near_lens_m", dl.map(|x| x.near_m));
    out.put_opt("dof_far_lens_m", dl.map(|x| x.far_m));
    out.put_opt("dof_near_depth_path_m", dd.map(|x| x.near_m));
    out.put_opt("dof_far_depth_path_m", dd.map(|x| x.far_m));
    out.put_opt("dof_lens_per_m", dl.map(|x| x.width_per_m));
    out.put_opt("dof_depth_path_per_m", dd.map(|x| x.width_per_m));
    out.put_opt(
        "dof_agreement_pct",
        dl.zip(dd)
            .map(|(a, b)| 100.0 * (b.width_per_m / a.width_per_m - 1.0)),
    );
    // thin-lens expectation with the entrance pupil as aperture: the defocus disc radius
    // c = R_ep |Δv| F_px reaches the threshold's disc radius 0.3526/thr (disc MTF = 0.5 at
    // 2π f c ≈ 2.215), so Δv_half = 0.3526 / (thr · R_ep · F_px)
    let f_px = h as f64 / (2.0 * (0.5 * tiles.yfov_deg.to_radians()).tan());
    out.put(
        "dof_thin_lens_per_m",
        2.0 * 0.3526 / (thr * out_r.entrance_pupil_radius_m * f_px),
    );
    // per-depth MTF50 figure
    let curve = |s: &[(f64, Option<f64>)]| -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = s.iter().filter_map(|p| Some((1.0 / p.0, p.1?))).collect();
        v.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
        v
    };
    let zs: Vec<f64> = tiles.depths_m.clone();
    let (zmin, zmax) = zs
        .iter()
        .fold((f64::INFINITY, 0f64), |(a, b), z| (a.min(*z), b.max(*z)));
    crate::plots::line_plot(
        &dir.join("mtf50_vs_depth.png"),
        &format!("MTF50 vs depth, f/{}", d.f_number),
        &[
            ("real lens".to_string(), curve(&lens_s)),
            ("depth path".to_string(), curve(&dp_s)),
            (format!("threshold {thr}"), vec![(zmin, thr), (zmax, thr)]),
        ],
        ("object distance (m)", "MTF50 (cy/px)"),
    )?;
    out.images = vec![
        ("real_lens.png".into(), "real-lens render".into()),
        (
            "depth_path.png".into(),
            "depth path (pinhole + lens PSFs)".into(),
        ),
        ("mtf50_vs_depth.png".into(), "MTF50 per depth".into()),
    ];
    out.detail = json!({
        "depths_m": zs,
        "mtf50_lens_cy_per_px": per.iter().map(|p| p.1).collect::<Vec<_>>(),
        "mtf50_depth_path_cy_per_px": per.iter().map(|p| p.2).collect::<Vec<_>>(),
        "dof_lens_censored": dl.map(|x| x.censored),
        "dof_depth_path_censored": dd.map(|x| x.censored),
    });
    // Wall times are not results: they would make two identical runs' files differ.
    eprintln!("camsim: study point render times {:?} s", out_r.times_s);
    Ok(out)
}

/// `"task": "light_field"` (study 3, docs/study_lightfield.md): tiles at several depths
/// (the slanted-edge scene of [`camsim_render::dof_scene`]) through a plenoptic camera (thin
/// main lens + microlens array, [`camsim_render::camera::lightfield`]); the sub-aperture
/// views, shift-and-add refocusing at every tile depth, and the same scene through the same
/// main lens without the MLA (thin-lens camera at the raw sensor's pixel pitch and field).
/// MTF50 of every tile in every refocused image (cy per view pixel = per microlens) and of
/// the in-focus tile in the full-resolution image (cy/px); the resolution loss factor is
/// MTF50_full / (MTF50_refocused / n) with n pixels per microlens (the refocused image has
/// one pixel per microlens).
///
/// ```json
/// {"kind": "render", "task": "light_field",
///  "scene": {"depths_m": [1, 2, 8], "edge_angle_deg": 5},
///  "main_lens": {"focal_length_mm": 50, "f_number": 4}, "focus_distance_m": 2,
///  "mla": {"microlens_pitch_um": 100, "microlens_focal_length_um": 410,
///          "pixels_per_microlens": 7, "microlenses_per_tile": 32},
///  "render": {"spp": 16, "band_nm": [500, 600]},
///  "metrics": {"roi_fraction": 0.75}}
/// ```
mod lightfield {
    use super::{grey_png, PointOutput};
    use crate::error::CliError;
    use camsim_core::stats::Rect;
    use camsim_metrics::slanted_edge_mtf;
    use camsim_render::camera::lightfield::{refocus, LightFieldCamera, MainLens};
    use camsim_render::camera::ThinLens;
    use camsim_render::dof_scene::DofTiles;
    use camsim_render::{render, Bands, RenderSettings};
    use serde::Deserialize;
    use serde_json::{json, Value};
    use std::path::Path;

    #[derive(Debug, Clone, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct SceneDoc {
        depths_m: Vec<f64>,
        #[serde(default = "super::default_angle")]
        edge_angle_deg: f64,
    }
    #[derive(Debug, Clone, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct MainDoc {
        focal_length_mm: f64,
        f_number: f64,
    }
    #[derive(Debug, Clone, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct MlaDoc {
        microlens_pitch_um: f64,
        microlens_focal_length_um: f64,
        pixels_per_microlens: u32,
        microlenses_per_tile: u32,
    }
    #[derive(Debug, Clone, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct RenderDoc {
        #[serde(default = "default_spp")]
        spp: u32,
        #[serde(default = "super::default_band")]
        band_nm: [f64; 2],
    }
    fn default_spp() -> u32 {
        16
    }
    #[derive(Debug, Clone, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct MetricsDoc {
        #[serde(default = "super::default_roi")]
        roi_fraction: f64,
    }
    #[derive(Debug, Clone, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub(super) struct LfDoc {
        #[allow(dead_code)]
        kind: String,
        #[allow(dead_code)]
        task: String,
        scene: SceneDoc,
        main_lens: MainDoc,
        focus_distance_m: f64,
        mla: MlaDoc,
        #[serde(default)]
        render: Option<RenderDoc>,
        #[serde(default)]
        metrics: Option<MetricsDoc>,
        #[serde(default)]
        #[allow(dead_code)]
        seed: Option<u64>,
        #[serde(default)]
        #[allow(dead_code)]
        camsim_version: Option<String>,
    }

    struct Setup {
        cam: LightFieldCamera,
        tiles: DofTiles,
        width_px: u32,
        height_px: u32,
    }

    fn setup(d: &LfDoc) -> Result<Setup, String> {
        let m = &d.mla;
        if m.pixels_per_microlens == 0 || m.pixels_per_microlens > 32 {
            return Err(format!(
                "mla.pixels_per_microlens: must be 1–32, got {}",
                m.pixels_per_microlens
            ));
        }
        if m.microlenses_per_tile < 16 || m.microlenses_per_tile > 256 {
            return Err(format!(
                "mla.microlenses_per_tile: must be 16–256 (the slanted edge needs ≥ 16), got {}",
                m.microlenses_per_tile
            ));
        }
        let cols = d.scene.depths_m.len().max(1);
        let (n, t) = (m.pixels_per_microlens, m.microlenses_per_tile);
        let (w, h) = (n * t * cols as u32, n * t);
        let cam = LightFieldCamera::new(
            MainLens::Thin {
                focal_length_mm: d.main_lens.focal_length_mm,
                f_number: d.main_lens.f_number,
            },
            d.focus_distance_m,
            m.microlens_pitch_um,
            m.microlens_focal_length_um,
            None,
            n,
            w,
            h,
        )
        .map_err(|e| e.to_string())?;
        // field of the MLA seen through the main-lens centre: tan(θ/2) = (H/n)·p_μ / (2b)
        let i = cam.info();
        let yfov_deg = 2.0 * ((t as f64 * i.microlens_pitch_mm) / (2.0 * i.mla_distance_mm)).atan();
        let tiles = DofTiles {
            depths_m: d.scene.depths_m.clone(),
            cols,
            yfov_deg: yfov_deg.to_degrees(),
            edge_angle_deg: d.scene.edge_angle_deg,
        };
        tiles.validate().map_err(|e| format!("scene: {e}"))?;
        Ok(Setup {
            cam,
            tiles,
            width_px: w,
            height_px: h,
        })
    }

    pub(super) fn parse(doc: &Value) -> Result<LfDoc, String> {
        let d: LfDoc =
            serde_json::from_value(doc.clone()).map_err(|e| format!("render point: {e}"))?;
        if d.scene.depths_m.is_empty() || d.scene.depths_m.len() > 8 {
            return Err(format!(
                "scene.depths_m: need 1–8 depths, got {}",
                d.scene.depths_m.len()
            ));
        }
        let r = render_of(&d);
        if r.spp == 0 || r.spp > 4096 {
            return Err(format!("render.spp: must be 1–4096, got {}", r.spp));
        }
        if !(r.band_nm[0] > 0.0 && r.band_nm[1] > r.band_nm[0]) {
            return Err(format!(
                "render.band_nm: need 0 < lo < hi, got {:?}",
                r.band_nm
            ));
        }
        let roi = metrics_of(&d).roi_fraction;
        if !(roi > 0.2 && roi <= 1.0) {
            return Err(format!(
                "metrics.roi_fraction: must be in (0.2, 1], got {roi}"
            ));
        }
        setup(&d)?;
        Ok(d)
    }

    fn render_of(d: &LfDoc) -> RenderDoc {
        d.render.clone().unwrap_or(RenderDoc {
            spp: default_spp(),
            band_nm: super::default_band(),
        })
    }
    fn metrics_of(d: &LfDoc) -> MetricsDoc {
        d.metrics.clone().unwrap_or(MetricsDoc {
            roi_fraction: super::default_roi(),
        })
    }

    /// ISO 12233 MTF50 (cy/px) of tile `k` in a `w × h` image; `None` when no edge is found.
    fn tile_mtf50(
        tiles: &DofTiles,
        img: &[f32],
        w: usize,
        h: usize,
        k: usize,
        roi_f: f64,
    ) -> Option<f64> {
        let c = tiles.cell_px(k, w as u32, h as u32);
        let half = 0.5 * roi_f * (c.x1 - c.x0);
        let (xc, yc) = (0.5 * (c.x0 + c.x1), 0.5 * (c.y0 + c.y1));
        let roi = Rect {
            row0: (yc - half).ceil() as usize,
            row1: (yc + half).floor() as usize,
            col0: (xc - half).ceil() as usize,
            col1: (xc + half).floor() as usize,
        };
        slanted_edge_mtf(img, h, w, roi)
            .ok()?
            .mtf50_cycles_per_pixel
    }

    pub(super) fn evaluate(doc: &Value, seed: u64, dir: &Path) -> Result<PointOutput, CliError> {
        let d = parse(doc).map_err(CliError::Other)?;
        let s = setup(&d).map_err(CliError::Other)?;
        let r = render_of(&d);
        let roi_f = metrics_of(&d).roi_fraction;
        let tmp = dir.join(".scene_tmp");
        std::fs::create_dir_all(&tmp)
            .map_err(|e| CliError::Other(format!("{}: {e}", tmp.display())))?;
        let path = tmp.join("tiles.gltf");
        s.tiles
            .builder()
            .write(&path)
            .map_err(|e| CliError::Other(format!("{}: {e}", path.display())))?;
        let scene = camsim_render::gltf_load::load_gltf(&path);
        let _ = std::fs::remove_dir_all(&tmp);
        let scene = scene.map_err(|e| CliError::Other(format!("scene: {e}")))?;
        let sc = camsim_render::gltf_load::pick_camera(&scene, None).map_err(CliError::Other)?;
        let bands = Bands::new(r.band_nm[0], r.band_nm[1], r.band_nm[1] - r.band_nm[0])
            .map_err(|e| CliError::Other(format!("render.band_nm: {e}")))?;
        let settings = |seed: u64| RenderSettings {
            spp: r.spp,
            seed,
            bands: bands.clone(),
            variance: false,
            depth_spp: 0,
            ..Default::default()
        };
        let (w, h) = (s.width_px, s.height_px);
        let t0 = std::time::Instant::now();
        let raw = render(&scene, &s.cam, sc.to_world, &settings(seed), None).band_planes[0].clone();
        let t1 = std::time::Instant::now();
        // the same main lens without the MLA: thin lens of aperture radius F/2N focused at D,
        // sensor pixels of the raw light-field sensor's pitch over the same field
        let full_cam = ThinLens {
            perspective: sc.perspective(w, h),
            aperture_radius_m: (d.main_lens.focal_length_mm / (2.0 * d.main_lens.f_number) * 1e-3)
                as f32,
            focus_distance_m: d.focus_distance_m as f32,
        };
        let full = render(
            &scene,
            &full_cam,
            sc.to_world,
            &settings(seed ^ 0x5bd1_e995),
            None,
        )
        .band_planes[0]
            .clone();
        let t2 = std::time::Instant::now();
        let n = d.mla.pixels_per_microlens as usize;
        let (wu, hu) = (w as usize, h as usize);
        let (vw, vh) = (wu / n, hu / n);
        let views = s.cam.sub_aperture_views(&raw);
        // grid of the n × n sub-aperture views (view (u, v) at column u, row v)
        let mut grid = vec![0f32; wu * hu];
        for (k, v) in views.iter().enumerate() {
            let (u, vv) = (k % n, k / n);
            for j in 0..vh {
                let row = (vv * vh + j) * wu + u * vw;
                grid[row..row + vw].copy_from_slice(&v[j * vw..(j + 1) * vw]);
            }
        }
        grey_png(&dir.join("sub_aperture_views.png"), &grid, wu, hu)?;
        grey_png(&dir.join("full_resolution.png"), &full, wu, hu)?;
        let depths = s.tiles.depths_m.clone();
        let nt = depths.len();
        let mut out = PointOutput::default();
        let mut matrix = Vec::new();
        let mut images = vec![(
            "sub_aperture_views.png".to_string(),
            format!("{n} × {n} sub-aperture views"),
        )];
        let mut series = Vec::new();
        for (a, &za) in depths.iter().enumerate() {
            let shift = s.cam.disparity_per_view(za);
            let img = refocus(&views, n, vw, vh, shift);
            let name = format!("refocus_{a}.png");
            grey_png(&dir.join(&name), &img, vw, vh)?;
            images.push((name, format!("refocused at {za} m")));
            let row: Vec<Option<f64>> = (0..nt)
                .map(|k| tile_mtf50(&s.tiles, &img, vw, vh, k, roi_f))
                .collect();
            out.put_opt(&format!("mtf50_refocus{a}_own_tile_cy_per_view_px"), row[a]);
            series.push((
                format!("refocused at {za} m"),
                depths
                    .iter()
                    .zip(&row)
                    .filter_map(|(z, m)| Some((*z, (*m)?)))
                    .collect::<Vec<_>>(),
            ));
            matrix.push(row);
        }
        images.push((
            "full_resolution.png".into(),
            "same main lens, no MLA".into(),
        ));
        // the in-focus tile (nearest the focus distance)
        let kf = (0..nt)
            .min_by(|a, b| {
                let e = |k: usize| (1.0 / depths[k] - 1.0 / d.focus_distance_m).abs();
                e(*a).partial_cmp(&e(*b)).unwrap()
            })
            .unwrap_or(0);
        let full_mtf = tile_mtf50(&s.tiles, &full, wu, hu, kf, roi_f);
        let lf_mtf = matrix[kf][kf];
        out.put("pixels_per_microlens", n as f64);
        out.put(
            "disparity_max_px_per_view",
            depths
                .iter()
                .map(|z| s.cam.disparity_per_view(*z).abs())
                .fold(0.0, f64::max),
        );
        out.put_opt("mtf50_full_res_focus_cy_per_px", full_mtf);
        // refocused MTF50 in cycles per raw-sensor pixel (one view pixel = n sensor pixels)
        out.put_opt(
            "mtf50_lf_focus_cy_per_sensor_px",
            lf_mtf.map(|m| m / n as f64),
        );
        out.put_opt(
            "resolution_loss_factor",
            full_mtf.zip(lf_mtf).map(|(f, l)| f / (l / n as f64)),
        );
        crate::plots::line_plot(
            &dir.join("mtf50_per_tile.png"),
            "MTF50 of each tile in each refocused image",
            &series,
            ("tile depth (m)", "MTF50 (cy per microlens)"),
        )?;
        images.push((
            "mtf50_per_tile.png".into(),
            "MTF50 per tile and refocus depth".into(),
        ));
        out.images = images;
        out.detail = json!({
            "depths_m": depths,
            "in_focus_tile": kf,
            "mtf50_refocus_cy_per_view_px": matrix,
            "disparity_px_per_view": depths.iter().map(|z| s.cam.disparity_per_view(*z)).collect::<Vec<_>>(),
            "raw_px": [w, h],
            "views_px": [vw, vh],
        });
        // Wall times are not results (they would make identical runs' files differ).
        eprintln!(
            "camsim: light-field render times {:.2} s, {:.2} s",
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64()
        );
        Ok(out)
    }
}
