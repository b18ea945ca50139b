//! Shot targets as written in captures.json (spec kinds `dark`, `uniform`, `patches`,
//! `slanted_edge`, `image`, plus camsim's `macbeth`, `ramp`, `frequency_sweep`,
//! `point_array`, `grid_lines`; docs/config.md) → [`Target`] with photon-unit spectra.
use crate::spectrum_file::to_photons;
use camsim_core::constants::SI;
use camsim_core::data;
use camsim_core::exr_io;
use camsim_core::scene::Target;
use camsim_core::spectrum::Spectrum;
use camsim_sensor::SensorModel;
use serde_json::{Map, Value};
use std::path::Path;

/// A parsed target and what the scene keeps with it.
#[derive(Debug, Clone, PartialEq)]
pub struct ParsedTarget {
    /// The target (photon units).
    pub target: Target,
    /// Scale the scene to this mean luminance over the sensor (cd/m²).
    pub mean_luminance_cd_m2: Option<f64>,
    /// The illuminant (photons) when the target is reflectance × illuminant.
    pub illuminant: Option<Spectrum>,
    /// `patches` extension `labels`: where each patch is in the recorded frames (used by
    /// `camsim calibrate`; simulation keeps the spec's chart geometry).
    pub patch_labels: Option<std::sync::Arc<crate::raw_input::PatchLabels>>,
    /// Field of view, distance, illuminant swap and the illuminant's source (the keys every
    /// target accepts; docs/config.md "Scenes from the world").
    pub world: crate::world_targets::SceneWorld,
    /// A `gltf` target (then `target` is [`Target::Rendered`]): the scene file and its render
    /// settings ([`crate::gltf_target`]).
    pub gltf: Option<std::sync::Arc<crate::gltf_target::GltfTarget>>,
}

const KINDS: &str = "dark, uniform, patches, slanted_edge, image, cube, gltf, macbeth, ramp, frequency_sweep, point_array, grid_lines";

struct Obj<'a> {
    m: &'a Map<String, Value>,
    photons: bool,
}

impl<'a> Obj<'a> {
    fn allow(&self, keys: &[&str]) -> Result<(), String> {
        for k in self.m.keys() {
            if k != "kind"
                && k != "radiance_unit"
                && k != "mean_luminance_cd_m2"
                && !crate::world_targets::COMMON_KEYS.contains(&k.as_str())
                && !keys.contains(&k.as_str())
            {
                let kind = self.m["kind"].as_str().unwrap_or("");
                return Err(format!(
                    ".{k}: unknown key for a target of kind \"{kind}\" (allowed: {})",
                    keys.join(", ")
                ));
            }
        }
        Ok(())
    }
    fn num(&self, k: &str, default: Option<f64>) -> Result<f64, String> {
        match self.m.get(k) {
            None => default.ok_or_else(|| format!(".{k}: required")),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!(".{k}: must be a number")),
        }
    }
    fn count(&self, k: &str) -> Result<usize, String> {
        let v = self.num(k, None)?;
        if v < 1.0 || v.fract() != 0.0 {
            return Err(format!(".{k}: must be a positive integer, got {v}"));
        }
        Ok(v as usize)
    }
    /// A radiance spectrum in photon units (converted from W unless radiance_unit = photons).
    fn radiance(&self, k: &str, default: Option<f64>) -> Result<Spectrum, String> {
        let s = match self.m.get(k) {
            None => Spectrum::constant(default.ok_or_else(|| format!(".{k}: required"))?),
            Some(v) => spectrum(v).map_err(|e| format!(".{k}: {e}"))?,
        };
        radiance_checked(s, k, self.photons)
    }
}

/// The largest spectral radiance a target may give, W/(sr·m²·nm): 1e15, eight orders above
/// the sun's disc (~2e7). Beyond ~1e20 the photon radiance no longer fits the f32 scene planes
/// (it becomes +∞), so larger values are refused rather than silently turned into ∞ or NaN.
pub const MAX_RADIANCE_W: f64 = 1e15;

/// The largest `mean_luminance_cd_m2`: 1e12 cd/m², three orders above the sun's disc (1.6e9).
pub const MAX_LUMINANCE_CD_M2: f64 = 1e12;

fn radiance_checked(s: Spectrum, k: &str, photons: bool) -> Result<Spectrum, String> {
    if let Some((w, v)) = s.first_negative() {
        return Err(format!(".{k}: negative radiance {v} at {w} nm"));
    }
    // photons/(s·sr·m²·nm) at 1000 nm per W/(sr·m²·nm): λ/(hc) ≈ 5.03e18.
    let max = if photons {
        MAX_RADIANCE_W * 5.03e18
    } else {
        MAX_RADIANCE_W
    };
    let peak = match &s {
        Spectrum::Sampled { values, .. } => values.iter().fold(0.0f64, |a, &v| a.max(v.abs())),
        Spectrum::Affine { .. } => (300..=1200)
            .step_by(10)
            .fold(0.0f64, |a, w| a.max(s.eval(w as f64).abs())),
    };
    if !(peak <= max) {
        return Err(format!(
            ".{k}: radiance {peak:e} is over the limit of {max:e} {} (no physical source is \
             that bright; docs/limits.md)",
            if photons {
                "photons/(s·sr·m²·nm)"
            } else {
                "W/(sr·m²·nm)"
            }
        ));
    }
    Ok(if photons { s } else { to_photons(&s) })
}

fn spectrum(v: &Value) -> Result<Spectrum, String> {
    serde_json::from_value::<crate::spectrum_file::SpectrumValue>(v.clone())
        .map(|s| s.0)
        .map_err(|e| e.to_string())
}

/// Parse one target object. Errors start with the key path below `target` (".radiance: …").
pub fn target_from_value(
    v: &Value,
    dir: &Path,
    sensor: &SensorModel,
) -> Result<ParsedTarget, String> {
    let m = v.as_object().ok_or(": must be an object with a \"kind\"")?;
    let kind = m
        .get("kind")
        .and_then(Value::as_str)
        .ok_or(".kind: required (a string)")?;
    let photons = match m.get("radiance_unit").map(|u| u.as_str()) {
        None => false,
        Some(Some("photons")) => true,
        Some(Some("W")) | Some(Some("watts")) => false,
        Some(other) => {
            return Err(format!(
                ".radiance_unit: expected \"photons\" (or \"W\", the default), got {}",
                other
                    .map(|s| format!("\"{s}\""))
                    .unwrap_or("a non-string".into())
            ))
        }
    };
    let o = Obj { m, photons };
    let mean_luminance_cd_m2 = match m.get("mean_luminance_cd_m2") {
        None => None,
        Some(_) => {
            let l = o.num("mean_luminance_cd_m2", None)?;
            if !(0.0..=MAX_LUMINANCE_CD_M2).contains(&l) {
                return Err(format!(
                    ".mean_luminance_cd_m2: must be in [0, {MAX_LUMINANCE_CD_M2:e}] cd/m², got {l}"
                ));
            }
            Some(l)
        }
    };
    let pitch = sensor.pixel_pitch_m;
    let mut illuminant = None;
    let mut patch_labels = None;
    let mut world_illuminant: Option<(Spectrum, String)> = None;
    let mut implied: (Option<f64>, Option<f64>) = (None, None);
    let mut gltf = None;
    let target = match kind {
        "gltf" => {
            o.allow(crate::gltf_target::GLTF_KEYS)?;
            let t = crate::gltf_target::gltf_target(m, dir)?;
            let description = format!("the glTF scene {}", t.file.display());
            gltf = Some(std::sync::Arc::new(t));
            Target::Rendered { description }
        }
        "dark" => {
            o.allow(&[])?;
            Target::Dark
        }
        "uniform" => {
            o.allow(&["radiance"])?;
            Target::Uniform {
                radiance: o.radiance("radiance", None)?,
            }
        }
        "patches" => {
            o.allow(&[
                "rows",
                "cols",
                "patch_fraction",
                "background",
                "patches",
                "labels",
            ])?;
            let (rows, cols) = (o.count("rows")?, o.count("cols")?);
            let pf = o.num("patch_fraction", Some(1.0))?;
            if !(pf > 0.0 && pf <= 1.0) {
                return Err(format!(".patch_fraction: must be in (0, 1], got {pf}"));
            }
            let list = m
                .get("patches")
                .and_then(Value::as_array)
                .ok_or(".patches: required (a list of spectra)")?;
            if list.len() != rows * cols {
                return Err(format!(
                    ".patches: lists {} spectra but rows·cols = {}",
                    list.len(),
                    rows * cols
                ));
            }
            let patches = list
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    radiance_checked(
                        spectrum(p).map_err(|e| format!(".patches[{i}]: {e}"))?,
                        &format!("patches[{i}]"),
                        photons,
                    )
                })
                .collect::<Result<Vec<_>, _>>()?;
            if let Some(v) = m.get("labels") {
                let f = v
                    .as_str()
                    .ok_or(".labels: must be a path to a label image (PNG or TIFF)")?;
                let l = crate::raw_input::read_patch_labels(
                    &dir.join(f),
                    sensor.rows,
                    sensor.cols,
                    rows * cols,
                )
                .map_err(|e| format!(".labels: {}", e.one_line()))?;
                patch_labels = Some(std::sync::Arc::new(l));
            }
            Target::Patches {
                rows,
                cols,
                patch_fraction: pf,
                background: o.radiance("background", Some(0.0))?,
                patches,
            }
        }
        "slanted_edge" => {
            o.allow(&["dark", "light", "angle_deg"])?;
            Target::SlantedEdge {
                dark: o.radiance("dark", None)?,
                light: o.radiance("light", None)?,
                angle_deg: o.num("angle_deg", None)?,
            }
        }
        "image" if m.contains_key("display") => {
            o.allow(&["file", "display", "illuminant"])?;
            let w = crate::world_targets::rgb_image_target(m, dir, photons)?;
            implied = (w.implied_fov_deg, w.implied_distance_m);
            world_illuminant = w.illuminant;
            w.target
        }
        "cube" => {
            o.allow(&[
                "file",
                "illuminant",
                "quantity",
                "wavelength_nm",
                "wavelength_file",
                "data_file",
            ])?;
            let w = crate::world_targets::cube_target(m, dir, photons)?;
            world_illuminant = w.illuminant;
            w.target
        }
        "image" => {
            o.allow(&["file", "illuminant"])?;
            let f = m
                .get("file")
                .and_then(Value::as_str)
                .ok_or(".file: required (a spectral EXR path)")?;
            let p = dir.join(f);
            let limit = crate::budget::memory_limit().bytes as f64;
            // Over the memory budget: refused from the header, before the pixels are read.
            let exr = read_exr_target(&p, limit).map_err(|e| format!(".file: {}", e.one_line()))?;
            let mut img = exr.image;
            let photon_file = photons || exr.emissive_units.to_lowercase().contains("photon");
            let max = if photon_file {
                MAX_RADIANCE_W * 5.03e18
            } else {
                MAX_RADIANCE_W
            };
            let peak = img.planes.iter().flatten().fold(0.0f32, |a, &v| {
                if v.is_nan() {
                    f32::INFINITY
                } else {
                    a.max(v.abs())
                }
            });
            if !(peak as f64 <= max) {
                return Err(format!(
                    ".file: {}: a radiance of {peak:e} is over the limit of {max:e} (or not a \
                     number); no physical source is that bright (docs/limits.md)",
                    p.display()
                ));
            }
            if !photon_file {
                exr_io::bands_energy_to_photons(&mut img, &SI, false);
            }
            world_illuminant = crate::world_targets::file_illuminant(m, &img, photons)?;
            Target::Image { radiance: img }
        }
        "macbeth" => {
            o.allow(&["illuminant", "patch_fraction", "background"])?;
            let ill_energy = match m.get("illuminant") {
                None => data::illuminant("D65").map_err(|e| e.to_string())?,
                Some(Value::String(name)) => {
                    data::illuminant(name).map_err(|e| format!(".illuminant: {e}"))?
                }
                Some(v) => spectrum(v).map_err(|e| format!(".illuminant: {e}"))?,
            };
            if let Some((w, v)) = ill_energy.first_negative() {
                return Err(format!(".illuminant: negative value {v} at {w} nm"));
            }
            let ill = radiance_checked(ill_energy, "illuminant", photons)?;
            let refl = data::macbeth_reflectances_row_major().map_err(|e| e.to_string())?;
            let pf = o.num("patch_fraction", Some(1.0))?;
            if !(pf > 0.0 && pf <= 1.0) {
                return Err(format!(".patch_fraction: must be in (0, 1], got {pf}"));
            }
            let patches = refl.iter().map(|r| Spectrum::multiply(r, &ill)).collect();
            illuminant = Some(ill);
            Target::Patches {
                rows: 4,
                cols: 6,
                patch_fraction: pf,
                background: o.radiance("background", Some(0.0))?,
                patches,
            }
        }
        "ramp" => {
            o.allow(&["radiance", "min", "max"])?;
            Target::Ramp {
                radiance: o.radiance("radiance", None)?,
                min: o.num("min", Some(0.0))?.max(0.0),
                max: o.num("max", Some(1.0))?.max(0.0),
            }
        }
        "frequency_sweep" => {
            o.allow(&["radiance", "max_cycles_per_pixel", "contrast"])?;
            let c = o.num("contrast", Some(1.0))?;
            if !(0.0..=1.0).contains(&c) {
                return Err(format!(".contrast: must be in [0, 1], got {c}"));
            }
            Target::FrequencySweep {
                radiance: o.radiance("radiance", None)?,
                max_cycles_per_pixel: o.num("max_cycles_per_pixel", Some(0.5))?,
                pixel_pitch_m: pitch,
                contrast: c,
            }
        }
        "point_array" => {
            o.allow(&["radiance", "background", "spacing_px", "point_size_px"])?;
            Target::PointArray {
                radiance: o.radiance("radiance", None)?,
                background: o.radiance("background", Some(0.0))?,
                spacing_m: at_least(o.num("spacing_px", Some(16.0))?, 1.0, "spacing_px")? * pitch,
                point_size_m: at_least(o.num("point_size_px", Some(1.0))?, 1e-3, "point_size_px")?
                    * pitch,
            }
        }
        "grid_lines" => {
            o.allow(&["radiance", "background", "spacing_px", "line_width_px"])?;
            Target::GridLines {
                radiance: o.radiance("radiance", None)?,
                background: o.radiance("background", Some(0.0))?,
                spacing_m: at_least(o.num("spacing_px", Some(16.0))?, 1.0, "spacing_px")? * pitch,
                line_width_m: at_least(o.num("line_width_px", Some(1.0))?, 1e-3, "line_width_px")?
                    * pitch,
            }
        }
        other => {
            return Err(format!(
                ".kind: unknown target kind \"{other}\" (expected one of {KINDS})"
            ))
        }
    };
    if mean_luminance_cd_m2.is_some_and(|l| l > 0.0) && is_black(&target) {
        return Err(format!(
            ".mean_luminance_cd_m2: a {kind} target without light cannot be scaled to a \
             luminance (give it a radiance, or drop mean_luminance_cd_m2)"
        ));
    }
    let mut world = crate::world_targets::SceneWorld {
        fov_deg: crate::world_targets::fov_value(m.get("fov_deg"), implied.0)?,
        distance_m: crate::world_targets::distance_value(m.get("distance_m"), implied.1)?,
        swapped_from: None,
        illuminant_source: None,
    };
    if let Some((ill, src)) = world_illuminant {
        illuminant = Some(ill);
        world.illuminant_source = Some(src);
    } else if illuminant.is_some() {
        world.illuminant_source = Some("given".into());
    }
    if let Some(v) = m.get("swap_illuminant") {
        let new = crate::world_targets::swap_illuminant_value(v, photons)?;
        let Some(old) = illuminant.replace(new) else {
            return Err(format!(
                ".swap_illuminant: a {kind} target has no illuminant to swap (only macbeth, \
                 image and cube targets carry one)"
            ));
        };
        world.swapped_from = Some(old);
        world.illuminant_source = Some(format!(
            "swapped in for the scene's own ({})",
            world.illuminant_source.as_deref().unwrap_or("given")
        ));
    }
    Ok(ParsedTarget {
        target,
        mean_luminance_cd_m2,
        illuminant,
        patch_labels,
        world,
        gltf,
    })
}

/// A size in pixels that must be at least `min` (and finite): one error naming the key.
fn at_least(v: f64, min: f64, key: &str) -> Result<f64, String> {
    if v.is_finite() && v >= min {
        Ok(v)
    } else {
        Err(format!(".{key}: must be at least {min} pixel(s), got {v}"))
    }
}

/// A target that emits no light at all (dark, or a uniform radiance of zero everywhere).
fn is_black(t: &Target) -> bool {
    match t {
        Target::Dark => true,
        Target::Uniform { radiance } => match radiance {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } => *offset == 0.0 && *slope_per_nm == 0.0,
            Spectrum::Sampled { values, .. } => values.iter().all(|&v| v == 0.0),
        },
        _ => false,
    }
}

/// Read a spectral EXR target: refused from its header when its pixels need more than
/// `max_decoded_bytes`, and a panic inside the `exr` crate on a malformed file is one error.
pub fn read_exr_target(
    path: &Path,
    max_decoded_bytes: f64,
) -> Result<exr_io::SpectralExr, crate::error::CliError> {
    crate::staging::protect_input(path);
    crate::guard::guarded(path, || {
        exr_io::read_spectral_exr_within(path, max_decoded_bytes)
            .map_err(|e| crate::error::CliError::Other(e.to_string()))
    })
}

/// Fraction of a patch side dropped on every side before sampling a chart patch.
pub const PATCH_MARGIN_FRACTION: f64 = 0.2;

/// The chart layout of a 4 × 6 chart target (macbeth or patches), as `camsim run` samples it.
pub fn chart_layout(t: &Target) -> Option<camsim_metrics::ChartLayout> {
    match t {
        Target::Patches {
            rows: 4,
            cols: 6,
            patch_fraction,
            ..
        } => Some(camsim_metrics::ChartLayout {
            chart_rows: 4,
            chart_cols: 6,
            patch_fraction: *patch_fraction,
            margin_fraction: PATCH_MARGIN_FRACTION,
        }),
        _ => None,
    }
}
