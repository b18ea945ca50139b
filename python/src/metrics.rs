//! Spectra, colorimetry and image-quality metrics: photon/energy conversion, illuminants,
//! CIE XYZ, CIELAB, ΔE*ab / ΔE94 / CIEDE2000, S-CIELAB, ISO 12233 slanted-edge MTF, PSNR.
use crate::{arr, err_msg, f64_values};
use camsim_core::colorimetry::{Lab, Quadrature, Xyz};
use camsim_core::constants::{PhysicalConstants, ISETCAM, SI};
use camsim_core::spectrum::Spectrum;
use numpy::{AllowTypeChange, PyArrayLikeDyn};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn constants(name: &str) -> PyResult<&'static PhysicalConstants> {
    match name {
        "si" => Ok(&SI),
        "isetcam" => Ok(&ISETCAM),
        c => Err(err_msg(format!(
            "constants: expected \"si\" or \"isetcam\", got \"{c}\""
        ))),
    }
}

fn spectrum(wavelength_nm: Vec<f64>, values: Vec<f64>) -> PyResult<Spectrum> {
    Spectrum::sampled(wavelength_nm, values).map_err(|e| err_msg(format!("spectrum: {e}")))
}

/// Triples of the last axis (length 3) of an array-like; returns them and the leading shape.
fn triples(
    what: &str,
    a: &PyArrayLikeDyn<'_, f64, AllowTypeChange>,
) -> PyResult<(Vec<[f64; 3]>, Vec<usize>)> {
    let (v, shape) = f64_values(a);
    if shape.last() != Some(&3) {
        return Err(err_msg(format!(
            "{what}: the last axis must have length 3, got shape {shape:?}"
        )));
    }
    Ok((
        v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        shape[..shape.len() - 1].to_vec(),
    ))
}

fn lab(t: [f64; 3]) -> Lab {
    Lab {
        l: t[0],
        a: t[1],
        b: t[2],
    }
}

fn xyz(t: [f64; 3]) -> Xyz {
    Xyz {
        x: t[0],
        y: t[1],
        z: t[2],
    }
}

/// Energy spectrum (W per nm) → photons (photons/s per nm) sampled at `wavelength_nm`:
/// E · λ / (h c), with the SI 2019 or ISETCam constants.
#[pyfunction]
#[pyo3(signature = (wavelength_nm, energy, constants="si"))]
fn energy_to_photons<'py>(
    py: Python<'py>,
    wavelength_nm: Vec<f64>,
    energy: Vec<f64>,
    constants: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let c = self::constants(constants)?;
    let s = spectrum(wavelength_nm.clone(), energy)?.energy_to_photons(c);
    let n = wavelength_nm.len();
    arr(py, wavelength_nm.iter().map(|&w| s.eval(w)).collect(), &[n])
}

/// A named illuminant of the embedded ISETCam data (e.g. "D65", "tungsten"), energy units
/// (relative), sampled at `wavelength_nm`.
#[pyfunction]
fn illuminant<'py>(
    py: Python<'py>,
    name: &str,
    wavelength_nm: Vec<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let s = camsim_core::data::illuminant(name).map_err(err_msg)?;
    let n = wavelength_nm.len();
    arr(py, wavelength_nm.iter().map(|&w| s.eval(w)).collect(), &[n])
}

/// Blackbody spectral radiance (W/(sr·m²·nm)) at `kelvin`, sampled at `wavelength_nm`, with
/// the radiation constants c1 (W·m²) and c2 (m·K) (defaults: ISETCam's).
#[pyfunction]
#[pyo3(signature = (kelvin, wavelength_nm, c1=3.741832e-16, c2=1.438786e-2))]
fn blackbody<'py>(
    py: Python<'py>,
    kelvin: f64,
    wavelength_nm: Vec<f64>,
    c1: f64,
    c2: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let n = wavelength_nm.len();
    arr(
        py,
        wavelength_nm
            .iter()
            .map(|&w| camsim_core::scene::blackbody_value(kelvin, w, c1, c2))
            .collect(),
        &[n],
    )
}

/// CIE 1931 XYZ of an energy spectrum (W/(sr·m²·nm) → XYZ with K_m = 683 lm/W).
/// `quadrature`: "exact" (piecewise-linear integrals) or "riemann" (Σ on the given regular
/// integer grid × step, ISETCam's convention).
#[pyfunction]
#[pyo3(signature = (wavelength_nm, energy, quadrature="exact"))]
fn xyz_from_energy(
    wavelength_nm: Vec<f64>,
    energy: Vec<f64>,
    quadrature: &str,
) -> PyResult<(f64, f64, f64)> {
    let q = match quadrature {
        "exact" => Quadrature::Exact,
        "riemann" => {
            let n = wavelength_nm.len();
            let ok_int = |x: f64| x.fract() == 0.0 && x >= 0.0;
            let step = if n > 1 {
                wavelength_nm[1] - wavelength_nm[0]
            } else {
                1.0
            };
            let regular = wavelength_nm
                .windows(2)
                .all(|w| (w[1] - w[0] - step).abs() < 1e-9);
            if n == 0 || !regular || !ok_int(wavelength_nm[0]) || !ok_int(step) || step <= 0.0 {
                return Err(err_msg(
                    "wavelength_nm: the riemann quadrature needs a regular grid of whole nm",
                ));
            }
            Quadrature::RiemannOnGrid {
                start_nm: wavelength_nm[0] as u32,
                step_nm: step as u32,
                count: n as u32,
            }
        }
        q => {
            return Err(err_msg(format!(
                "quadrature: expected \"exact\" or \"riemann\", got \"{q}\""
            )))
        }
    };
    let s = spectrum(wavelength_nm, energy)?;
    let x = camsim_core::colorimetry::xyz_from_energy(&s, q);
    Ok((x.x, x.y, x.z))
}

/// CIE XYZ (..., 3) → CIELAB (..., 3) relative to `white_xyz` (same units).
#[pyfunction]
fn xyz_to_lab<'py>(
    py: Python<'py>,
    xyz_values: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    white_xyz: [f64; 3],
) -> PyResult<Bound<'py, PyAny>> {
    let (t, mut shape) = triples("xyz", &xyz_values)?;
    let w = xyz(white_xyz);
    let out: Vec<f64> = t
        .iter()
        .flat_map(|&v| {
            let l = camsim_core::colorimetry::xyz_to_lab(xyz(v), w);
            [l.l, l.a, l.b]
        })
        .collect();
    shape.push(3);
    arr(py, out, &shape)
}

fn pairwise<'py>(
    py: Python<'py>,
    a: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    b: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    f: fn(Lab, Lab) -> f64,
) -> PyResult<Bound<'py, PyAny>> {
    let (ta, sa) = triples("lab1", &a)?;
    let (tb, sb) = triples("lab2", &b)?;
    if sa != sb {
        return Err(err_msg(format!(
            "lab1 and lab2 differ in shape: {sa:?} vs {sb:?}"
        )));
    }
    let out: Vec<f64> = ta
        .iter()
        .zip(&tb)
        .map(|(x, y)| f(lab(*x), lab(*y)))
        .collect();
    arr(py, out, &sa)
}

/// ΔE*ab (CIE 1976) between CIELAB arrays (..., 3).
#[pyfunction]
fn delta_e_76<'py>(
    py: Python<'py>,
    lab1: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    lab2: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
) -> PyResult<Bound<'py, PyAny>> {
    pairwise(py, lab1, lab2, camsim_core::colorimetry::delta_e_76)
}

/// ΔE94 (graphic-arts weights; `lab1` is the reference) between CIELAB arrays (..., 3).
#[pyfunction]
fn delta_e_94<'py>(
    py: Python<'py>,
    lab1: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    lab2: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
) -> PyResult<Bound<'py, PyAny>> {
    pairwise(py, lab1, lab2, camsim_metrics::delta_e_94)
}

/// CIEDE2000 (k_L = k_C = k_H = 1) between CIELAB arrays (..., 3).
#[pyfunction]
fn delta_e_2000<'py>(
    py: Python<'py>,
    lab1: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    lab2: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
) -> PyResult<Bound<'py, PyAny>> {
    pairwise(py, lab1, lab2, camsim_metrics::delta_e_2000)
}

/// S-CIELAB between two XYZ images (rows, cols, 3) viewed at `samples_per_degree`, CIELAB
/// against `white_xyz`. `formula`: "cie76" (Zhang & Wandell 1996) or "ciede2000".
/// `parameters`: "camsim" (the published 1996 filters, mirror borders) or "isetcam" (ISETCam's
/// scielab: CIEDE2000 whatever `formula`, distributed filters, one-degree support, 10° opponent
/// matrix — give 10° XYZ —, circular filtering, XYZ clipped to the white; even sides are cut by
/// one). Returns (ΔE map float64 (rows', cols'), mean ΔE).
#[pyfunction]
#[pyo3(signature = (xyz_a, xyz_b, white_xyz, samples_per_degree, formula="cie76", parameters="camsim"))]
fn scielab<'py>(
    py: Python<'py>,
    xyz_a: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    xyz_b: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    white_xyz: [f64; 3],
    samples_per_degree: f64,
    formula: &str,
    parameters: &str,
) -> PyResult<(Bound<'py, PyAny>, f64)> {
    let (a, sa) = triples("xyz_a", &xyz_a)?;
    let (b, sb) = triples("xyz_b", &xyz_b)?;
    if sa.len() != 2 || sa != sb {
        return Err(err_msg(format!(
            "xyz_a, xyz_b: expected two (rows, cols, 3) images of one shape, got {sa:?} and {sb:?}"
        )));
    }
    let isetcam = match parameters {
        "camsim" => false,
        "isetcam" => true,
        p => {
            return Err(err_msg(format!(
                "parameters: expected \"camsim\" or \"isetcam\", got \"{p}\""
            )))
        }
    };
    let mut opts = if isetcam {
        camsim_metrics::ScielabOptions::isetcam(samples_per_degree)
    } else {
        camsim_metrics::ScielabOptions::new(samples_per_degree)
    };
    opts.formula = match formula {
        _ if isetcam => camsim_metrics::DeltaEFormula::Ciede2000,
        "cie76" => camsim_metrics::DeltaEFormula::Cie76,
        "ciede2000" => camsim_metrics::DeltaEFormula::Ciede2000,
        f => {
            return Err(err_msg(format!(
                "formula: expected \"cie76\" or \"ciede2000\", got \"{f}\""
            )))
        }
    };
    let a: Vec<Xyz> = a.into_iter().map(xyz).collect();
    let b: Vec<Xyz> = b.into_iter().map(xyz).collect();
    let r = py
        .detach(|| {
            camsim_metrics::scielab_with_options(&a, &b, sa[0], sa[1], xyz(white_xyz), &opts)
        })
        .map_err(err_msg)?;
    Ok((arr(py, r.delta_e_map, &[r.rows, r.cols])?, r.mean_delta_e))
}

/// ISO 12233 e-SFR of the edge in `roi` = (row0, row1, col0, col1) (end-exclusive) of a
/// (rows, cols) image: {frequencies_cycles_per_pixel, mtf, mtf50_cycles_per_pixel, angle_deg,
/// edge_offset_px, orientation, lines_used}.
#[pyfunction]
#[pyo3(signature = (image, roi=None))]
fn slanted_edge_mtf<'py>(
    py: Python<'py>,
    image: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    roi: Option<(usize, usize, usize, usize)>,
) -> PyResult<Bound<'py, PyDict>> {
    let (v, shape) = f64_values(&image);
    if shape.len() != 2 {
        return Err(err_msg(format!(
            "image: expected shape (rows, cols), got {shape:?}"
        )));
    }
    let (rows, cols) = (shape[0], shape[1]);
    let (row0, row1, col0, col1) = roi.unwrap_or((0, rows, 0, cols));
    if !(row0 < row1 && row1 <= rows && col0 < col1 && col1 <= cols) {
        return Err(err_msg(format!(
            "roi: ({row0}, {row1}, {col0}, {col1}) is not a region of the {rows}×{cols} image"
        )));
    }
    let img: Vec<f32> = v.iter().map(|&x| x as f32).collect();
    let rect = camsim_core::stats::Rect {
        row0,
        row1,
        col0,
        col1,
    };
    let e = camsim_metrics::slanted_edge_mtf(&img, rows, cols, rect).map_err(err_msg)?;
    let d = PyDict::new(py);
    let n = e.mtf.len();
    d.set_item(
        "frequencies_cycles_per_pixel",
        arr(py, e.frequencies_cycles_per_pixel, &[n])?,
    )?;
    d.set_item("mtf", arr(py, e.mtf, &[n])?)?;
    d.set_item("mtf50_cycles_per_pixel", e.mtf50_cycles_per_pixel)?;
    d.set_item("angle_deg", e.angle_deg)?;
    d.set_item("edge_offset_px", e.edge_offset_px)?;
    d.set_item("orientation", format!("{:?}", e.orientation).to_lowercase())?;
    d.set_item("lines_used", e.lines_used)?;
    Ok(d)
}

/// PSNR (dB) between two images of one shape for the peak value `peak`.
#[pyfunction]
fn psnr_db(
    a: PyArrayLikeDyn<'_, f64, AllowTypeChange>,
    b: PyArrayLikeDyn<'_, f64, AllowTypeChange>,
    peak: f64,
) -> PyResult<f64> {
    let (va, sa) = f64_values(&a);
    let (vb, sb) = f64_values(&b);
    if sa != sb {
        return Err(err_msg(format!(
            "a and b differ in shape: {sa:?} vs {sb:?}"
        )));
    }
    let fa: Vec<f32> = va.iter().map(|&x| x as f32).collect();
    let fb: Vec<f32> = vb.iter().map(|&x| x as f32).collect();
    camsim_metrics::psnr_db(&fa, &fb, peak).map_err(err_msg)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(energy_to_photons, m)?)?;
    m.add_function(wrap_pyfunction!(illuminant, m)?)?;
    m.add_function(wrap_pyfunction!(blackbody, m)?)?;
    m.add_function(wrap_pyfunction!(xyz_from_energy, m)?)?;
    m.add_function(wrap_pyfunction!(xyz_to_lab, m)?)?;
    m.add_function(wrap_pyfunction!(delta_e_76, m)?)?;
    m.add_function(wrap_pyfunction!(delta_e_94, m)?)?;
    m.add_function(wrap_pyfunction!(delta_e_2000, m)?)?;
    m.add_function(wrap_pyfunction!(scielab, m)?)?;
    m.add_function(wrap_pyfunction!(slanted_edge_mtf, m)?)?;
    m.add_function(wrap_pyfunction!(psnr_db, m)?)?;
    Ok(())
}
