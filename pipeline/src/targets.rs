//! Shot targets as written in captures.json (spec kinds `dark`, `uniform`, `patches`,
//! `slanted_edge`, `image`, plus camsim's `macbeth`, `ramp`, `frequency_sweep`,
//! `point_array`, `grid_lines`; docs/config.md) → [`Target`] with photon-unit spectra.
use crate::spectrum_file::to_photons;
use camsim_core::constants::SI;
use camsim_core::data;
use camsim_core::exr_io::{self, read_spectral_exr};
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
}

const KINDS: &str = "dark, uniform, patches, slanted_edge, image, macbeth, ramp, frequency_sweep, point_array, grid_lines";

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

fn radiance_checked(s: Spectrum, k: &str, photons: bool) -> Result<Spectrum, String> {
    if let Some((w, v)) = s.first_negative() {
        return Err(format!(".{k}: negative radiance {v} at {w} nm"));
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
            if l < 0.0 {
                return Err(format!(".mean_luminance_cd_m2: must be ≥ 0, got {l}"));
            }
            Some(l)
        }
    };
    let pitch = sensor.pixel_pitch_m;
    let mut illuminant = None;
    let mut patch_labels = None;
    let target = match kind {
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
        "image" => {
            o.allow(&["file"])?;
            let f = m
                .get("file")
                .and_then(Value::as_str)
                .ok_or(".file: required (a spectral EXR path)")?;
            let p = dir.join(f);
            let exr = read_spectral_exr(&p).map_err(|e| format!(".file: {e}"))?;
            let mut img = exr.image;
            let photon_file = photons || exr.emissive_units.to_lowercase().contains("photon");
            if !photon_file {
                exr_io::bands_energy_to_photons(&mut img, &SI, false);
            }
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
                spacing_m: o.num("spacing_px", Some(16.0))?.max(1.0) * pitch,
                point_size_m: o.num("point_size_px", Some(1.0))?.max(1e-3) * pitch,
            }
        }
        "grid_lines" => {
            o.allow(&["radiance", "background", "spacing_px", "line_width_px"])?;
            Target::GridLines {
                radiance: o.radiance("radiance", None)?,
                background: o.radiance("background", Some(0.0))?,
                spacing_m: o.num("spacing_px", Some(16.0))?.max(1.0) * pitch,
                line_width_m: o.num("line_width_px", Some(1.0))?.max(1e-3) * pitch,
            }
        }
        other => {
            return Err(format!(
                ".kind: unknown target kind \"{other}\" (expected one of {KINDS})"
            ))
        }
    };
    Ok(ParsedTarget {
        target,
        mean_luminance_cd_m2,
        illuminant,
        patch_labels,
    })
}
