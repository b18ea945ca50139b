//! Lens prescriptions: the JSON file form (as written) and the validated [`LensPrescription`].
//!
//! See the crate docs for the file format. Geometry conventions (as in Smith, "Modern Optical
//! Engineering", ch. 2–3): surfaces are listed from the object side; light travels towards +z;
//! a radius is positive when its centre of curvature lies to the right (+z) of the vertex;
//! `thickness_mm` of surface *j* is the axial distance from its vertex to the next vertex, and
//! the thickness of the **last** surface is the distance to the image plane. Object space is air.
use crate::error::LensError;
pub use crate::fold::CoordinateBreak;
use crate::glass::{Glass, GlassCatalog};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Material after a surface, as written in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MaterialFile {
    /// `"air"` (or any other name, looked up in every catalogue).
    Name(String),
    /// `{"glass": "N-BK7", "catalog": "schott"}` (catalogue optional).
    Catalog {
        /// Glass name.
        glass: String,
        /// Vendor ("schott", "ohara", "hoya", "cdgm", "sumita", "hikari", "misc") or .agf
        /// catalogue name; all searched if absent.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        catalog: Option<String>,
    },
    /// `{"nd": 1.62, "vd": 53.3}`: the (n_d, V_d) model glass (no `vd` or 0 = no dispersion).
    Model {
        /// Index at the d line.
        nd: f64,
        /// Abbe number.
        #[serde(default)]
        vd: f64,
    },
}

impl Default for MaterialFile {
    fn default() -> Self {
        MaterialFile::Name("air".into())
    }
}

/// One surface as written in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceFile {
    /// Vertex radius of curvature (mm); `null` = flat.
    pub radius_mm: Option<f64>,
    /// Axial distance to the next vertex (the image plane for the last surface), mm.
    pub thickness_mm: f64,
    /// Medium after the surface.
    #[serde(default)]
    pub material: MaterialFile,
    /// Clear semi-aperture (mm); used for vignetting and drawing. Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub semi_diameter_mm: Option<f64>,
    /// Conic constant k (0 = sphere, −1 = paraboloid).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub conic: f64,
    /// Even-asphere coefficients A4, A6, A8, … (sag terms A4·r⁴ + A6·r⁶ + …, r in mm).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub aspheric_coeffs: Vec<f64>,
    /// Odd-asphere (Zemax `ODDASPHE`) coefficients β1, β2, β3, … (sag terms β1·r + β2·r² +
    /// β3·r³ + …, r in mm), added to the conic and the even terms.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub odd_aspheric_coeffs: Vec<f64>,
    /// This surface is the aperture stop.
    #[serde(default, skip_serializing_if = "is_false")]
    pub stop: bool,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}
fn is_false(b: &bool) -> bool {
    !*b
}

/// The aperture specification as written: `{"epd_mm": 25}`, `{"f_number": 2}`, or the
/// optics_ref form `{"type": "EPD", "value_mm": 25}` / `{"type": "FNO", "value": 2}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ApertureFile {
    /// Entrance-pupil diameter.
    Epd {
        /// mm.
        epd_mm: f64,
    },
    /// Infinite-conjugate F-number EFL/EPD.
    FNumber {
        /// F/#.
        f_number: f64,
    },
    /// optics_ref form.
    Typed {
        /// "EPD" or "FNO".
        #[serde(rename = "type")]
        kind: String,
        /// EPD in mm (type EPD).
        #[serde(default)]
        value_mm: Option<f64>,
        /// F/# (type FNO).
        #[serde(default)]
        value: Option<f64>,
    },
}

/// A prescription file as written (see the crate docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrescriptionFile {
    /// Lens name.
    #[serde(default)]
    pub name: String,
    /// Length unit; only "mm" is accepted.
    #[serde(default = "default_units")]
    pub units: String,
    /// Surfaces from the object side.
    pub surfaces: Vec<SurfaceFile>,
    /// Object distance from the first vertex (mm); `null` = infinity.
    #[serde(default)]
    pub object_distance_mm: Option<f64>,
    /// Field angles (degrees, object space).
    #[serde(default)]
    pub fields_deg: Vec<f64>,
    /// Wavelengths (nm).
    #[serde(default)]
    pub wavelengths_nm: Vec<f64>,
    /// Primary wavelength (nm); default the middle entry of `wavelengths_nm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub primary_nm: Option<f64>,
    /// Aperture.
    pub aperture: ApertureFile,
    /// Where the data come from (publication, patent, licence), free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<String>,
    /// Coordinate breaks (decentres and tilts, [`crate::fold`]); each names a flat dummy
    /// surface.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub coordinate_breaks: Vec<CoordinateBreak>,
}

fn default_units() -> String {
    "mm".into()
}

/// The medium after a surface, resolved to a dispersion law.
#[derive(Debug, Clone, PartialEq)]
pub enum Medium {
    /// Air (index 1; catalogue indices are relative to air).
    Air,
    /// A glass.
    Glass(Glass),
}

impl Medium {
    /// n at `wavelength_nm`.
    pub fn index(&self, wavelength_nm: f64) -> f64 {
        match self {
            Medium::Air => 1.0,
            Medium::Glass(g) => g.index(wavelength_nm),
        }
    }
}

/// A validated surface (f64 throughout).
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// Vertex curvature 1/R (mm⁻¹), 0 for flat.
    pub curvature_per_mm: f64,
    /// Axial distance to the next vertex / image plane (mm).
    pub thickness_mm: f64,
    /// Medium after the surface.
    pub medium: Medium,
    /// Material as written (kept for writing the file back).
    pub material: MaterialFile,
    /// Clear semi-aperture (mm), if given.
    pub semi_diameter_mm: Option<f64>,
    /// Conic constant.
    pub conic: f64,
    /// Even-asphere coefficients A4, A6, ….
    pub aspheric_coeffs: Vec<f64>,
    /// Odd-asphere coefficients β1, β2, β3, … of r¹, r², r³, … (Zemax `ODDASPHE`).
    pub odd_aspheric_coeffs: Vec<f64>,
}

impl Surface {
    /// Sag z(r²) of the surface: c r²/(1 + √(1 − (1+k)c²r²)) + Σ A_{2i+4} r^{2i+4}
    /// (standard even asphere, e.g. Smith §13) + Σ β_i r^i, i = 1, 2, … (the Zemax odd
    /// asphere, `ODDASPHE`, OpticStudio manual "Odd Asphere"; Optiland `OddAsphere`).
    /// `None` outside the conic's domain.
    pub fn sag_mm(&self, r2: f64) -> Option<f64> {
        let c = self.curvature_per_mm;
        let arg = 1.0 - (1.0 + self.conic) * c * c * r2;
        if arg < 0.0 {
            return None;
        }
        let mut z = c * r2 / (1.0 + arg.sqrt());
        let mut p = r2 * r2;
        for a in &self.aspheric_coeffs {
            z += a * p;
            p *= r2;
        }
        if !self.odd_aspheric_coeffs.is_empty() {
            let r = r2.sqrt();
            let mut p = r;
            for b in &self.odd_aspheric_coeffs {
                z += b * p;
                p *= r;
            }
        }
        Some(z)
    }

    /// dz/d(r²) of the sag (so ∂z/∂x = 2x·dz/d(r²)). `None` outside the conic's domain.
    /// An odd-asphere β1·r term (a cone at the vertex) contributes β1/(2r), which is infinite
    /// on the axis: there it is left out (the axial normal, the limit of the symmetric cone).
    pub fn dsag_dr2(&self, r2: f64) -> Option<f64> {
        let c = self.curvature_per_mm;
        let arg = 1.0 - (1.0 + self.conic) * c * c * r2;
        if arg <= 0.0 {
            return None;
        }
        // d/dr of the conic term is c r/√arg, so d/d(r²) is c/(2√arg).
        let mut d = c / (2.0 * arg.sqrt());
        let mut p = r2;
        for (i, a) in self.aspheric_coeffs.iter().enumerate() {
            let m = (i + 2) as f64; // term a·(r²)^m
            d += a * m * p;
            p *= r2;
        }
        // β_i r^i = β_i (r²)^(i/2): d/d(r²) = (i/2) β_i r^(i−2).
        if !self.odd_aspheric_coeffs.is_empty() {
            let r = r2.sqrt();
            for (k, b) in self.odd_aspheric_coeffs.iter().enumerate() {
                let i = (k + 1) as i32;
                if *b == 0.0 || (i == 1 && r == 0.0) {
                    continue;
                }
                d += b * 0.5 * i as f64 * r.powi(i - 2);
            }
        }
        Some(d)
    }

    /// d²z/d(r²)² of the sag (so ∂²z/∂y² on the meridian = 2·dz/d(r²) + 4y²·d²z/d(r²)²).
    /// `None` outside the conic's domain. Odd-asphere terms β1·r and β3·r³ have a d²z/d(r²)²
    /// that is infinite on the axis (their d²z/dr² is finite: 0 and 6β3·r); there they are
    /// left out, which keeps 2·dz/d(r²) + 4r²·d²z/d(r²)² right at r = 0.
    pub fn d2sag_dr2(&self, r2: f64) -> Option<f64> {
        let c = self.curvature_per_mm;
        let k1 = 1.0 + self.conic;
        let arg = 1.0 - k1 * c * c * r2;
        if arg <= 0.0 {
            return None;
        }
        // d/d(r²) of c/(2√arg) = c·k1c²/(4 arg^{3/2}).
        let mut d = c * k1 * c * c / (4.0 * arg * arg.sqrt());
        let mut p = 1.0;
        for (i, a) in self.aspheric_coeffs.iter().enumerate() {
            let m = (i + 2) as f64; // term a·(r²)^m
            d += a * m * (m - 1.0) * p;
            p *= r2;
        }
        // d²/d(r²)² of β_i (r²)^(i/2) = (i/2)(i/2 − 1) β_i r^(i−4).
        if !self.odd_aspheric_coeffs.is_empty() {
            let r = r2.sqrt();
            for (k, b) in self.odd_aspheric_coeffs.iter().enumerate() {
                let i = (k + 1) as i32;
                if *b == 0.0 || i == 2 || (i < 4 && r == 0.0) {
                    continue;
                }
                let h = 0.5 * i as f64;
                d += b * h * (h - 1.0) * r.powi(i - 4);
            }
        }
        Some(d)
    }

    /// Principal curvatures (mm⁻¹) of the surface at radial distance `r_mm` from the axis:
    /// meridional (tangential) z''/(1 + z'²)^{3/2} and azimuthal (sagittal) z'/(r (1 + z'²)^{1/2})
    /// of the profile z(r) (a surface of revolution; both equal the vertex curvature on the
    /// axis). Signed like `curvature_per_mm`. `None` outside the conic's domain.
    pub fn principal_curvatures_per_mm(&self, r_mm: f64) -> Option<[f64; 2]> {
        let r2 = r_mm * r_mm;
        let g = self.dsag_dr2(r2)?;
        let g2 = self.d2sag_dr2(r2)?;
        let z1 = 2.0 * r_mm * g; // dz/dr
        let z2 = 2.0 * g + 4.0 * r2 * g2; // d²z/dr²
        let q = 1.0 + z1 * z1;
        // z'/r = 2g (finite on the axis).
        Some([z2 / (q * q.sqrt()), 2.0 * g / q.sqrt()])
    }

    /// True if the surface is a sphere or plane (closed-form intersection suffices).
    pub fn is_conic_only(&self) -> bool {
        self.aspheric_coeffs.iter().all(|a| *a == 0.0)
            && self.odd_aspheric_coeffs.iter().all(|b| *b == 0.0)
    }
}

/// Aperture specification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Aperture {
    /// Entrance-pupil diameter (mm).
    EntrancePupilDiameter(f64),
    /// Infinite-conjugate F-number EFL/EPD (the EPD follows from the EFL at the primary
    /// wavelength).
    FNumber(f64),
}

/// A validated sequential, rotationally symmetric lens.
#[derive(Debug, Clone, PartialEq)]
pub struct LensPrescription {
    /// Name.
    pub name: String,
    /// Surfaces from the object side; the last thickness is the image distance.
    pub surfaces: Vec<Surface>,
    /// Index of the aperture-stop surface.
    pub stop_index: usize,
    /// Object distance from the first vertex (mm); `None` = infinity.
    pub object_distance_mm: Option<f64>,
    /// Field angles (degrees).
    pub fields_deg: Vec<f64>,
    /// Wavelengths (nm).
    pub wavelengths_nm: Vec<f64>,
    /// Primary wavelength (nm).
    pub primary_nm: f64,
    /// Aperture.
    pub aperture: Aperture,
    /// Provenance text.
    pub provenance: Option<String>,
    /// Coordinate breaks ([`crate::fold`]), at most one per surface.
    pub coordinate_breaks: Vec<CoordinateBreak>,
}

impl LensPrescription {
    /// Parse JSON text and validate, resolving glasses in `catalog`.
    pub fn from_json_str(text: &str, catalog: &GlassCatalog) -> Result<Self, LensError> {
        let f: PrescriptionFile = serde_json::from_str(text)?;
        Self::from_file_form(&f, catalog)
    }

    /// Read and validate a JSON prescription file.
    pub fn from_json_file(
        path: impl AsRef<Path>,
        catalog: &GlassCatalog,
    ) -> Result<Self, LensError> {
        let p = path.as_ref();
        let text = std::fs::read_to_string(p).map_err(|e| LensError::Io {
            path: p.display().to_string(),
            msg: e.to_string(),
        })?;
        Self::from_json_str(&text, catalog)
    }

    /// Validate the file form.
    pub fn from_file_form(f: &PrescriptionFile, catalog: &GlassCatalog) -> Result<Self, LensError> {
        let bad = |m: String| LensError::Prescription(m);
        if f.units != "mm" {
            return Err(bad(format!(
                "units = '{}' (only \"mm\" is supported)",
                f.units
            )));
        }
        if f.surfaces.is_empty() {
            return Err(bad("no surfaces".into()));
        }
        let mut surfaces = Vec::with_capacity(f.surfaces.len());
        let mut stop = None;
        let mut prev_medium = Medium::Air;
        for (k, c) in f.coordinate_breaks.iter().enumerate() {
            let v = [
                c.decenter_x_mm,
                c.decenter_y_mm,
                c.tilt_x_deg,
                c.tilt_y_deg,
                c.tilt_z_deg,
            ];
            if c.surface >= f.surfaces.len() {
                return Err(bad(format!(
                    "coordinate_breaks[{k}]: surface {} does not exist ({} surfaces)",
                    c.surface,
                    f.surfaces.len()
                )));
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!(
                    "coordinate_breaks[{k}]: decentres and tilts must be finite, got {v:?}"
                )));
            }
            if f.coordinate_breaks[..k]
                .iter()
                .any(|o| o.surface == c.surface)
            {
                return Err(bad(format!(
                    "coordinate_breaks[{k}]: surface {} has two coordinate breaks",
                    c.surface
                )));
            }
        }
        for (i, s) in f.surfaces.iter().enumerate() {
            let curvature_per_mm = match s.radius_mm {
                None => 0.0,
                Some(r) if r.is_infinite() => 0.0,
                Some(r) if r == 0.0 || r.is_nan() => {
                    return Err(bad(format!(
                        "surface {i}: radius_mm = {r} (use null for a flat surface)"
                    )))
                }
                Some(r) => 1.0 / r,
            };
            if !s.thickness_mm.is_finite() {
                return Err(bad(format!(
                    "surface {i}: thickness_mm = {} is not finite",
                    s.thickness_mm
                )));
            }
            if let Some(sd) = s.semi_diameter_mm {
                if !(sd.is_finite() && sd > 0.0) {
                    return Err(bad(format!(
                        "surface {i}: semi_diameter_mm = {sd} must be > 0"
                    )));
                }
            }
            if !s.conic.is_finite()
                || s.aspheric_coeffs.iter().any(|a| !a.is_finite())
                || s.odd_aspheric_coeffs.iter().any(|b| !b.is_finite())
            {
                return Err(bad(format!(
                    "surface {i}: conic / aspheric_coeffs / odd_aspheric_coeffs must be finite"
                )));
            }
            let is_break = f.coordinate_breaks.iter().any(|c| c.surface == i);
            let medium = match &s.material {
                // A mirror or a coordinate break leaves the light in the medium it was in.
                _ if is_break => prev_medium.clone(),
                MaterialFile::Name(n) if n.eq_ignore_ascii_case("mirror") => prev_medium.clone(),
                MaterialFile::Name(n) if n.eq_ignore_ascii_case("air") => Medium::Air,
                MaterialFile::Name(n) => Medium::Glass(catalog.glass(n, None)?),
                MaterialFile::Catalog { glass, catalog: c } => {
                    Medium::Glass(catalog.glass(glass, c.as_deref())?)
                }
                MaterialFile::Model { nd, vd } => {
                    if *nd == 1.0 && *vd == 0.0 {
                        Medium::Air
                    } else {
                        Medium::Glass(Glass::from_nd_vd(*nd, *vd)?)
                    }
                }
            };
            if s.stop {
                if let Some(j) = stop {
                    return Err(bad(format!(
                        "surfaces {j} and {i} are both marked \"stop\""
                    )));
                }
                stop = Some(i);
            }
            if is_break && s.stop {
                return Err(bad(format!(
                    "surface {i}: a coordinate break cannot be the stop"
                )));
            }
            if is_break
                && (curvature_per_mm != 0.0
                    || s.conic != 0.0
                    || !s.aspheric_coeffs.is_empty()
                    || !s.odd_aspheric_coeffs.is_empty())
            {
                return Err(bad(format!(
                    "surface {i}: a coordinate break must be flat (radius_mm null, no conic or \
                     aspheric_coeffs)"
                )));
            }
            prev_medium = medium.clone();
            surfaces.push(Surface {
                curvature_per_mm,
                thickness_mm: s.thickness_mm,
                medium,
                material: s.material.clone(),
                semi_diameter_mm: s.semi_diameter_mm,
                conic: s.conic,
                aspheric_coeffs: s.aspheric_coeffs.clone(),
                odd_aspheric_coeffs: s.odd_aspheric_coeffs.clone(),
            });
        }
        let stop_index = stop.ok_or_else(|| bad("no surface is marked \"stop\": true".into()))?;
        if let Some(d) = f.object_distance_mm {
            if !(d.is_finite() && d > 0.0) {
                return Err(bad(format!(
                    "object_distance_mm = {d} must be > 0 (null = infinity)"
                )));
            }
        }
        if let Some(w) = f
            .wavelengths_nm
            .iter()
            .find(|w| !(w.is_finite() && **w > 0.0))
        {
            return Err(LensError::Wavelength {
                wavelength_nm: *w,
                msg: "must be positive".into(),
            });
        }
        let wavelengths_nm = if f.wavelengths_nm.is_empty() {
            vec![crate::glass::LAMBDA_D_NM]
        } else {
            f.wavelengths_nm.clone()
        };
        let primary_nm = f
            .primary_nm
            .unwrap_or(wavelengths_nm[wavelengths_nm.len() / 2]);
        if !(primary_nm.is_finite() && primary_nm > 0.0) {
            return Err(LensError::Wavelength {
                wavelength_nm: primary_nm,
                msg: "primary_nm must be positive".into(),
            });
        }
        if !wavelengths_nm
            .iter()
            .any(|w| (w - primary_nm).abs() <= 1e-6 * primary_nm)
        {
            return Err(LensError::Wavelength {
                wavelength_nm: primary_nm,
                msg: format!("primary_nm is not one of wavelengths_nm {wavelengths_nm:?}"),
            });
        }
        let fields_deg = if f.fields_deg.is_empty() {
            vec![0.0]
        } else {
            f.fields_deg.clone()
        };
        if let Some(a) = fields_deg
            .iter()
            .find(|a| !(a.is_finite() && a.abs() < 90.0))
        {
            return Err(bad(format!(
                "fields_deg contains {a} (must be in (−90, 90))"
            )));
        }
        let aperture = match &f.aperture {
            ApertureFile::Epd { epd_mm } => Aperture::EntrancePupilDiameter(*epd_mm),
            ApertureFile::FNumber { f_number } => Aperture::FNumber(*f_number),
            ApertureFile::Typed {
                kind,
                value_mm,
                value,
            } => match kind.to_ascii_uppercase().as_str() {
                "EPD" => Aperture::EntrancePupilDiameter(
                    value_mm
                        .or(*value)
                        .ok_or_else(|| bad("aperture type EPD without value_mm".into()))?,
                ),
                "FNO" => Aperture::FNumber(
                    value.ok_or_else(|| bad("aperture type FNO without value".into()))?,
                ),
                k => return Err(bad(format!("aperture type '{k}' (expected EPD or FNO)"))),
            },
        };
        let v = match aperture {
            Aperture::EntrancePupilDiameter(v) | Aperture::FNumber(v) => v,
        };
        if !(v.is_finite() && v > 0.0) {
            return Err(bad(format!("aperture value {v} must be > 0")));
        }
        Ok(LensPrescription {
            name: f.name.clone(),
            surfaces,
            stop_index,
            object_distance_mm: f.object_distance_mm,
            fields_deg,
            wavelengths_nm,
            primary_nm,
            aperture,
            provenance: f.provenance.clone(),
            coordinate_breaks: f.coordinate_breaks.clone(),
        })
    }

    /// Back to the file form (for writing converted prescriptions).
    pub fn to_file_form(&self) -> PrescriptionFile {
        PrescriptionFile {
            name: self.name.clone(),
            units: "mm".into(),
            surfaces: self
                .surfaces
                .iter()
                .enumerate()
                .map(|(i, s)| SurfaceFile {
                    radius_mm: if s.curvature_per_mm == 0.0 {
                        None
                    } else {
                        Some(1.0 / s.curvature_per_mm)
                    },
                    thickness_mm: s.thickness_mm,
                    material: s.material.clone(),
                    semi_diameter_mm: s.semi_diameter_mm,
                    conic: s.conic,
                    aspheric_coeffs: s.aspheric_coeffs.clone(),
                    odd_aspheric_coeffs: s.odd_aspheric_coeffs.clone(),
                    stop: i == self.stop_index,
                })
                .collect(),
            object_distance_mm: self.object_distance_mm,
            fields_deg: self.fields_deg.clone(),
            wavelengths_nm: self.wavelengths_nm.clone(),
            primary_nm: Some(self.primary_nm),
            aperture: match self.aperture {
                Aperture::EntrancePupilDiameter(epd_mm) => ApertureFile::Epd { epd_mm },
                Aperture::FNumber(f_number) => ApertureFile::FNumber { f_number },
            },
            provenance: self.provenance.clone(),
            coordinate_breaks: self.coordinate_breaks.clone(),
        }
    }

    /// Axial position (mm) of each vertex, the first at 0, plus the image plane as last entry.
    /// With mirrors these are unfolded positions (Σ s·t, s the propagation sign, see
    /// [`crate::fold`]).
    pub fn vertex_z_mm(&self) -> Vec<f64> {
        let mut z = Vec::with_capacity(self.surfaces.len() + 1);
        let mut acc = 0.0;
        z.push(0.0);
        let mut sign = 1.0;
        for s in &self.surfaces {
            if s.is_mirror() {
                sign = -sign;
            }
            acc += sign * s.thickness_mm;
            z.push(acc);
        }
        z
    }

    /// The image distance: unfolded last thickness (the last thickness itself unless an odd
    /// number of mirrors precedes the image).
    pub fn image_distance_mm(&self) -> f64 {
        let s = self.propagation_signs().last().copied().unwrap_or(1.0);
        s * self.surfaces.last().map_or(0.0, |x| x.thickness_mm)
    }

    /// Index after each surface at `wavelength_nm` (object space is air, n = 1).
    pub fn indices(&self, wavelength_nm: f64) -> Vec<f64> {
        self.surfaces
            .iter()
            .map(|s| s.medium.index(wavelength_nm))
            .collect()
    }

    /// The lens with its aperture stop's clear radius set to the paraxial stop radius that its
    /// aperture specification implies (at the primary wavelength; a smaller clear radius is
    /// kept): the physical stop a camera built from the prescription has, which limits the real
    /// rays (the stop of an `FNumber` or `Epd` aperture is otherwise only the paraxial one).
    pub fn with_aperture_stop_clear(&self) -> Result<Self, LensError> {
        let stop_sd = self.first_order(self.primary_nm)?.stop_semi_diameter_mm;
        let mut lens = self.clone();
        let s = &mut lens.surfaces[lens.stop_index];
        s.semi_diameter_mm = Some(s.semi_diameter_mm.map_or(stop_sd, |v| v.min(stop_sd)));
        Ok(lens)
    }

    /// A copy with the image distance (last thickness) set to `image_distance_mm`.
    pub fn with_image_distance(&self, image_distance_mm: f64) -> Self {
        let mut l = self.clone();
        let sign = self.propagation_signs().last().copied().unwrap_or(1.0);
        if let Some(s) = l.surfaces.last_mut() {
            s.thickness_mm = sign * image_distance_mm;
        }
        l
    }

    /// A copy with the object distance set (`None` = infinity).
    pub fn with_object_distance(&self, object_distance_mm: Option<f64>) -> Self {
        let mut l = self.clone();
        l.object_distance_mm = object_distance_mm;
        l
    }
}
