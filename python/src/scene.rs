//! Scenes and optical images as NumPy arrays with their wavelengths: spectral radiance and
//! irradiance cubes (rows, cols, bands), spectral EXR in and out, glTF rendering, and the
//! closed-form optics (diffraction OTF, Airy disk, wavefront PSF).
use crate::{arr, err, err_msg, f64_values, json_to_py, vec1};
use camsim_core::constants::{ISETCAM, SI};
use camsim_core::exr_io::{
    bands_energy_to_photons, read_spectral_exr, write_spectral_exr, IRRADIANCE_UNITS,
    RADIANCE_UNITS,
};
use camsim_core::image::{Plane, SceneRadiance, SensorIrradiance, SpectralBasis, SpectralImage};
use camsim_core::spectrum::WavelengthGrid;
use camsim_pipeline::error::CliError;
use numpy::{AllowTypeChange, PyArrayLikeDyn};
use pyo3::prelude::*;
use std::path::PathBuf;

/// A band cube (rows, cols, bands) as float32 on `grid` (a linear-model image is evaluated on
/// the grid's bands first).
fn cube<'py>(
    py: Python<'py>,
    img: &SpectralImage,
    grid: &WavelengthGrid,
) -> PyResult<Bound<'py, PyAny>> {
    let banded;
    let img = if matches!(&img.basis, SpectralBasis::Bands(g) if g == grid) {
        img
    } else {
        banded = img.to_bands(grid);
        &banded
    };
    let (r, c, b) = (img.rows, img.cols, img.planes.len());
    let mut v = vec![0f32; r * c * b];
    for (k, p) in img.planes.iter().enumerate() {
        for (i, x) in p.iter().enumerate() {
            v[i * b + k] = *x;
        }
    }
    arr(py, v, &[r, c, b])
}

/// A band image from a (rows, cols, bands) array and its wavelengths.
fn image_from_array(
    values: &PyArrayLikeDyn<'_, f64, AllowTypeChange>,
    wavelength_nm: Vec<f64>,
) -> PyResult<(SpectralImage, WavelengthGrid)> {
    let (v, shape) = f64_values(values);
    if shape.len() != 3 {
        return Err(err_msg(format!(
            "radiance: expected an array of shape (rows, cols, bands), got shape {shape:?}"
        )));
    }
    let (r, c, b) = (shape[0], shape[1], shape[2]);
    if b != wavelength_nm.len() {
        return Err(err_msg(format!(
            "wavelength_nm: {} wavelengths for {b} bands",
            wavelength_nm.len()
        )));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(err_msg(format!("radiance: non-finite value {x}")));
    }
    let grid =
        WavelengthGrid::new(wavelength_nm).map_err(|e| err_msg(format!("wavelength_nm: {e}")))?;
    let mut planes = vec![vec![0f32; r * c]; b];
    for i in 0..r * c {
        for (k, p) in planes.iter_mut().enumerate() {
            p[i] = v[i * b + k] as f32;
        }
    }
    let img = SpectralImage::new(r, c, SpectralBasis::Bands(grid.clone()), planes)
        .map_err(|e| err_msg(format!("radiance: {e}")))?;
    Ok((img, grid))
}

fn unit_is_photons(unit: &str) -> PyResult<bool> {
    match unit {
        "photons" => Ok(true),
        "W" | "watts" => Ok(false),
        u => Err(err_msg(format!(
            "unit: expected \"photons\" or \"W\", got \"{u}\""
        ))),
    }
}

/// Scene spectral radiance: photons/(s·sr·m²·nm) on a wavelength grid, sampled at
/// `sample_pitch_m` in the image plane (the scene as the optics see it).
#[pyclass(module = "camsim._camsim", frozen)]
pub struct Scene {
    pub(crate) scene: SceneRadiance,
    pub(crate) grid: WavelengthGrid,
}

impl Scene {
    /// A scene kept in its own spectral representation (a linear model stays one, so the
    /// optics and sensor see exactly what the CLI's do); `grid` is the wavelength grid of
    /// wavelength-dependent optics and of the band view `radiance`.
    pub(crate) fn from_radiance(scene: SceneRadiance, grid: WavelengthGrid) -> Self {
        Scene { scene, grid }
    }
}

#[pymethods]
impl Scene {
    /// A scene from a (rows, cols, bands) radiance array with its wavelengths (nm), sample
    /// pitch (m) and unit ("photons": photons/(s·sr·m²·nm); "W": W/(sr·m²·nm)); optional
    /// depth (m, (rows, cols)) and object distance (m; None = at infinity).
    #[staticmethod]
    #[pyo3(signature = (radiance, wavelength_nm, sample_pitch_m, unit="photons", depth_m=None, object_distance_m=None))]
    fn from_array(
        radiance: PyArrayLikeDyn<'_, f64, AllowTypeChange>,
        wavelength_nm: Vec<f64>,
        sample_pitch_m: f64,
        unit: &str,
        depth_m: Option<PyArrayLikeDyn<'_, f64, AllowTypeChange>>,
        object_distance_m: Option<f64>,
    ) -> PyResult<Self> {
        let photons = unit_is_photons(unit)?;
        if !(sample_pitch_m.is_finite() && sample_pitch_m > 0.0) {
            return Err(err_msg(format!(
                "sample_pitch_m: must be a positive number, got {sample_pitch_m}"
            )));
        }
        let (mut img, grid) = image_from_array(&radiance, wavelength_nm)?;
        if !photons {
            bands_energy_to_photons(&mut img, &SI, false);
        }
        let depth = match depth_m {
            None => None,
            Some(d) => {
                let (v, shape) = f64_values(&d);
                if shape != [img.rows, img.cols] {
                    return Err(err_msg(format!(
                        "depth_m: expected shape ({}, {}), got {shape:?}",
                        img.rows, img.cols
                    )));
                }
                Some(Plane {
                    rows: img.rows,
                    cols: img.cols,
                    data: v.into_iter().map(|x| x as f32).collect(),
                })
            }
        };
        Ok(Scene {
            scene: SceneRadiance {
                radiance: img,
                sample_pitch_m,
                object_distance_m,
                illuminant: None,
                depth_m: depth,
                sample_aperture: Default::default(),
            },
            grid,
        })
    }

    /// Read a spectral OpenEXR (Fichet 2021 layout; a `Z` channel becomes the depth).
    /// Values in W units (the default `emissiveUnits`) are converted to photons.
    #[staticmethod]
    #[pyo3(signature = (path, sample_pitch_m=1e-6))]
    fn read_exr(path: PathBuf, sample_pitch_m: f64) -> PyResult<Self> {
        let exr = read_spectral_exr(&path).map_err(|e| err(CliError::input(&path, e)))?;
        let mut img = exr.image;
        if !exr.emissive_units.to_lowercase().contains("photon") {
            bands_energy_to_photons(&mut img, &SI, false);
        }
        Ok(Scene {
            scene: SceneRadiance {
                radiance: img,
                sample_pitch_m,
                object_distance_m: None,
                illuminant: None,
                depth_m: exr.depth_m,
                sample_aperture: Default::default(),
            },
            grid: exr.grid,
        })
    }

    /// Write the radiance as a spectral OpenEXR in W/(sr·m²·nm) (as `camsim scene` does).
    fn write_exr(&self, path: PathBuf) -> PyResult<()> {
        let mut w = self.scene.radiance.to_bands(&self.grid);
        bands_energy_to_photons(&mut w, &SI, true);
        write_spectral_exr(&path, &w, RADIANCE_UNITS, self.scene.depth_m.as_ref())
            .map_err(|e| err(CliError::output(&path, e)))
    }

    /// Radiance, photons/(s·sr·m²·nm), float32 (rows, cols, bands).
    #[getter]
    fn radiance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        cube(py, &self.scene.radiance, &self.grid)
    }
    /// Wavelengths of the bands (nm).
    #[getter]
    fn wavelength_nm<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        vec1(py, self.grid.wavelength_nm.clone()).into_any()
    }
    /// Sample pitch in the image plane (m).
    #[getter]
    fn sample_pitch_m(&self) -> f64 {
        self.scene.sample_pitch_m
    }
    /// (rows, cols, bands).
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        (
            self.scene.radiance.rows,
            self.scene.radiance.cols,
            self.grid.len(),
        )
    }
    /// Depth along the viewing axis (m, float32 (rows, cols)), when known.
    #[getter]
    fn depth_m<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.scene
            .depth_m
            .as_ref()
            .map(|p| arr(py, p.data.clone(), &[p.rows, p.cols]))
            .transpose()
    }
    /// The illuminant (photons/(s·sr·m²·nm) per unit reflectance, sampled on the bands), when
    /// the scene is reflectance × illuminant.
    #[getter]
    fn illuminant<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.scene
            .illuminant
            .as_ref()
            .map(|s| vec1(py, s.sample(&self.grid)).into_any())
    }
    /// Mean luminance (cd/m²) over the whole image (exact integrals, SI constants).
    fn mean_luminance_cd_m2(&self) -> f64 {
        camsim_core::scene::mean_luminance(&self.scene, None, &SI)
    }
    /// Mean luminance (cd/m²) by Riemann sums on the band grid with ISETCam's constants
    /// (ISETCam `sceneGet(scene,'mean luminance')`).
    fn mean_luminance_isetcam_cd_m2(&self) -> f64 {
        camsim_core::scene::mean_luminance_riemann(&self.scene, &self.grid, &ISETCAM)
    }
    /// A copy scaled so that the ISETCam-convention mean luminance is `cd_m2`.
    fn scaled_to_isetcam_luminance(&self, cd_m2: f64) -> PyResult<Scene> {
        let l = self.mean_luminance_isetcam_cd_m2();
        if !(l > 0.0) {
            return Err(err_msg("scene: zero mean luminance cannot be scaled"));
        }
        let mut s = self.scene.clone();
        s.scale(cd_m2 / l);
        Ok(Scene {
            scene: s,
            grid: self.grid.clone(),
        })
    }
    fn __repr__(&self) -> String {
        let (r, c, b) = self.shape();
        format!(
            "Scene({r}x{c}, {b} bands {:.0}–{:.0} nm, pitch {:.3} µm)",
            self.grid.wavelength_nm[0],
            self.grid.wavelength_nm[b - 1],
            self.scene.sample_pitch_m * 1e6
        )
    }
}

/// Sensor irradiance: photons/(s·m²·nm) on a wavelength grid, sampled at `sample_pitch_m`.
#[pyclass(module = "camsim._camsim", frozen)]
pub struct Irradiance {
    pub(crate) irr: SensorIrradiance,
    pub(crate) grid: WavelengthGrid,
}

impl Irradiance {
    /// An irradiance kept in its own spectral representation; `grid` is that of its band view.
    pub(crate) fn new(irr: SensorIrradiance, grid: WavelengthGrid) -> Self {
        Irradiance { irr, grid }
    }
}

#[pymethods]
impl Irradiance {
    /// An irradiance from a (rows, cols, bands) array (photons/(s·m²·nm) or W/(m²·nm)).
    #[staticmethod]
    #[pyo3(signature = (irradiance, wavelength_nm, sample_pitch_m, unit="photons"))]
    fn from_array(
        irradiance: PyArrayLikeDyn<'_, f64, AllowTypeChange>,
        wavelength_nm: Vec<f64>,
        sample_pitch_m: f64,
        unit: &str,
    ) -> PyResult<Self> {
        let photons = unit_is_photons(unit)?;
        if !(sample_pitch_m.is_finite() && sample_pitch_m > 0.0) {
            return Err(err_msg(format!(
                "sample_pitch_m: must be a positive number, got {sample_pitch_m}"
            )));
        }
        let (mut img, grid) = image_from_array(&irradiance, wavelength_nm)?;
        if !photons {
            bands_energy_to_photons(&mut img, &SI, false);
        }
        Ok(Irradiance {
            irr: SensorIrradiance {
                irradiance: img,
                sample_pitch_m,
            },
            grid,
        })
    }
    /// Irradiance, photons/(s·m²·nm), float32 (rows, cols, bands).
    #[getter]
    fn irradiance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        cube(py, &self.irr.irradiance, &self.grid)
    }
    /// Wavelengths of the bands (nm).
    #[getter]
    fn wavelength_nm<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        vec1(py, self.grid.wavelength_nm.clone()).into_any()
    }
    /// Sample pitch on the sensor (m).
    #[getter]
    fn sample_pitch_m(&self) -> f64 {
        self.irr.sample_pitch_m
    }
    /// (rows, cols, bands).
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        (
            self.irr.irradiance.rows,
            self.irr.irradiance.cols,
            self.grid.len(),
        )
    }
    /// Write as a spectral OpenEXR in W/(m²·nm).
    fn write_exr(&self, path: PathBuf) -> PyResult<()> {
        let mut w = self.irr.irradiance.to_bands(&self.grid);
        bands_energy_to_photons(&mut w, &SI, true);
        write_spectral_exr(&path, &w, IRRADIANCE_UNITS, None)
            .map_err(|e| err(CliError::output(&path, e)))
    }
    fn __repr__(&self) -> String {
        let (r, c, b) = self.shape();
        format!(
            "Irradiance({r}x{c}, {b} bands, pitch {:.3} µm)",
            self.irr.sample_pitch_m * 1e6
        )
    }
}

/// `camsim render SCENE.gltf --out OUT.exr ARGS…`: path-trace a glTF scene into a spectral
/// EXR (band radiance + Z depth). `args` are the CLI's options (e.g. `["--width", "64",
/// "--spp", "16"]`). Returns (summary dict, Scene read back from the EXR, with depth).
#[pyfunction]
#[pyo3(signature = (scene, out, args=Vec::new()))]
fn render<'py>(
    py: Python<'py>,
    scene: PathBuf,
    out: PathBuf,
    args: Vec<String>,
) -> PyResult<(Bound<'py, PyAny>, Scene)> {
    use clap::{Args, FromArgMatches};
    let mut argv: Vec<std::ffi::OsString> = vec!["render".into(), scene.into_os_string()];
    argv.push("--out".into());
    argv.push(out.clone().into_os_string());
    argv.extend(args.into_iter().map(Into::into));
    let cmd = camsim_pipeline::render_cmd::RenderArgs::augment_args(clap::Command::new("render"));
    let m = cmd
        .try_get_matches_from(argv)
        .map_err(|e| err_msg(e.to_string().trim().replace('\n', " ")))?;
    let a = camsim_pipeline::render_cmd::RenderArgs::from_arg_matches(&m)
        .map_err(|e| err_msg(e.to_string().trim().replace('\n', " ")))?;
    let v = py
        .detach(|| camsim_pipeline::render_cmd::run_render(&a, false))
        .map_err(err)?;
    let s = Scene::read_exr(out, 1e-6)?;
    Ok((json_to_py(py, &v)?, s))
}

/// Diffraction-limited OTF (= MTF, real and ≥ 0) of a circular pupil at spatial frequencies
/// `freq_cyc_per_mm` (any shape), wavelength (nm) and f-number.
#[pyfunction]
fn diffraction_otf<'py>(
    py: Python<'py>,
    freq_cyc_per_mm: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    wavelength_nm: f64,
    f_number: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let (v, shape) = f64_values(&freq_cyc_per_mm);
    let out: Vec<f64> = v
        .iter()
        .map(|f| camsim_optics::diffraction_otf(f * 1e3, wavelength_nm, f_number))
        .collect();
    arr(py, out, &shape)
}

/// Airy-disk radius to the first zero in the image plane (µm): 1.22 λ N.
#[pyfunction]
fn airy_radius_um(wavelength_nm: f64, f_number: f64) -> f64 {
    camsim_optics::airy_first_zero_m(wavelength_nm, f_number) * 1e6
}

/// Airy-disk angular radius to the first zero (rad): 1.22 λ / D.
#[pyfunction]
fn airy_radius_rad(wavelength_nm: f64, pupil_diameter_m: f64) -> f64 {
    camsim_optics::airy_first_zero_rad(wavelength_nm, pupil_diameter_m)
}

/// PSF of a circular pupil with Zernike defocus (RMS wavefront error `defocus_um`, µm) at
/// `wavelength_nm` and f-number, sampled at `pitch_um` (sum 1). Returns (psf (n, n) float64,
/// pitch µm); zero defocus is the Airy pattern.
#[pyfunction]
#[pyo3(signature = (wavelength_nm, f_number, defocus_um=0.0, pitch_um=0.25, pupil_samples=128))]
fn wavefront_psf<'py>(
    py: Python<'py>,
    wavelength_nm: f64,
    f_number: f64,
    defocus_um: f64,
    pitch_um: f64,
    pupil_samples: usize,
) -> PyResult<(Bound<'py, PyAny>, f64)> {
    let p = py
        .detach(|| {
            camsim_optics::wavefront_psf(
                wavelength_nm,
                f_number,
                defocus_um,
                pupil_samples,
                pitch_um * 1e-6,
            )
        })
        .map_err(err_msg)?;
    let (r, c) = (2 * p.half_rows + 1, 2 * p.half_cols + 1);
    Ok((arr(py, p.data, &[r, c])?, p.pitch_m * 1e6))
}

/// Read a frame file (16-bit PNG as the capture format defines, or TIFF) as uint16 DN
/// (rows, cols).
#[pyfunction]
fn read_frame<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let f = camsim_pipeline::frames::read_png16(&path).map_err(err)?;
    arr(py, f.dn, &[f.rows, f.cols])
}

/// Read every channel of an OpenEXR's first layer: {name: float32 (rows, cols)} (e.g. the
/// `Y` channel of `camsim simulate --expected`, in DN).
#[pyfunction]
fn read_exr_channels<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let (rows, cols, chans, _) =
        camsim_core::exr_io::read_channels(&path).map_err(|e| err(CliError::input(&path, e)))?;
    let d = pyo3::types::PyDict::new(py);
    for (name, v) in chans {
        d.set_item(name, arr(py, v, &[rows, cols])?)?;
    }
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_frame, m)?)?;
    m.add_function(wrap_pyfunction!(read_exr_channels, m)?)?;
    m.add_class::<Scene>()?;
    m.add_class::<Irradiance>()?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(diffraction_otf, m)?)?;
    m.add_function(wrap_pyfunction!(airy_radius_um, m)?)?;
    m.add_function(wrap_pyfunction!(airy_radius_rad, m)?)?;
    m.add_function(wrap_pyfunction!(wavefront_psf, m)?)?;
    Ok(())
}
