//! Field model: the ISET ray-trace lens representation (the "field model" of §2.B.3 of the
//! camera-simulation paper): point-spread functions, distortion and relative illumination
//! tabulated over image height × wavelength for a lens focused at its paraxial focus, with
//! interpolation between tabulated heights and wavelengths and rotation of a PSF to any field
//! azimuth.
//!
//! ## Conventions
//! * Fields are tabulated at object-space angles θ_k whose **paraxial** image heights
//!   h_k = |y_parax(θ_k)| are evenly spaced from 0 to the maximum field; look-ups are by
//!   paraxial image height in mm (the ideal, undistorted position of the image point).
//! * Every PSF is computed for a field point on **+y** (the meridional plane is y–z) and stored
//!   on an `psf_n` × `psf_n` grid (odd `psf_n`) of pitch `psf_pitch_um` µm, row-major
//!   `[iy·n + ix]`, sample (n/2, n/2) at the real chief ray's image point, x = (ix − n/2)·pitch,
//!   y = (iy − n/2)·pitch, values summing to 1.
//! * A field point at azimuth φ (measured from +x towards +y, so +y is φ = 90°) has the +y
//!   PSF rotated by φ − 90° about its centre (bilinear resampling, renormalised).
//! * Distortion: `real_height_mm[field][wavelength]` is the real chief-ray height (chief ray
//!   aimed at the stop centre at that wavelength), `paraxial_height_mm[field]` the paraxial
//!   one at the primary wavelength; distortion % = 100 (real − paraxial)/paraxial.
//! * Relative illumination: [`LensPrescription::relative_illumination`] (vignetting × cos⁴ of
//!   the image-space chief-ray angle) at the primary wavelength.
//! * Wave PSFs come from [`LensPrescription::wave_optics`] (FFT of the pupil function) and are
//!   point-sampled bilinearly onto the common grid, then renormalised; geometric PSFs bin the
//!   rays of a square pupil grid (clipped at the semi-diameters) about the chief ray.
//!
//! ## File format (`FieldModel::save` / `load`)
//! A JSON object whose keys carry their units:
//! ```json
//! {"format": "camsim-lens field model", "version": 1,
//!  "lens_name": "...", "psf_kind": "wave" | "geometric",
//!  "object_distance_mm": null, "image_distance_mm": 41.6, "efl_mm": 49.4, "f_number": 4.5,
//!  "primary_nm": 587.56, "wavelengths_nm": [486.1, 587.6, 656.3],
//!  "field_angles_deg": [0, 8.1, 16.0], "paraxial_height_mm": [0, 7.0, 14.1],
//!  "real_height_mm": [[0, 0, 0], [7.01, 7.02, 7.03], ...],      // [field][wavelength]
//!  "relative_illumination": [1.0, 0.93, 0.78],                  // [field]
//!  "psf_n": 33, "psf_pitch_um": 1.0,
//!  "psf": [[[...n² values...], ...], ...]}                      // [field][wavelength]
//! ```
use crate::analysis::pupil_grid;
use crate::error::LensError;
use crate::prescription::LensPrescription;
use crate::trace::Clipping;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Which PSF the model holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PsfKind {
    /// Diffraction PSF from the OPD map (FFT).
    Wave,
    /// Ray-density (spot) PSF.
    Geometric,
}

/// How to build a [`FieldModel`].
#[derive(Debug, Clone, PartialEq)]
pub struct FieldModelOptions {
    /// Number of tabulated field heights (≥ 2), evenly spaced in paraxial image height.
    pub n_fields: usize,
    /// Maximum field angle (degrees); default the largest of the lens's `fields_deg`.
    pub max_field_deg: Option<f64>,
    /// Wavelengths (nm); default the lens's.
    pub wavelengths_nm: Option<Vec<f64>>,
    /// PSF kind.
    pub kind: PsfKind,
    /// Samples per side of the stored PSFs (made odd).
    pub psf_n: usize,
    /// Pitch of the stored PSFs (µm).
    pub psf_pitch_um: f64,
    /// Pupil samples per side (OPD grid for wave PSFs, ray grid for geometric ones).
    pub pupil_n: usize,
    /// Zero-padding factor of the FFT (wave PSFs).
    pub pad: usize,
    /// Pupil grid per side for relative illumination.
    pub ri_grid_n: usize,
}

impl Default for FieldModelOptions {
    fn default() -> Self {
        FieldModelOptions {
            n_fields: 5,
            max_field_deg: None,
            wavelengths_nm: None,
            kind: PsfKind::Wave,
            psf_n: 33,
            psf_pitch_um: 1.0,
            pupil_n: 64,
            pad: 4,
            ri_grid_n: 64,
        }
    }
}

/// The tabulated field model (see the module docs for conventions and the file format).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldModel {
    /// Always "camsim-lens field model".
    pub format: String,
    /// Format version (1).
    pub version: u32,
    /// Lens name.
    pub lens_name: String,
    /// PSF kind.
    pub psf_kind: PsfKind,
    /// Object distance (mm from the first vertex), `null` = infinity.
    pub object_distance_mm: Option<f64>,
    /// Last vertex → image plane (mm), the paraxial focus at the primary wavelength.
    pub image_distance_mm: f64,
    /// EFL at the primary wavelength (mm).
    pub efl_mm: f64,
    /// Infinite-conjugate F-number.
    pub f_number: f64,
    /// Primary wavelength (nm).
    pub primary_nm: f64,
    /// Tabulated wavelengths (nm, increasing).
    pub wavelengths_nm: Vec<f64>,
    /// Object-space field angle of each tabulated field (degrees).
    pub field_angles_deg: Vec<f64>,
    /// Paraxial image height of each tabulated field at the primary wavelength (mm, increasing).
    pub paraxial_height_mm: Vec<f64>,
    /// Real chief-ray image height, `[field][wavelength]` (mm).
    pub real_height_mm: Vec<Vec<f64>>,
    /// Relative illumination per field (1 on axis).
    pub relative_illumination: Vec<f64>,
    /// PSF samples per side (odd).
    pub psf_n: usize,
    /// PSF sample pitch (µm).
    pub psf_pitch_um: f64,
    /// PSFs `[field][wavelength][iy·n + ix]`, field on +y, centred on the chief ray, sum 1.
    pub psf: Vec<Vec<Vec<f64>>>,
}

/// Bilinear sample of an n×n row-major image at fractional index (fx, fy); 0 outside.
fn bilinear(img: &[f64], n: usize, fx: f64, fy: f64) -> f64 {
    if !(fx > -1.0 && fy > -1.0 && fx < n as f64 && fy < n as f64) {
        return 0.0;
    }
    let x0 = fx.floor();
    let y0 = fy.floor();
    let (tx, ty) = (fx - x0, fy - y0);
    let get = |x: f64, y: f64| -> f64 {
        if x < 0.0 || y < 0.0 || x >= n as f64 || y >= n as f64 {
            0.0
        } else {
            img[y as usize * n + x as usize]
        }
    };
    get(x0, y0) * (1.0 - tx) * (1.0 - ty)
        + get(x0 + 1.0, y0) * tx * (1.0 - ty)
        + get(x0, y0 + 1.0) * (1.0 - tx) * ty
        + get(x0 + 1.0, y0 + 1.0) * tx * ty
}

fn normalise(v: &mut [f64]) {
    let s: f64 = v.iter().sum();
    if s > 0.0 {
        v.iter_mut().for_each(|x| *x /= s);
    }
}

/// Index i and weight t with x = (1 − t)·xs[i] + t·xs[i+1], clamped to the table.
fn bracket(xs: &[f64], x: f64) -> (usize, f64) {
    if xs.len() < 2 || x <= xs[0] {
        return (0, 0.0);
    }
    let last = xs.len() - 1;
    if x >= xs[last] {
        return (last - 1, 1.0);
    }
    let i = xs.partition_point(|&a| a <= x) - 1;
    (i, (x - xs[i]) / (xs[i + 1] - xs[i]))
}

/// Rotate an n×n PSF (centre n/2) by `angle_deg` counter-clockwise (+x towards +y) about its
/// centre, by bilinear resampling; renormalised to sum 1.
pub fn rotate_psf(psf: &[f64], n: usize, angle_deg: f64) -> Vec<f64> {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let c0 = (n / 2) as f64;
    let mut out = vec![0.0; n * n];
    for iy in 0..n {
        for ix in 0..n {
            let (u, v) = (ix as f64 - c0, iy as f64 - c0);
            // source point = R(−angle)·(u, v)
            let (x, y) = (c * u + s * v, -s * u + c * v);
            out[iy * n + ix] = bilinear(psf, n, x + c0, y + c0);
        }
    }
    normalise(&mut out);
    out
}

impl FieldModel {
    /// Build the field model of `lens` focused at its paraxial focus (primary wavelength) for
    /// its own object distance.
    pub fn compute(lens: &LensPrescription, opts: &FieldModelOptions) -> Result<Self, LensError> {
        let bad = |m: String| LensError::Prescription(format!("field model: {m}"));
        if opts.n_fields < 2 {
            return Err(bad(format!("n_fields = {} (need ≥ 2)", opts.n_fields)));
        }
        if !(opts.psf_pitch_um > 0.0) || opts.psf_n == 0 || opts.pupil_n < 2 {
            return Err(bad(
                "psf_pitch_um, psf_n and pupil_n must be positive".into()
            ));
        }
        let psf_n = opts.psf_n | 1;
        let lens = lens.focused(lens.primary_nm)?;
        let fo = lens.first_order(lens.primary_nm)?;
        let mut wls = opts
            .wavelengths_nm
            .clone()
            .unwrap_or_else(|| lens.wavelengths_nm.clone());
        wls.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let max_deg = opts
            .max_field_deg
            .unwrap_or_else(|| lens.fields_deg.iter().cloned().fold(0.0, f64::max));
        if !(max_deg > 0.0) {
            return Err(bad(format!("maximum field {max_deg}° must be > 0")));
        }
        // Paraxial height is linear in tan θ.
        let hmax = lens
            .paraxial_chief_height_mm(max_deg, lens.primary_nm)?
            .abs();
        let per_tan = hmax / max_deg.to_radians().tan();
        let paraxial_height_mm: Vec<f64> = (0..opts.n_fields)
            .map(|k| hmax * k as f64 / (opts.n_fields - 1) as f64)
            .collect();
        let field_angles_deg: Vec<f64> = paraxial_height_mm
            .iter()
            .map(|h| (h / per_tan).atan().to_degrees())
            .collect();
        let pitch_mm = opts.psf_pitch_um * 1e-3;
        let c0 = (psf_n / 2) as f64;
        let mut real_height_mm = Vec::new();
        let mut relative_illumination = Vec::new();
        let mut psf = Vec::new();
        for &th in &field_angles_deg {
            relative_illumination.push(
                lens.relative_illumination(th, opts.ri_grid_n)?
                    .relative_illumination,
            );
            let mut heights = Vec::new();
            let mut per_wl = Vec::new();
            for &w in &wls {
                let fo_w = lens.first_order(w)?;
                let aim = lens.aim_field(th, w, &fo_w)?;
                let chief = lens
                    .trace(&aim.ray(0.0, 0.0), w, Clipping::None)
                    .ok_or_else(|| LensError::Aiming {
                        field_deg: th,
                        msg: format!("chief ray lost at {w} nm"),
                    })?;
                heights.push(chief.image_mm[1]);
                let mut img = vec![0.0; psf_n * psf_n];
                match opts.kind {
                    PsfKind::Wave => {
                        let wo = lens.wave_optics(th, w, opts.pupil_n, opts.pad, &[])?;
                        let m = wo.psf.n;
                        let cm = (m / 2) as f64;
                        // The FFT PSF is point-reflected with respect to the image plane (its
                        // energy centroid sits on the opposite side of the chief ray from the
                        // traced spot centroid); sample it at (−x, −y) so wave and geometric
                        // PSFs share the image-plane orientation.
                        for iy in 0..psf_n {
                            for ix in 0..psf_n {
                                let x = cm - (ix as f64 - c0) * pitch_mm / wo.psf.sample_mm;
                                let y = cm - (iy as f64 - c0) * pitch_mm / wo.psf.sample_mm;
                                img[iy * psf_n + ix] = bilinear(&wo.psf.values, m, x, y);
                            }
                        }
                    }
                    PsfKind::Geometric => {
                        let grid = pupil_grid(opts.pupil_n);
                        for p in &grid {
                            if let Some(r) =
                                lens.trace(&aim.ray(p[0], p[1]), w, Clipping::SemiDiameters)
                            {
                                let fx =
                                    ((r.image_mm[0] - chief.image_mm[0]) / pitch_mm + c0 + 0.5)
                                        .floor();
                                let fy =
                                    ((r.image_mm[1] - chief.image_mm[1]) / pitch_mm + c0 + 0.5)
                                        .floor();
                                if fx >= 0.0
                                    && fy >= 0.0
                                    && (fx as usize) < psf_n
                                    && (fy as usize) < psf_n
                                {
                                    img[fy as usize * psf_n + fx as usize] += 1.0;
                                }
                            }
                        }
                    }
                }
                normalise(&mut img);
                per_wl.push(img);
            }
            real_height_mm.push(heights);
            psf.push(per_wl);
        }
        Ok(FieldModel {
            format: "camsim-lens field model".into(),
            version: 1,
            lens_name: lens.name.clone(),
            psf_kind: opts.kind,
            object_distance_mm: lens.object_distance_mm,
            image_distance_mm: lens.surfaces.last().unwrap().thickness_mm,
            efl_mm: fo.efl_mm,
            f_number: fo.f_number,
            primary_nm: lens.primary_nm,
            wavelengths_nm: wls,
            field_angles_deg,
            paraxial_height_mm,
            real_height_mm,
            relative_illumination,
            psf_n,
            psf_pitch_um: opts.psf_pitch_um,
            psf,
        })
    }

    /// Write the model as JSON (see the module docs).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LensError> {
        let p = path.as_ref();
        let text = serde_json::to_string(self)?;
        std::fs::write(p, text).map_err(|e| LensError::Io {
            path: p.display().to_string(),
            msg: e.to_string(),
        })
    }

    /// Read a model written by [`FieldModel::save`], checking the table shapes.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LensError> {
        let p = path.as_ref();
        let text = std::fs::read_to_string(p).map_err(|e| LensError::Io {
            path: p.display().to_string(),
            msg: e.to_string(),
        })?;
        let m: FieldModel = serde_json::from_str(&text)?;
        let bad = |msg: String| LensError::Io {
            path: p.display().to_string(),
            msg,
        };
        if m.format != "camsim-lens field model" || m.version != 1 {
            return Err(bad(format!(
                "format '{}' version {} (expected camsim-lens field model 1)",
                m.format, m.version
            )));
        }
        let (nf, nw, nn) = (
            m.paraxial_height_mm.len(),
            m.wavelengths_nm.len(),
            m.psf_n * m.psf_n,
        );
        let shape_ok = m.field_angles_deg.len() == nf
            && m.relative_illumination.len() == nf
            && m.real_height_mm.len() == nf
            && m.real_height_mm.iter().all(|r| r.len() == nw)
            && m.psf.len() == nf
            && m.psf
                .iter()
                .all(|f| f.len() == nw && f.iter().all(|p| p.len() == nn));
        if !shape_ok || nf == 0 || nw == 0 {
            return Err(bad(
                "table shapes do not match the field/wavelength lists".into()
            ));
        }
        Ok(m)
    }

    /// PSF of a field on +y at paraxial image height `height_mm` and `wavelength_nm`,
    /// bilinearly interpolated between the tabulated heights and wavelengths (clamped at the
    /// table ends), renormalised to sum 1.
    pub fn psf_on_y(&self, height_mm: f64, wavelength_nm: f64) -> Vec<f64> {
        let (i, s) = bracket(&self.paraxial_height_mm, height_mm.abs());
        let (j, t) = bracket(&self.wavelengths_nm, wavelength_nm);
        let nn = self.psf_n * self.psf_n;
        if (s == 0.0 || s == 1.0) && (t == 0.0 || t == 1.0) {
            // Exactly on a tabulated point: the table entry itself.
            let fi = if s == 1.0 { i + 1 } else { i };
            let wj = if t == 1.0 { j + 1 } else { j };
            return self.psf[fi][wj].clone();
        }
        let mut out = vec![0.0; nn];
        let i1 = (i + 1).min(self.paraxial_height_mm.len() - 1);
        let j1 = (j + 1).min(self.wavelengths_nm.len() - 1);
        for (fi, fw) in [(i, 1.0 - s), (i1, s)] {
            for (wj, ww) in [(j, 1.0 - t), (j1, t)] {
                let w = fw * ww;
                if w == 0.0 {
                    continue;
                }
                for (o, v) in out.iter_mut().zip(&self.psf[fi][wj]) {
                    *o += w * v;
                }
            }
        }
        normalise(&mut out);
        out
    }

    /// PSF of the image point (x, y) mm (paraxial image-plane position) at `wavelength_nm`:
    /// the interpolated +y PSF at r = √(x² + y²) rotated by its azimuth − 90°.
    pub fn psf_at(&self, x_mm: f64, y_mm: f64, wavelength_nm: f64) -> Vec<f64> {
        let r = x_mm.hypot(y_mm);
        let p = self.psf_on_y(r, wavelength_nm);
        if r == 0.0 {
            return p;
        }
        let az = y_mm.atan2(x_mm).to_degrees();
        rotate_psf(&p, self.psf_n, az - 90.0)
    }

    /// Real chief-ray height (mm) at paraxial height `height_mm` and `wavelength_nm`
    /// (bilinear in the tables).
    pub fn real_height_mm_at(&self, height_mm: f64, wavelength_nm: f64) -> f64 {
        let (i, s) = bracket(&self.paraxial_height_mm, height_mm.abs());
        let (j, t) = bracket(&self.wavelengths_nm, wavelength_nm);
        let i1 = (i + 1).min(self.paraxial_height_mm.len() - 1);
        let j1 = (j + 1).min(self.wavelengths_nm.len() - 1);
        let r = &self.real_height_mm;
        (1.0 - s) * ((1.0 - t) * r[i][j] + t * r[i][j1])
            + s * ((1.0 - t) * r[i1][j] + t * r[i1][j1])
    }

    /// Distortion % at tabulated field `k` and wavelength index `j` (0 on axis, where both
    /// heights vanish).
    pub fn distortion_pct(&self, k: usize, j: usize) -> f64 {
        let p = self.paraxial_height_mm[k];
        if p == 0.0 {
            0.0
        } else {
            100.0 * (self.real_height_mm[k][j].abs() - p) / p
        }
    }

    /// Relative illumination at paraxial height `height_mm` (linear in the table).
    pub fn relative_illumination_at(&self, height_mm: f64) -> f64 {
        let (i, s) = bracket(&self.paraxial_height_mm, height_mm.abs());
        let i1 = (i + 1).min(self.paraxial_height_mm.len() - 1);
        (1.0 - s) * self.relative_illumination[i] + s * self.relative_illumination[i1]
    }
}
