//! Readers for foreign lens formats.
//!
//! ISET / pbrt `.dat` (pbrt-v4 `RealisticCamera`, ISETCam `lensC`): comment lines start with
//! `#`; each data row is `radius  thickness  index  aperture` in mm, listed from the scene side;
//! `thickness` is the axial distance to the next row, `index` the medium after the surface
//! (0 = air for the stop row), `aperture` the clear **diameter**; a radius of 0 marks the
//! aperture stop (flat). The last row's thickness is the distance to the film (often 0 in the
//! files; the caller refocuses). The entrance pupil follows from the stop diameter.
use crate::error::LensError;
use crate::glass::GlassCatalog;
use crate::paraxial::ynu_trace;
use crate::prescription::{
    ApertureFile, LensPrescription, MaterialFile, PrescriptionFile, SurfaceFile,
};

/// Parse an ISET/pbrt `.dat` lens. The EPD is set so the paraxial marginal ray of an object at
/// infinity fills the stop row's aperture (at `wavelength_nm`; the indices are dispersionless).
pub fn read_iset_dat(text: &str, name: &str) -> Result<PrescriptionFile, LensError> {
    let err = |line: usize, msg: String| LensError::Reader {
        format: "ISET .dat",
        line,
        msg,
    };
    let mut surfaces = Vec::new();
    let mut stop_sd = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = t
            .split_whitespace()
            .map(|w| {
                w.parse::<f64>()
                    .map_err(|_| err(i + 1, format!("'{w}' is not a number")))
            })
            .collect::<Result<_, _>>()?;
        if v.len() != 4 {
            return Err(err(
                i + 1,
                format!(
                    "expected 4 columns (radius thickness index aperture), got {}",
                    v.len()
                ),
            ));
        }
        let (r, t_mm, n, ap) = (v[0], v[1], v[2], v[3]);
        let stop = r == 0.0;
        if stop {
            if stop_sd.is_some() {
                return Err(err(i + 1, "second stop row (radius 0)".into()));
            }
            stop_sd = Some(ap / 2.0);
        }
        let material = if n == 0.0 || n == 1.0 {
            MaterialFile::Name("air".into())
        } else {
            MaterialFile::Model { nd: n, vd: 0.0 }
        };
        surfaces.push(SurfaceFile {
            radius_mm: if stop { None } else { Some(r) },
            thickness_mm: t_mm,
            material,
            semi_diameter_mm: Some(ap / 2.0),
            conic: 0.0,
            aspheric_coeffs: vec![],
            stop,
        });
    }
    let stop_sd = stop_sd.ok_or_else(|| err(0, "no stop row (radius 0)".into()))?;
    let mut f = PrescriptionFile {
        name: name.to_string(),
        units: "mm".into(),
        surfaces,
        object_distance_mm: None,
        fields_deg: vec![0.0],
        wavelengths_nm: vec![crate::glass::LAMBDA_D_NM],
        primary_nm: None,
        aperture: ApertureFile::Epd { epd_mm: 1.0 },
        provenance: None,
    };
    // Unit-height parallel ray → its stop height gives EPD = 2 sd / |y_stop|.
    let l = LensPrescription::from_file_form(&f, &GlassCatalog::bundled())?;
    let a = ynu_trace(&l, l.primary_nm, 1.0, 0.0);
    let ys = a.y_mm[l.stop_index].abs();
    if ys < 1e-12 {
        return Err(err(0, "the stop is at a focus of the front group".into()));
    }
    f.aperture = ApertureFile::Epd {
        epd_mm: 2.0 * stop_sd / ys,
    };
    Ok(f)
}
