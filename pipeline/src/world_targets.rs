//! Targets from the world (docs/config.md, "Scenes from the world"): an RGB picture on a
//! display (`image` + `display`), hyperspectral cubes (`cube`: ENVI, `.npy`, spectral EXR),
//! the illuminant stored with them (given, the display's white, or estimated), and the keys
//! every target accepts: `fov_deg`, `distance_m`, `swap_illuminant`.
use crate::scene_files::{self, SpectralCube};
use camsim_core::constants::SI;
use camsim_core::illuminant::{estimate_illuminant, EstimateMethod, IlluminantFamily};
use camsim_core::image::{SpectralBasis, SpectralImage};
use camsim_core::scene::Target;
use camsim_core::scene_import::{scene_from_rgb, DisplayPrimaries};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_display::DisplayModel;
use serde_json::{Map, Value};
use std::path::Path;

/// Keys every target accepts (besides `kind`, `radiance_unit`, `mean_luminance_cd_m2`).
pub const COMMON_KEYS: &[&str] = &["fov_deg", "distance_m", "swap_illuminant"];

/// Field of view, distance and illuminant swap of a target, and where its illuminant came
/// from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneWorld {
    /// Horizontal field of view (degrees); None = the target fills the sensor (spec).
    pub fov_deg: Option<f64>,
    /// Object distance (m); None = far away (magnification 0, spec baseline).
    pub distance_m: Option<f64>,
    /// The scene's own illuminant (photons) when `swap_illuminant` replaced it: the target is
    /// rendered under this one, then swapped to [`crate::targets::ParsedTarget::illuminant`]
    /// keeping reflectance and the mean luminance ([`camsim_core::illuminant::swap_illuminant`]).
    pub swapped_from: Option<Spectrum>,
    /// Where the scene's illuminant came from (for reports), e.g. "display white point" or
    /// "estimated (grey world): blackbody 3125 K".
    pub illuminant_source: Option<String>,
}

/// How a target states its illuminant.
enum IlluminantSpec {
    /// A spectrum (photon units).
    Given(Spectrum, String),
    /// Estimate it from the scene.
    Estimate(EstimateMethod),
    /// The display's white point (RGB pictures).
    DisplayWhite,
}

fn to_photons_checked(s: Spectrum, key: &str, photons: bool) -> Result<Spectrum, String> {
    if let Some((w, v)) = s.first_negative() {
        return Err(format!(".{key}: negative value {v} at {w} nm"));
    }
    Ok(if photons {
        s
    } else {
        crate::spectrum_file::to_photons(&s)
    })
}

/// An illuminant value: a name (D65, A, tungsten, …), a spectrum (W unless the target says
/// photons), or one of "display", "grey_world", "brightest".
fn illuminant_spec(v: &Value, key: &str, photons: bool) -> Result<IlluminantSpec, String> {
    match v {
        Value::String(s) if s == "display" => Ok(IlluminantSpec::DisplayWhite),
        Value::String(s) if s == "grey_world" || s == "estimate" => {
            Ok(IlluminantSpec::Estimate(EstimateMethod::GreyWorld))
        }
        Value::String(s) if s == "brightest" => {
            Ok(IlluminantSpec::Estimate(EstimateMethod::Brightest))
        }
        Value::String(name) => {
            let s = camsim_core::data::illuminant(name).map_err(|e| format!(".{key}: {e}"))?;
            Ok(IlluminantSpec::Given(
                to_photons_checked(s, key, false)?,
                format!("given: {name}"),
            ))
        }
        v => {
            let s = serde_json::from_value::<crate::spectrum_file::SpectrumValue>(v.clone())
                .map(|s| s.0)
                .map_err(|e| {
                    format!(
                        ".{key}: {e} (expected an illuminant name, a spectrum, \"grey_world\", \
                         \"brightest\" or \"display\")"
                    )
                })?;
            Ok(IlluminantSpec::Given(
                to_photons_checked(s, key, photons)?,
                "given: spectrum".into(),
            ))
        }
    }
}

/// The illuminant to swap in (`swap_illuminant`): a name or a spectrum, photons.
pub fn swap_illuminant_value(v: &Value, photons: bool) -> Result<Spectrum, String> {
    match illuminant_spec(v, "swap_illuminant", photons)? {
        IlluminantSpec::Given(s, _) => Ok(s),
        _ => Err(".swap_illuminant: expected an illuminant name or a spectrum".into()),
    }
}

/// The wavelengths an estimate is fitted on: the image's bands, or 400–700 nm by 5 nm.
fn estimate_grid(img: &SpectralImage) -> WavelengthGrid {
    match &img.basis {
        SpectralBasis::Bands(g) => g.clone(),
        SpectralBasis::Spectra(_) => WavelengthGrid::regular(400.0, 700.0, 5.0).expect("grid"),
    }
}

/// Resolve an illuminant spec for `img` (photon units).
fn resolve_illuminant(
    spec: IlluminantSpec,
    img: &SpectralImage,
    display_white: Option<&Spectrum>,
) -> Result<(Spectrum, String), String> {
    match spec {
        IlluminantSpec::Given(s, note) => Ok((s, note)),
        IlluminantSpec::DisplayWhite => display_white
            .cloned()
            .map(|s| (s, "display white point".to_string()))
            .ok_or_else(|| {
                ".illuminant: \"display\" is only for an image shown on a display".to_string()
            }),
        IlluminantSpec::Estimate(method) => {
            let e = estimate_illuminant(img, &estimate_grid(img), method, &SI)
                .map_err(|e| format!(".illuminant: {e}"))?;
            let fam = match e.family {
                IlluminantFamily::Blackbody => "blackbody",
                IlluminantFamily::Daylight => "CIE daylight",
            };
            let how = match method {
                EstimateMethod::GreyWorld => "grey world",
                EstimateMethod::Brightest => "brightest pixels",
            };
            Ok((
                e.spectrum_photons,
                format!("estimated ({how}): {fam} {:.0} K", e.cct_k),
            ))
        }
    }
}

/// What a world target parsed to.
pub struct WorldTarget {
    /// The target.
    pub target: Target,
    /// Its illuminant (photons) and where it came from.
    pub illuminant: Option<(Spectrum, String)>,
    /// Field of view and distance the file or display implies (used when the target does
    /// not state its own).
    pub implied_fov_deg: Option<f64>,
    /// Distance implied (the display's viewing distance).
    pub implied_distance_m: Option<f64>,
}

fn string_key<'a>(m: &'a Map<String, Value>, k: &str, what: &str) -> Result<&'a str, String> {
    m.get(k)
        .and_then(Value::as_str)
        .ok_or_else(|| format!(".{k}: required ({what})"))
}

/// `{"kind": "image", "file": PICTURE, "display": NAME_OR_JSON, "illuminant": …}`: an 8/16-bit
/// PNG/TIFF through a display model (ISETCam `sceneFromFile`, see
/// [`camsim_core::scene_import`]).
pub fn rgb_image_target(
    m: &Map<String, Value>,
    dir: &Path,
    photons: bool,
) -> Result<WorldTarget, String> {
    let file = string_key(m, "file", "a PNG or TIFF picture")?;
    let dname = string_key(m, "display", "an ISET display name or a display JSON file")?;
    let display = if dname.ends_with(".json") {
        let p = dir.join(dname);
        crate::staging::protect_input(&p);
        let t = std::fs::read_to_string(&p)
            .map_err(|e| format!(".display: {}: cannot read: {e}", p.display()))?;
        let v: Value = serde_json::from_str(&t)
            .map_err(|e| format!(".display: {}: invalid JSON: {e}", p.display()))?;
        DisplayModel::from_json(&v).map_err(|e| format!(".display: {}: {e}", p.display()))?
    } else {
        DisplayModel::load(dname).map_err(|e| format!(".display: {e}"))?
    };
    let prim = DisplayPrimaries {
        spd_energy: display.primary_spd.clone(),
        gamma: (0..display.n_primaries())
            .map(|p| display.gamma.table(p).map(<[f64]>::to_vec))
            .collect::<Result<_, _>>()
            .map_err(|e| format!(".display: {e}"))?,
        pixel_pitch_m: display.pixel_pitch_m(),
        viewing_distance_m: display.viewing_distance_m,
    };
    let p = dir.join(file);
    let codes = scene_files::read_rgb_picture(&p).map_err(|e| format!(".file: {e}"))?;
    let rgb =
        scene_from_rgb(&codes, &prim, &SI).map_err(|e| format!(".file: {}: {e}", p.display()))?;
    let spec = match m.get("illuminant") {
        None => IlluminantSpec::DisplayWhite,
        Some(v) => illuminant_spec(v, "illuminant", photons)?,
    };
    let illuminant = resolve_illuminant(spec, &rgb.radiance, Some(&rgb.illuminant_photons))?;
    Ok(WorldTarget {
        target: Target::Image {
            radiance: rgb.radiance,
        },
        illuminant: Some(illuminant),
        implied_fov_deg: Some(rgb.fov_deg),
        implied_distance_m: Some(rgb.distance_m),
    })
}

/// The illuminant of a spectral image from a file (`image` EXR, `cube`): the stated one, or
/// an estimate (grey world) when none is stated — none for a black image (nothing to estimate
/// from; an estimate asked for explicitly is then an error).
pub fn file_illuminant(
    m: &Map<String, Value>,
    img: &SpectralImage,
    photons: bool,
) -> Result<Option<(Spectrum, String)>, String> {
    match m.get("illuminant") {
        None => Ok(resolve_illuminant(
            IlluminantSpec::Estimate(EstimateMethod::GreyWorld),
            img,
            None,
        )
        .ok()),
        Some(v) => {
            resolve_illuminant(illuminant_spec(v, "illuminant", photons)?, img, None).map(Some)
        }
    }
}

/// `{"kind": "cube", "file": F, …}`: an ENVI header (`.hdr`), a `.npy` array or a spectral
/// EXR; `quantity` `"radiance"` (default; W unless `radiance_unit` = photons) or
/// `"reflectance"` (times the stated `illuminant`).
pub fn cube_target(
    m: &Map<String, Value>,
    dir: &Path,
    photons: bool,
) -> Result<WorldTarget, String> {
    let file = string_key(m, "file", "an ENVI .hdr, a .npy or a spectral .exr")?;
    let p = dir.join(file);
    let ext = p
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let reflectance = match m.get("quantity").map(|v| v.as_str()) {
        None | Some(Some("radiance")) => false,
        Some(Some("reflectance")) => true,
        Some(v) => {
            return Err(format!(
                ".quantity: expected \"radiance\" or \"reflectance\", got {v:?}"
            ))
        }
    };
    let mut photon_file = photons;
    let cube: SpectralCube = match ext.as_str() {
        "hdr" => {
            let df = m
                .get("data_file")
                .map(|v| v.as_str().ok_or(".data_file: must be a path"))
                .transpose()?
                .map(|s| dir.join(s));
            scene_files::read_envi(&p, df.as_deref()).map_err(|e| format!(".file: {e}"))?
        }
        "npy" => {
            let wl = match (m.get("wavelength_nm"), m.get("wavelength_file")) {
                (Some(v), None) => serde_json::from_value::<Vec<f64>>(v.clone())
                    .map_err(|_| ".wavelength_nm: must be a list of numbers (nm)".to_string())?,
                (None, Some(Value::String(f))) => scene_files::read_wavelength_file(&dir.join(f))
                    .map_err(|e| format!(".wavelength_file: {e}"))?,
                (None, Some(_)) => return Err(".wavelength_file: must be a path".into()),
                (Some(_), Some(_)) => {
                    return Err("give wavelength_nm or wavelength_file, not both".into())
                }
                (None, None) => {
                    return Err(
                        ".wavelength_nm: required for a .npy cube (or wavelength_file), one \
                         wavelength (nm) per band"
                            .into(),
                    )
                }
            };
            scene_files::read_npy_cube(&p, &wl).map_err(|e| format!(".file: {e}"))?
        }
        "exr" => {
            let limit = crate::budget::memory_limit().bytes as f64;
            let exr = crate::targets::read_exr_target(&p, limit)
                .map_err(|e| format!(".file: {}", e.one_line()))?;
            photon_file = photons || exr.emissive_units.to_lowercase().contains("photon");
            SpectralCube {
                rows: exr.image.rows,
                cols: exr.image.cols,
                wavelength_nm: exr.grid.wavelength_nm.clone(),
                planes: exr.image.planes,
            }
        }
        other => {
            return Err(format!(
                ".file: {}: unknown cube format \".{other}\" (expected .hdr (ENVI), .npy or .exr)",
                p.display()
            ))
        }
    };
    let grid =
        WavelengthGrid::new(cube.wavelength_nm.clone()).map_err(|e| format!(".file: {e}"))?;
    let mut img = SpectralImage::new(
        cube.rows,
        cube.cols,
        SpectralBasis::Bands(grid),
        cube.planes,
    )
    .map_err(|e| format!(".file: {e}"))?;
    let illuminant = if reflectance {
        let spec = match m.get("illuminant") {
            Some(v) => illuminant_spec(v, "illuminant", photons)?,
            None => {
                return Err(
                    ".illuminant: required for a reflectance cube (a name or a spectrum)".into(),
                )
            }
        };
        let IlluminantSpec::Given(ill, note) = spec else {
            return Err(
                ".illuminant: a reflectance cube needs a stated illuminant (a name or a \
                        spectrum), not an estimate"
                    .into(),
            );
        };
        // radiance = reflectance × illuminant, per band
        img.scale_spectrally(&ill);
        Some((ill, note))
    } else {
        if !photon_file {
            camsim_core::exr_io::bands_energy_to_photons(&mut img, &SI, false);
        }
        file_illuminant(m, &img, photons)?
    };
    Ok(WorldTarget {
        target: Target::Image { radiance: img },
        illuminant,
        implied_fov_deg: None,
        implied_distance_m: None,
    })
}

/// `fov_deg`: a number of degrees in (0, 180), or `"display"` (the display's, for a picture on
/// a display).
pub fn fov_value(v: Option<&Value>, implied: Option<f64>) -> Result<Option<f64>, String> {
    match v {
        None => Ok(None),
        Some(Value::String(s)) if s == "display" => implied.map(Some).ok_or_else(|| {
            ".fov_deg: \"display\" is only for an image shown on a display".to_string()
        }),
        Some(v) => match v.as_f64() {
            Some(f) if f > 0.0 && f < 180.0 => Ok(Some(f)),
            _ => Err(format!(
                ".fov_deg: expected degrees in (0, 180) (or \"display\"), got {v}"
            )),
        },
    }
}

/// `distance_m`: a positive number of metres, or `"display"` (the viewing distance).
pub fn distance_value(v: Option<&Value>, implied: Option<f64>) -> Result<Option<f64>, String> {
    match v {
        None => Ok(None),
        Some(Value::String(s)) if s == "display" => implied.map(Some).ok_or_else(|| {
            ".distance_m: \"display\" is only for an image shown on a display".to_string()
        }),
        Some(v) => match v.as_f64() {
            Some(d) if d > 0.0 && d.is_finite() => Ok(Some(d)),
            _ => Err(format!(
                ".distance_m: expected metres > 0 (or \"display\"), got {v}"
            )),
        },
    }
}
