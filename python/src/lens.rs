//! Lenses: prescriptions from .json / .zmx / .dat, first-order data, spots, distortion,
//! wave-optics PSF and MTF, the `lens report` numbers and the field model.
use crate::{arr, err, err_msg, json_text, json_to_py, vec1};
use camsim_lens::analysis::pupil_grid;
use camsim_lens::{
    Clipping, FieldModel, FieldModelOptions, GlassCatalog, LensPrescription, PsfKind,
};
use camsim_pipeline::error::CliError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

fn clipping(clip: bool) -> Clipping {
    if clip {
        Clipping::SemiDiameters
    } else {
        Clipping::None
    }
}

/// A sequential lens prescription (units: mm, nm, degrees of object-space field).
#[pyclass(module = "camsim._camsim", frozen)]
pub struct Lens {
    lens: LensPrescription,
    path: PathBuf,
}

impl Lens {
    fn lerr(&self, e: camsim_lens::LensError) -> PyErr {
        err(CliError::input(&self.path, e))
    }
    fn wl(&self, wavelength_nm: Option<f64>) -> f64 {
        wavelength_nm.unwrap_or(self.lens.primary_nm)
    }
}

#[pymethods]
impl Lens {
    /// Read a lens: project .json, Zemax .zmx, ISET/pbrt .dat or ISETCam lens .json (as
    /// `camsim lens`).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let lens = camsim_pipeline::lens_cmd::load_lens(&path).map_err(err)?;
        Ok(Lens { lens, path })
    }

    /// A lens from a project-JSON dict (or its text); glasses from the bundled catalogues.
    #[staticmethod]
    #[pyo3(signature = (text, path=None))]
    fn from_json(text: &Bound<'_, PyAny>, path: Option<PathBuf>) -> PyResult<Self> {
        let path = path.unwrap_or_else(|| PathBuf::from("<python>"));
        let lens = LensPrescription::from_json_str(&json_text(text)?, &GlassCatalog::bundled())
            .map_err(|e| err(CliError::input(&path, e)))?;
        Ok(Lens { lens, path })
    }

    /// Lens name.
    #[getter]
    fn name(&self) -> String {
        self.lens.name.clone()
    }
    /// Design wavelengths (nm).
    #[getter]
    fn wavelengths_nm(&self) -> Vec<f64> {
        self.lens.wavelengths_nm.clone()
    }
    /// Primary wavelength (nm).
    #[getter]
    fn primary_nm(&self) -> f64 {
        self.lens.primary_nm
    }
    /// Number of surfaces.
    #[getter]
    fn surfaces(&self) -> usize {
        self.lens.surfaces.len()
    }

    /// The lens with its image plane at the paraxial focus of `wavelength_nm` (default: the
    /// primary wavelength).
    #[pyo3(signature = (wavelength_nm=None))]
    fn focused(&self, wavelength_nm: Option<f64>) -> PyResult<Lens> {
        let lens = self
            .lens
            .focused(self.wl(wavelength_nm))
            .map_err(|e| self.lerr(e))?;
        Ok(Lens {
            lens,
            path: self.path.clone(),
        })
    }

    /// The lens with the last thickness (last surface → image plane) set to
    /// `image_distance_mm`.
    fn with_image_distance(&self, image_distance_mm: f64) -> PyResult<Lens> {
        if !image_distance_mm.is_finite() {
            return Err(err_msg(format!(
                "image_distance_mm: must be finite, got {image_distance_mm}"
            )));
        }
        Ok(Lens {
            lens: self.lens.with_image_distance(image_distance_mm),
            path: self.path.clone(),
        })
    }

    /// Paraxial first-order data at `wavelength_nm` (mm; z from the first vertex).
    #[pyo3(signature = (wavelength_nm=None))]
    fn first_order<'py>(
        &self,
        py: Python<'py>,
        wavelength_nm: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let f = self
            .lens
            .first_order(self.wl(wavelength_nm))
            .map_err(|e| self.lerr(e))?;
        let d = PyDict::new(py);
        for (k, v) in [
            ("wavelength_nm", f.wavelength_nm),
            ("efl_mm", f.efl_mm),
            ("bfl_mm", f.bfl_mm),
            ("ffl_mm", f.ffl_mm),
            ("rear_focal_z_mm", f.rear_focal_z_mm),
            ("front_focal_z_mm", f.front_focal_z_mm),
            ("front_principal_z_mm", f.front_principal_z_mm),
            ("rear_principal_z_mm", f.rear_principal_z_mm),
            ("entrance_pupil_z_mm", f.entrance_pupil_z_mm),
            ("entrance_pupil_diameter_mm", f.entrance_pupil_diameter_mm),
            ("exit_pupil_z_mm", f.exit_pupil_z_mm),
            ("exit_pupil_from_image_mm", f.exit_pupil_from_image_mm),
            ("exit_pupil_diameter_mm", f.exit_pupil_diameter_mm),
            ("stop_semi_diameter_mm", f.stop_semi_diameter_mm),
            ("f_number", f.f_number),
            ("working_f_number", f.working_f_number),
            ("paraxial_image_distance_mm", f.paraxial_image_distance_mm),
            ("magnification", f.magnification),
        ] {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Vertex positions (mm from the first surface) of every surface.
    fn vertex_z_mm(&self) -> Vec<f64> {
        self.lens.vertex_z_mm()
    }

    /// Spot diagram of `field_deg` at `wavelength_nm` on a `grid`² pupil grid (clipped to the
    /// unit disc; chief ray aimed at the primary wavelength), `defocus_mm` from the lens's
    /// image plane. Returns {points_mm (N, 2), centroid_mm, rms_radius_um, n_launched}.
    #[pyo3(signature = (field_deg=0.0, wavelength_nm=None, grid=33, defocus_mm=0.0, clip=false))]
    fn spot<'py>(
        &self,
        py: Python<'py>,
        field_deg: f64,
        wavelength_nm: Option<f64>,
        grid: usize,
        defocus_mm: f64,
        clip: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let s = py
            .detach(|| {
                self.lens.spot_diagram(
                    field_deg,
                    self.wl(wavelength_nm),
                    grid.max(1),
                    defocus_mm,
                    clipping(clip),
                )
            })
            .map_err(|e| self.lerr(e))?;
        let d = PyDict::new(py);
        let n = s.points_mm.len();
        let pts: Vec<f64> = s.points_mm.iter().flat_map(|p| [p[0], p[1]]).collect();
        d.set_item("points_mm", arr(py, pts, &[n, 2])?)?;
        d.set_item("centroid_mm", (s.centroid_mm[0], s.centroid_mm[1]))?;
        d.set_item("rms_radius_um", 1e3 * s.rms_radius_mm)?;
        d.set_item("n_launched", s.n_launched)?;
        Ok(d)
    }

    /// RMS spot radius (µm) of all design wavelengths pooled at `field_deg`, `defocus_mm` from
    /// the image plane (no clipping, chief ray aimed at the primary wavelength).
    #[pyo3(signature = (field_deg=0.0, defocus_mm=0.0, grid=33))]
    fn polychromatic_rms_um(
        &self,
        py: Python<'_>,
        field_deg: f64,
        defocus_mm: f64,
        grid: usize,
    ) -> PyResult<f64> {
        let fans = py.detach(|| self.fans(field_deg, grid))?;
        Ok(1e3 * self.lens.polychromatic_rms_mm(&fans, defocus_mm))
    }

    /// Image-plane shift (mm) minimising the polychromatic RMS spot at `field_deg`, searched in
    /// ± `span_mm` (default 2 % of the EFL).
    #[pyo3(signature = (field_deg=0.0, grid=33, span_mm=None))]
    fn best_focus_shift_mm(
        &self,
        py: Python<'_>,
        field_deg: f64,
        grid: usize,
        span_mm: Option<f64>,
    ) -> PyResult<f64> {
        let span = match span_mm {
            Some(s) => s,
            None => {
                0.02 * self
                    .lens
                    .first_order(self.lens.primary_nm)
                    .map_err(|e| self.lerr(e))?
                    .efl_mm
            }
        };
        let fans = py.detach(|| self.fans(field_deg, grid))?;
        Ok(py.detach(|| self.lens.best_focus_shift_mm(&fans, span)))
    }

    /// Distortion and lateral colour at `field_deg`: {paraxial_height_mm, real_height_mm,
    /// distortion_pct, chief_height_by_wavelength_mm, lateral_colour_um}.
    fn distortion<'py>(&self, py: Python<'py>, field_deg: f64) -> PyResult<Bound<'py, PyDict>> {
        let p = self.lens.distortion(field_deg).map_err(|e| self.lerr(e))?;
        let d = PyDict::new(py);
        d.set_item("field_deg", p.field_deg)?;
        d.set_item("paraxial_height_mm", p.paraxial_height_mm)?;
        d.set_item("real_height_mm", p.real_height_mm)?;
        d.set_item("distortion_pct", p.distortion_pct)?;
        d.set_item(
            "chief_height_by_wavelength_mm",
            p.chief_height_by_wavelength_mm,
        )?;
        d.set_item("lateral_colour_um", p.lateral_colour_um)?;
        Ok(d)
    }

    /// Wave-optics PSF (sum 1, float64 (m, m), m = n·pad, centred at (m/2, m/2)) of `field_deg`
    /// at `wavelength_nm` from the OPD on an n² pupil grid; returns (psf, sample pitch µm).
    #[pyo3(signature = (field_deg=0.0, wavelength_nm=None, n=64, pad=4))]
    fn psf<'py>(
        &self,
        py: Python<'py>,
        field_deg: f64,
        wavelength_nm: Option<f64>,
        n: usize,
        pad: usize,
    ) -> PyResult<(Bound<'py, PyAny>, f64)> {
        if n < 2 {
            return Err(err_msg(format!("n: must be ≥ 2, got {n}")));
        }
        let w = py
            .detach(|| {
                self.lens
                    .wave_optics(field_deg, self.wl(wavelength_nm), n, pad, &[])
            })
            .map_err(|e| self.lerr(e))?;
        let m = w.psf.n;
        Ok((arr(py, w.psf.values, &[m, m])?, w.psf.sample_mm * 1e3))
    }

    /// Wave-optics MTF of `field_deg` at `wavelength_nm` at `freq_cyc_per_mm`: {freq_cyc_per_mm,
    /// tangential, sagittal, opd_rms_waves, opd_pv_waves}.
    #[pyo3(signature = (freq_cyc_per_mm, field_deg=0.0, wavelength_nm=None, n=64, pad=4))]
    fn mtf<'py>(
        &self,
        py: Python<'py>,
        freq_cyc_per_mm: Vec<f64>,
        field_deg: f64,
        wavelength_nm: Option<f64>,
        n: usize,
        pad: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        if n < 2 {
            return Err(err_msg(format!("n: must be ≥ 2, got {n}")));
        }
        let w = py
            .detach(|| {
                self.lens
                    .wave_optics(field_deg, self.wl(wavelength_nm), n, pad, &freq_cyc_per_mm)
            })
            .map_err(|e| self.lerr(e))?;
        let d = PyDict::new(py);
        d.set_item("freq_cyc_per_mm", vec1(py, freq_cyc_per_mm))?;
        d.set_item(
            "tangential",
            vec1(py, w.mtf.iter().map(|p| p.tangential).collect()),
        )?;
        d.set_item(
            "sagittal",
            vec1(py, w.mtf.iter().map(|p| p.sagittal).collect()),
        )?;
        d.set_item("opd_rms_waves", w.opd.rms_waves)?;
        d.set_item("opd_pv_waves", w.opd.pv_waves)?;
        Ok(d)
    }

    /// The numbers of `camsim lens report` (report.json's content) without writing files.
    #[pyo3(signature = (field_fractions=vec![0.0, 0.5, 0.7, 1.0], wavelengths_nm=None, max_field_deg=None, grid=33, mtf_lp_mm=None, mtf_focus="best", clip=false))]
    #[allow(clippy::too_many_arguments)]
    fn report<'py>(
        &self,
        py: Python<'py>,
        field_fractions: Vec<f64>,
        wavelengths_nm: Option<Vec<f64>>,
        max_field_deg: Option<f64>,
        grid: usize,
        mtf_lp_mm: Option<Vec<f64>>,
        mtf_focus: &str,
        clip: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        use camsim_pipeline::lens_cmd::{lens_report, MtfFocus, ReportOptions};
        let mtf_focus = match mtf_focus {
            "best" => MtfFocus::Best,
            "paraxial" => MtfFocus::Paraxial,
            f => {
                return Err(err_msg(format!(
                    "mtf_focus: expected \"best\" or \"paraxial\", got \"{f}\""
                )))
            }
        };
        let opts = ReportOptions {
            field_fractions,
            wavelengths: wavelengths_nm
                .map(|w| w.iter().map(|x| format!("{x}")).collect())
                .unwrap_or_else(|| vec!["486.1".into(), "587.6".into(), "656.3".into()]),
            max_field_deg,
            grid,
            mtf_lp_mm: mtf_lp_mm.unwrap_or_else(|| {
                vec![
                    0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 120.0, 140.0,
                    160.0, 180.0, 200.0,
                ]
            }),
            mtf_focus,
            clip,
        };
        let r = py
            .detach(|| lens_report(&self.lens, &self.path, &opts))
            .map_err(err)?;
        json_to_py(py, &r.json)
    }

    /// The field model (PSFs, distortion and relative illumination tabulated over image
    /// height × wavelength), as `camsim lens field-model`.
    #[pyo3(signature = (n_fields=5, max_field_deg=None, wavelengths_nm=None, kind="wave", psf_n=33, psf_pitch_um=1.0, pupil_n=64, pad=4))]
    #[allow(clippy::too_many_arguments)]
    fn field_model(
        &self,
        py: Python<'_>,
        n_fields: usize,
        max_field_deg: Option<f64>,
        wavelengths_nm: Option<Vec<f64>>,
        kind: &str,
        psf_n: usize,
        psf_pitch_um: f64,
        pupil_n: usize,
        pad: usize,
    ) -> PyResult<LensFieldModel> {
        let kind = match kind {
            "wave" => PsfKind::Wave,
            "geometric" => PsfKind::Geometric,
            k => {
                return Err(err_msg(format!(
                    "kind: expected \"wave\" or \"geometric\", got \"{k}\""
                )))
            }
        };
        let opts = FieldModelOptions {
            n_fields,
            max_field_deg,
            wavelengths_nm,
            kind,
            psf_n,
            psf_pitch_um,
            pupil_n,
            pad,
            ..FieldModelOptions::default()
        };
        let fm = py
            .detach(|| FieldModel::compute(&self.lens, &opts))
            .map_err(|e| self.lerr(e))?;
        Ok(LensFieldModel::new(fm))
    }

    fn __repr__(&self) -> String {
        format!(
            "Lens({:?}, {} surfaces, primary {} nm)",
            self.lens.name,
            self.lens.surfaces.len(),
            self.lens.primary_nm
        )
    }
}

impl Lens {
    /// Ray fans of every design wavelength at `field_deg` (no clipping, aimed at the primary).
    fn fans(&self, field_deg: f64, grid: usize) -> PyResult<Vec<camsim_lens::analysis::RayFan>> {
        let g = pupil_grid(grid.max(1));
        self.lens
            .wavelengths_nm
            .iter()
            .map(|&w| {
                self.lens
                    .ray_fan(field_deg, w, self.lens.primary_nm, &g, Clipping::None)
                    .map_err(|e| self.lerr(e))
            })
            .collect()
    }
}

/// A lens field model: PSFs (sum 1, `psf_n`², pitch `psf_pitch_um`), real image heights and
/// relative illumination tabulated over paraxial image height (mm) and wavelength (nm).
#[pyclass(module = "camsim._camsim", frozen)]
pub struct LensFieldModel {
    fm: FieldModel,
    /// The tables at the focus distance.
    table: camsim_lens::FieldTable,
}

impl LensFieldModel {
    fn new(fm: FieldModel) -> Self {
        let table = fm.at_distance(fm.focus_distance_mm);
        LensFieldModel { fm, table }
    }
}

#[pymethods]
impl LensFieldModel {
    /// Read a saved field model (`camsim lens field-model` output).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let fm = FieldModel::load(&path).map_err(|e| err(CliError::input(&path, e)))?;
        Ok(LensFieldModel::new(fm))
    }
    /// Save it (the file `camsim run` and `lens field-model` use).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.fm
            .save(&path)
            .map_err(|e| err(CliError::output(&path, e)))
    }
    /// Tabulated wavelengths (nm).
    #[getter]
    fn wavelengths_nm(&self) -> Vec<f64> {
        self.fm.wavelengths_nm.clone()
    }
    /// Tabulated paraxial image heights (mm).
    #[getter]
    fn paraxial_height_mm(&self) -> Vec<f64> {
        self.fm.paraxial_height_mm.clone()
    }
    /// PSF samples per side.
    #[getter]
    fn psf_n(&self) -> usize {
        self.fm.psf_n
    }
    /// PSF sample pitch (µm).
    #[getter]
    fn psf_pitch_um(&self) -> f64 {
        self.fm.psf_pitch_um
    }
    /// EFL (mm).
    #[getter]
    fn efl_mm(&self) -> f64 {
        self.fm.efl_mm
    }
    /// F-number.
    #[getter]
    fn f_number(&self) -> f64 {
        self.fm.f_number
    }
    /// Interpolated PSF (float64 (psf_n, psf_n), sum 1, centred on the chief ray) at image
    /// point (x_mm, y_mm) and `wavelength_nm`, rotated to the point's azimuth.
    fn psf_at<'py>(
        &self,
        py: Python<'py>,
        x_mm: f64,
        y_mm: f64,
        wavelength_nm: f64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = self.table.psf_n;
        arr(py, self.table.psf_at(x_mm, y_mm, wavelength_nm), &[n, n])
    }
    /// Real chief-ray image height (mm) at paraxial height `height_mm` and `wavelength_nm`.
    fn real_height_mm_at(&self, height_mm: f64, wavelength_nm: f64) -> f64 {
        self.table.real_height_mm_at(height_mm, wavelength_nm)
    }
    /// Relative illumination (1 on axis) at paraxial height `height_mm` and `wavelength_nm`.
    fn relative_illumination_at(&self, height_mm: f64, wavelength_nm: f64) -> f64 {
        self.table
            .relative_illumination_at(height_mm, wavelength_nm)
    }
}

/// Run any `camsim lens …` subcommand in-process (e.g. `["psf", "lens.json", "--out",
/// "DIR"]`); files are written as by the CLI.
#[pyfunction]
fn lens_command(py: Python<'_>, args: Vec<String>) -> PyResult<()> {
    use clap::{FromArgMatches, Subcommand};
    let cmd = camsim_pipeline::lens_cmd::LensCommand::augment_subcommands(
        clap::Command::new("lens").subcommand_required(true),
    );
    let mut argv = vec!["lens".to_string()];
    argv.extend(args);
    let m = cmd
        .try_get_matches_from(argv)
        .map_err(|e| err_msg(e.to_string().trim().replace('\n', " ")))?;
    let c = camsim_pipeline::lens_cmd::LensCommand::from_arg_matches(&m)
        .map_err(|e| err_msg(e.to_string().trim().replace('\n', " ")))?;
    py.detach(|| camsim_pipeline::lens_cmd::run_lens(c))
        .map_err(err)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Lens>()?;
    m.add_class::<LensFieldModel>()?;
    m.add_function(wrap_pyfunction!(lens_command, m)?)?;
    Ok(())
}
