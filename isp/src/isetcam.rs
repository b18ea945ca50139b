//! ISETCam-compatible colour transforms, used for oracle tests (never the default).
//!
//! ISETCam's default image processor (ipCompute with "MCC optimized" sensor conversion and
//! XYZ as internal colour space) renders `result = sensor_rgb · T_sensor→XYZ · T_XYZ→display`
//! scaled by one scalar, where
//!
//! * `T_sensor→XYZ` is the least-squares map from the sensor responses to the 24 Macbeth
//!   patches under D65 to their XYZ (both computed with the illuminant in photons and the
//!   photon-based CIE functions `xyzQuanta`, as Riemann sums on the sensor's wavelength grid);
//! * `T_XYZ→display` is the inverse of the display's primaries → XYZ matrix (primary SPDs in
//!   energy against the energy CIE functions on the display's wavelength samples);
//! * the scalar makes `max(result)` equal to `max(sensor data) / voltage swing`.
//!
//! Matrices here use the column-vector convention of [`ColorMatrix`] (`out = M · in`); ISETCam
//! stores the transpose (`out = in · T`).
use crate::color::{fit_color_correction, ColorMatrix};
use crate::mosaic::RgbImage;
use crate::IspError;
use camsim_core::constants::ISETCAM;
use nalgebra::Matrix3;

/// Spectra sampled on a common wavelength grid, `values[wavelength][channel]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SampledSpectra<const N: usize> {
    /// Wavelengths (nm).
    pub wavelength_nm: Vec<f64>,
    /// One row of N channel values per wavelength.
    pub values: Vec<[f64; N]>,
}

fn check_len(name: &str, got: usize, want: usize) -> Result<(), IspError> {
    if got != want {
        return Err(IspError::InvalidParameter {
            name: name.into(),
            value: format!("{got} samples"),
            reason: format!("the wavelength grid has {want}"),
        });
    }
    Ok(())
}

/// ISETCam `imageSensorTransform(..., 'mcc')`: the 3×3 sensor → XYZ matrix fitted on the
/// Macbeth chart. `reflectances` holds one spectrum (on the grid) per patch; the illuminant is
/// in energy units and converted to photons (λ / hc) as ISETCam does.
pub fn mcc_sensor_to_xyz(
    sensor_qe: &SampledSpectra<3>,
    illuminant_energy: &[f64],
    reflectances: &[Vec<f64>],
    xyz_quanta: &SampledSpectra<3>,
) -> Result<ColorMatrix, IspError> {
    let nw = sensor_qe.wavelength_nm.len();
    check_len("sensor_qe", sensor_qe.values.len(), nw)?;
    check_len("illuminant_energy", illuminant_energy.len(), nw)?;
    check_len("xyz_quanta", xyz_quanta.values.len(), nw)?;
    if xyz_quanta.wavelength_nm != sensor_qe.wavelength_nm {
        return Err(IspError::InvalidParameter {
            name: "xyz_quanta.wavelength_nm".into(),
            value: format!("{:?}", xyz_quanta.wavelength_nm),
            reason: "must equal the sensor grid".into(),
        });
    }
    let ill_photons: Vec<f64> = sensor_qe
        .wavelength_nm
        .iter()
        .zip(illuminant_energy)
        .map(|(&w, &e)| e * ISETCAM.photons_per_joule(w))
        .collect();
    let mut sensor = Vec::with_capacity(reflectances.len());
    let mut target = Vec::with_capacity(reflectances.len());
    for (i, r) in reflectances.iter().enumerate() {
        check_len(&format!("reflectances[{i}]"), r.len(), nw)?;
        let mut s = [0.0; 3];
        let mut t = [0.0; 3];
        for w in 0..nw {
            let q = ill_photons[w] * r[w];
            for k in 0..3 {
                s[k] += sensor_qe.values[w][k] * q;
                t[k] += xyz_quanta.values[w][k] * q;
            }
        }
        sensor.push(s);
        target.push(t);
    }
    fit_color_correction(&sensor, &target)
}

/// ISETCam `displayGet(d, 'rgb2xyz')` as a column-vector matrix: column p is the XYZ of
/// primary p at full drive, `683 Σ_λ spd_p(λ) cmf(λ) Δλ` (Δλ = grid spacing, the first
/// interval for an irregular grid).
pub fn display_rgb_to_xyz(
    primaries_energy: &SampledSpectra<3>,
    cmf_energy: &SampledSpectra<3>,
) -> Result<ColorMatrix, IspError> {
    let w = &primaries_energy.wavelength_nm;
    check_len("cmf_energy", cmf_energy.values.len(), w.len())?;
    check_len("primaries_energy", primaries_energy.values.len(), w.len())?;
    let dl = if w.len() > 1 { w[1] - w[0] } else { 1.0 };
    let mut m = [[0.0; 3]; 3];
    for (spd, cmf) in primaries_energy.values.iter().zip(&cmf_energy.values) {
        for k in 0..3 {
            for p in 0..3 {
                m[k][p] += 683.0 * spd[p] * cmf[k] * dl;
            }
        }
    }
    Ok(ColorMatrix { m })
}

/// The inverse of a 3×3 matrix; errors when it is singular.
pub fn invert(m: &ColorMatrix) -> Result<ColorMatrix, IspError> {
    let a = Matrix3::from_fn(|i, j| m.m[i][j]);
    let inv = a
        .try_inverse()
        .ok_or_else(|| IspError::Fit(format!("matrix {:?} is singular", m.m)))?;
    Ok(ColorMatrix {
        m: [0, 1, 2].map(|i| [0, 1, 2].map(|j| inv[(i, j)])),
    })
}

/// Linearly interpolate sampled spectra onto another grid (zero outside the source range), as
/// ISETCam's `interp1(..., 'linear', 0)` resampling of data files.
pub fn resample<const N: usize>(s: &SampledSpectra<N>, wave_nm: &[f64]) -> SampledSpectra<N> {
    let w = &s.wavelength_nm;
    let values = wave_nm
        .iter()
        .map(|&x| {
            if w.is_empty() || x < w[0] || x > w[w.len() - 1] {
                return [0.0; N];
            }
            let j = w.partition_point(|&v| v <= x).clamp(1, w.len().max(2) - 1);
            if w.len() == 1 {
                return s.values[0];
            }
            let (x0, x1) = (w[j - 1], w[j]);
            let t = if x1 > x0 { (x - x0) / (x1 - x0) } else { 0.0 };
            let mut out = [0.0; N];
            for k in 0..N {
                out[k] = s.values[j - 1][k] * (1.0 - t) + s.values[j][k] * t;
            }
            out
        })
        .collect();
    SampledSpectra {
        wavelength_nm: wave_nm.to_vec(),
        values,
    }
}

/// The primaries of an embedded display file (e.g. `"displays/lcdExample"`), energy units.
pub fn display_primaries(name: &str) -> Result<SampledSpectra<3>, IspError> {
    let v = camsim_core::data::json(name)?;
    let bad = |m: &str| IspError::Data(format!("{name}: {m}"));
    let w: Vec<f64> = v["wavelength_nm"]
        .as_array()
        .ok_or_else(|| bad("no wavelength_nm"))?
        .iter()
        .map(|x| x.as_f64().ok_or_else(|| bad("non-numeric wavelength")))
        .collect::<Result<_, _>>()?;
    let spd = v["spd"].as_array().ok_or_else(|| bad("no spd"))?;
    if spd.len() != 3 {
        return Err(bad(&format!("{} primaries, expected 3", spd.len())));
    }
    let mut values = vec![[0.0; 3]; w.len()];
    for (p, prim) in spd.iter().enumerate() {
        let a = prim
            .as_array()
            .ok_or_else(|| bad("spd must be a list per primary"))?;
        if a.len() != w.len() {
            return Err(bad(&format!(
                "primary {p} has {} samples for {} wavelengths",
                a.len(),
                w.len()
            )));
        }
        for (i, x) in a.iter().enumerate() {
            values[i][p] = x.as_f64().ok_or_else(|| bad("non-numeric spd"))?;
        }
    }
    Ok(SampledSpectra {
        wavelength_nm: w,
        values,
    })
}

/// Scale an image so that its largest value equals `target_max` (ISETCam's final display
/// scaling, with `target_max = max(sensor data) / voltage swing`). Returns the factor.
pub fn scale_to_max(img: &mut RgbImage, target_max: f64) -> Result<f64, IspError> {
    let mx = img.max_value() as f64;
    if !(mx > 0.0 && mx.is_finite()) {
        return Err(IspError::InvalidParameter {
            name: "image maximum".into(),
            value: format!("{mx}"),
            reason: "must be positive to scale to a maximum".into(),
        });
    }
    let k = target_max / mx;
    img.data
        .iter_mut()
        .for_each(|p| *p = p.map(|v| (v as f64 * k) as f32));
    Ok(k)
}
