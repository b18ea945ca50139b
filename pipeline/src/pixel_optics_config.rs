//! `sensor.pixel_optics` (issue 21): the pixel's microlens and optical stack, the chief-ray
//! angle across the sensor and the microlens shift, giving pixel vignetting (CRA shading) and
//! angle-dependent optical crosstalk ([`camsim_sensor::pixel_optics`]; docs/pixel_optics.md).
//! Absent: no pixel optics, every output bit-identical to a camera without the key.
//!
//! | key | default | unit | meaning |
//! |---|---|---|---|
//! | `photodiode_width_um` | required | µm | side `w` of the square photodiode aperture, `0 < w ≤ pitch` |
//! | `microlens_focal_length_um` | — | µm | focal length `f` of the microlens inside the stack; give this or `microlens_f_number` |
//! | `microlens_f_number` | — | — | `f / D` (alternative to `microlens_focal_length_um`) |
//! | `microlens_diameter_um` | pixel pitch | µm | side `D` of the microlens's square aperture, `0 < D ≤ pitch` |
//! | `stack_height_um` | `f` | µm | microlens → photodiode plane (`= f`: the photodiode in the microlens's focal plane) |
//! | `refractive_index` | 1.5 | — | index `n` of the stack (paraxial Snell `t → t/n`) |
//! | `chief_ray` | thin lens | — | one of the forms below |
//! | `microlens_shift` | none | — | `{"cra_fraction": κ}` (shift `κ h tan θ_c / n` towards the axis; 1 = full CRA compensation) or `{"um_per_mm": k}` (`k` µm per mm of field height) |
//!
//! `chief_ray`:
//! * absent: the camera's thin lens — exit pupil at the lens, `focal_length_mm` in front of
//!   the sensor, radius `focal_length / (2 · f_number)`;
//! * `{"exit_pupil_distance_mm": z, "exit_pupil_diameter_mm": d}`: a circular exit pupil `z` in
//!   front of the sensor (negative: behind it);
//! * `{"lens": "file.json"}` (+ optional `"wavelength_nm"`, default 550): the paraxial exit
//!   pupil of a lens prescription ([`camsim_lens::LensPrescription::first_order`], at its
//!   prescribed conjugates), relative to the camera file;
//! * `{"cra_table": [[field_mm, cra_deg], …]}`: chief-ray angle against field height (linear
//!   between entries, held beyond), the cone from `optics.f_number` (`1/(2N)`).
//!
//! Units: `photodiode_width_um` and the like are µm; with the block, the electron rate is
//! `p² · FF · η · ∫ QE E dλ` — set `fill_factor` to 1 when `photodiode_width_um` describes the
//! photodiode aperture, or both apply.
use crate::error::CliError;
use camsim_sensor::pixel_optics::{ChiefRay, Microlens, MicrolensShift, PixelOptics, ResponseMap};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::{Arc, OnceLock};

/// Default `refractive_index` of the stack (silicon dioxide / polymer, ~1.46–1.6).
pub const DEFAULT_STACK_INDEX: f64 = 1.5;
/// Default wavelength (nm) of a lens's paraxial exit pupil.
pub const DEFAULT_PUPIL_WAVELENGTH_NM: f64 = 550.0;

/// `sensor.pixel_optics` as written (table in the module docs).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PixelOpticsFile {
    /// Photodiode aperture side (µm).
    pub photodiode_width_um: f64,
    /// Microlens focal length in the stack (µm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub microlens_focal_length_um: Option<f64>,
    /// Microlens f-number `f / D`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub microlens_f_number: Option<f64>,
    /// Microlens aperture side (µm; default the pitch).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub microlens_diameter_um: Option<f64>,
    /// Stack height (µm; default the focal length).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stack_height_um: Option<f64>,
    /// Stack index (default [`DEFAULT_STACK_INDEX`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refractive_index: Option<f64>,
    /// Chief-ray model (default: the camera's thin lens).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chief_ray: Option<ChiefRayFile>,
    /// Microlens shift law (default none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub microlens_shift: Option<MicrolensShiftFile>,
}

/// `sensor.pixel_optics.chief_ray` as written: exactly one of the forms.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChiefRayFile {
    /// Exit pupil distance in front of the sensor (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exit_pupil_distance_mm: Option<f64>,
    /// Exit pupil diameter (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exit_pupil_diameter_mm: Option<f64>,
    /// A lens prescription (path relative to the camera file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens: Option<String>,
    /// Wavelength of the lens's paraxial exit pupil (nm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wavelength_nm: Option<f64>,
    /// `[[field_mm, cra_deg], …]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cra_table: Option<Vec<[f64; 2]>>,
}

/// `sensor.pixel_optics.microlens_shift` as written: exactly one key.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MicrolensShiftFile {
    /// Fraction of the CRA-compensating shift.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cra_fraction: Option<f64>,
    /// Linear shift law (µm per mm of field height).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub um_per_mm: Option<f64>,
}

/// A camera's validated pixel optics, with its response map over the sensor computed once on
/// first use.
#[derive(Debug, Clone)]
pub struct CameraPixelOptics {
    /// The model.
    pub model: PixelOptics,
    /// Where the chief ray came from, for reports (e.g. `lens double_gauss_50mm_f2.json: exit
    /// pupil 61.2 mm, Ø 29.0 mm`).
    pub chief_ray_source: String,
    map: OnceLock<Arc<ResponseMap>>,
}

impl CameraPixelOptics {
    /// The model's response map for a `rows × cols` sensor (cached for the camera's size).
    pub fn response_map(&self, rows: usize, cols: usize) -> Arc<ResponseMap> {
        let m = self
            .map
            .get_or_init(|| Arc::new(self.model.response_map(rows, cols)));
        if m.rows == rows && m.cols == cols {
            m.clone()
        } else {
            Arc::new(self.model.response_map(rows, cols))
        }
    }
}

/// `sensor.pixel_optics` → [`CameraPixelOptics`]: defaults filled, every key checked; errors
/// name `sensor.pixel_optics.KEY`, the value and what was expected. `pitch_um`, `f_number` and
/// `focal_length_mm` are the camera's; `dir` resolves a lens path.
pub fn pixel_optics_from_file(
    path: &Path,
    dir: &Path,
    file: &PixelOpticsFile,
    pitch_um: f64,
    f_number: f64,
    focal_length_mm: f64,
) -> Result<CameraPixelOptics, CliError> {
    let key = |k: &str| format!("sensor.pixel_optics.{k}");
    let err = |k: &str, msg: String| CliError::input(path, format!("{}: {msg}", key(k)));
    let diameter_um = file.microlens_diameter_um.unwrap_or(pitch_um);
    let focal_length_um = match (file.microlens_focal_length_um, file.microlens_f_number) {
        (Some(f), None) => f,
        (None, Some(n)) => {
            if !(n.is_finite() && n > 0.0) {
                return Err(err(
                    "microlens_f_number",
                    format!("must be a positive number, got {n}"),
                ));
            }
            n * diameter_um
        }
        _ => {
            return Err(err(
                "microlens_focal_length_um",
                "give exactly one of microlens_focal_length_um and microlens_f_number".into(),
            ))
        }
    };
    let microlens = Microlens {
        pitch_um,
        diameter_um,
        focal_length_um,
        stack_height_um: file.stack_height_um.unwrap_or(focal_length_um),
        photodiode_width_um: file.photodiode_width_um,
        refractive_index: file.refractive_index.unwrap_or(DEFAULT_STACK_INDEX),
    };
    let (chief_ray, chief_ray_source) = chief_ray_from_file(
        path,
        dir,
        file.chief_ray.as_ref(),
        f_number,
        focal_length_mm,
    )?;
    let shift = match &file.microlens_shift {
        None => MicrolensShift::None,
        Some(MicrolensShiftFile {
            cra_fraction: Some(f),
            um_per_mm: None,
        }) => MicrolensShift::Cra { fraction: *f },
        Some(MicrolensShiftFile {
            cra_fraction: None,
            um_per_mm: Some(k),
        }) => MicrolensShift::Linear { um_per_mm: *k },
        Some(_) => {
            return Err(err(
                "microlens_shift",
                "expected {\"cra_fraction\": κ} or {\"um_per_mm\": k} (one key)".into(),
            ))
        }
    };
    let model = PixelOptics::new(microlens, chief_ray, shift).map_err(|e| {
        let field = match e.field.as_str() {
            "pixel_pitch_um" => "sensor.pixel_pitch_um".to_string(),
            "microlens_focal_length_um" if file.microlens_f_number.is_some() => {
                key("microlens_f_number")
            }
            "exit_pupil_radius_mm" => key("chief_ray.exit_pupil_diameter_mm"),
            f if f.starts_with("cra_table") || f.starts_with("exit_pupil") => {
                key(&format!("chief_ray.{f}"))
            }
            "f_number" => "optics.f_number".to_string(),
            "microlens_shift.cra_fraction" | "microlens_shift.um_per_mm" => key(&e.field),
            f => key(f),
        };
        CliError::input(path, format!("{field} = {}: {}", e.value, e.reason))
    })?;
    Ok(CameraPixelOptics {
        model,
        chief_ray_source,
        map: OnceLock::new(),
    })
}

fn chief_ray_from_file(
    path: &Path,
    dir: &Path,
    c: Option<&ChiefRayFile>,
    f_number: f64,
    focal_length_mm: f64,
) -> Result<(ChiefRay, String), CliError> {
    let err = |k: &str, msg: String| {
        CliError::input(path, format!("sensor.pixel_optics.chief_ray.{k}: {msg}"))
    };
    let Some(c) = c else {
        return Ok((
            ChiefRay::ExitPupil {
                distance_mm: focal_length_mm,
                radius_mm: focal_length_mm / (2.0 * f_number),
            },
            format!(
                "thin lens: exit pupil {focal_length_mm} mm in front of the sensor, f/{f_number}"
            ),
        ));
    };
    let forms = [
        c.exit_pupil_distance_mm.is_some() || c.exit_pupil_diameter_mm.is_some(),
        c.lens.is_some(),
        c.cra_table.is_some(),
    ];
    if forms.iter().filter(|f| **f).count() != 1 {
        return Err(err(
            "",
            "expected exactly one of {exit_pupil_distance_mm, exit_pupil_diameter_mm}, {lens}, {cra_table}".into(),
        ));
    }
    if c.wavelength_nm.is_some() && c.lens.is_none() {
        return Err(err("wavelength_nm", "only with \"lens\"".into()));
    }
    if let Some(t) = &c.cra_table {
        return Ok((
            ChiefRay::Table {
                field_mm: t.iter().map(|e| e[0]).collect(),
                cra_deg: t.iter().map(|e| e[1]).collect(),
                f_number,
            },
            format!("CRA table ({} entries), f/{f_number}", t.len()),
        ));
    }
    if let Some(l) = &c.lens {
        let p = dir.join(l);
        if !p.is_file() {
            return Err(err("lens", format!("cannot read {}", p.display())));
        }
        let lens = camsim_lens::LensPrescription::from_json_file(
            &p,
            &camsim_lens::GlassCatalog::bundled(),
        )
        .map_err(|e| CliError::input(&p, e))?;
        let wl = c.wavelength_nm.unwrap_or(DEFAULT_PUPIL_WAVELENGTH_NM);
        if !(wl.is_finite() && (200.0..=2500.0).contains(&wl)) {
            return Err(err(
                "wavelength_nm",
                format!("must be in [200, 2500] nm, got {wl}"),
            ));
        }
        let fo = lens.first_order(wl).map_err(|e| CliError::input(&p, e))?;
        // exit_pupil_from_image_mm = z_xp − z_image (negative: the pupil before the image).
        let distance_mm = -fo.exit_pupil_from_image_mm;
        let radius_mm = 0.5 * fo.exit_pupil_diameter_mm;
        // An image-space telecentric lens (exit pupil at infinity, more than a kilometre
        // here): every chief ray is parallel to the axis, so the chief-ray angle is 0 across
        // the sensor and the cone is the lens's f-number.
        if !(distance_mm.is_finite() && distance_mm.abs() < 1e6) {
            if !(fo.f_number.is_finite() && fo.f_number > 0.0) {
                return Err(err(
                    "lens",
                    format!("{l}: telecentric with no finite f-number ({})", fo.f_number),
                ));
            }
            return Ok((
                ChiefRay::Table {
                    field_mm: vec![0.0],
                    cra_deg: vec![0.0],
                    f_number: fo.f_number,
                },
                format!(
                    "lens {l}: image-space telecentric (exit pupil at infinity), chief-ray angle 0, f/{:.3} at {wl} nm",
                    fo.f_number
                ),
            ));
        }
        return Ok((
            ChiefRay::ExitPupil {
                distance_mm,
                radius_mm,
            },
            format!(
                "lens {l}: paraxial exit pupil {distance_mm:.3} mm in front of the image, Ø {:.3} mm at {wl} nm",
                2.0 * radius_mm
            ),
        ));
    }
    let z = c.exit_pupil_distance_mm.ok_or_else(|| {
        err(
            "exit_pupil_distance_mm",
            "required with exit_pupil_diameter_mm".into(),
        )
    })?;
    let d = c.exit_pupil_diameter_mm.ok_or_else(|| {
        err(
            "exit_pupil_diameter_mm",
            "required with exit_pupil_distance_mm".into(),
        )
    })?;
    if !(d.is_finite() && d > 0.0) {
        return Err(err(
            "exit_pupil_diameter_mm",
            format!("must be a positive number, got {d}"),
        ));
    }
    Ok((
        ChiefRay::ExitPupil {
            distance_mm: z,
            radius_mm: 0.5 * d,
        },
        format!("exit pupil {z} mm in front of the sensor, Ø {d} mm"),
    ))
}
