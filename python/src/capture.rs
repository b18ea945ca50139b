//! Cameras, capture sets and the commands that run on them: simulate (frames and expected
//! images), calibrate, validate, diagnose, scene, the `run` chain and studies.
use crate::scene::{Irradiance, Scene};
use crate::{arr, err, err_msg, json_text, json_to_py, parse_json, Progress};
use camsim_core::image::{Plane, RawFrame};
use camsim_pipeline::config::{
    camera_file_json, camera_from_file, captures_with_camera, load_captures, read_camera_file,
    CameraFile, CaptureSet as PlCaptureSet, CapturesFile, ShotFile, SimulationFile,
};
use camsim_pipeline::error::CliError;
use camsim_pipeline::simulate::{shot_scene, simulate_each, wavelength_grid, SimOutput};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

/// A validated camera (optics + sensor), read from a camera JSON file or built from a dict.
#[pyclass(module = "camsim._camsim", frozen)]
pub struct Camera {
    pub(crate) cam: camsim_pipeline::config::Camera,
    pub(crate) path: PathBuf,
    file: CameraFile,
}

impl Camera {
    fn from_parts(path: &Path, file: CameraFile) -> Result<Self, CliError> {
        let cam = camera_from_file(path, file.clone())?;
        Ok(Camera {
            cam,
            path: path.to_path_buf(),
            file,
        })
    }

    /// A capture set of one shot of `target` with `frames` frames (the in-memory form of a
    /// captures.json with that one shot), so every path below is the CLI's.
    #[allow(clippy::too_many_arguments)]
    fn one_shot(
        &self,
        target: &str,
        exposure_s: Option<f64>,
        auto_exposure: Option<f64>,
        analog_gain: Option<f64>,
        frames: usize,
        simulation: Option<&str>,
        base_dir: Option<PathBuf>,
    ) -> PyResult<PlCaptureSet> {
        let target = parse_json("target", target)?;
        let simulation: Option<SimulationFile> = match simulation {
            None => None,
            Some(t) => Some(
                serde_json::from_value(parse_json("simulation", t)?)
                    .map_err(|e| err_msg(format!("simulation: {e}")))?,
            ),
        };
        let raw = CapturesFile {
            camera: String::new(),
            shots: vec![ShotFile {
                id: "shot".into(),
                target,
                exposure_s,
                auto_exposure,
                analog_gain,
                frames: (0..frames).map(|i| format!("frame_{i}.png")).collect(),
                light_modulation: None,
                motion: None,
                frame_rate_hz: None,
                temperature_c: None,
            }],
            simulation,
            raw_format: None,
        };
        let dir = base_dir.unwrap_or_else(|| PathBuf::from("."));
        captures_with_camera(
            &dir.join("<python>"),
            raw,
            self.cam.clone(),
            self.path.clone(),
        )
        .map_err(err)
    }

    fn check_irradiance(&self, irr: &Irradiance) -> PyResult<()> {
        if irr.irr.irradiance.rows == 0 || irr.irr.irradiance.cols == 0 {
            return Err(err_msg("irradiance: empty image"));
        }
        Ok(())
    }
}

/// Run the simulation loop of `camsim simulate` on `set` without the GIL and collect its
/// products in order.
fn run_each(
    py: Python<'_>,
    set: &PlCaptureSet,
    seed: u64,
    expected: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Vec<SimOutput>, Vec<(String, f64)>)> {
    let prog = Progress::new(progress);
    let res = py.detach(|| {
        let mut outs = Vec::new();
        let ex = simulate_each(set, seed, expected, &mut |d, t| prog.tick(d, t), &mut |o| {
            outs.push(o);
            Ok(())
        })?;
        Ok::<_, CliError>((outs, ex))
    });
    prog.finish()?;
    res.map_err(err)
}

fn frames_array<'py>(py: Python<'py>, frames: Vec<RawFrame>) -> PyResult<Bound<'py, PyAny>> {
    let (rows, cols) = frames.first().map_or((0, 0), |f| (f.rows, f.cols));
    let n = frames.len();
    if n == 1 {
        // one frame: hand its buffer to NumPy as it is (no copy)
        let f = frames.into_iter().next().expect("one frame");
        return arr(py, f.dn, &[1, rows, cols]);
    }
    let mut data = Vec::with_capacity(n * rows * cols);
    for f in frames {
        data.extend_from_slice(&f.dn);
    }
    arr(py, data, &[n, rows, cols])
}

fn plane_array<'py>(py: Python<'py>, p: Plane) -> PyResult<Bound<'py, PyAny>> {
    let (r, c) = (p.rows, p.cols);
    arr(py, p.data, &[r, c])
}

#[pymethods]
impl Camera {
    /// Read and validate a camera JSON file (docs/config.md).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let file = read_camera_file(&path).map_err(err)?;
        Camera::from_parts(&path, file).map_err(err)
    }

    /// Validate a camera given as a dict (or JSON text) in camera-file form; `path` names it in messages and resolves its
    /// relative file references (default: `<python>` in the current folder).
    #[staticmethod]
    #[pyo3(signature = (text, path=None))]
    fn from_json(text: &Bound<'_, PyAny>, path: Option<PathBuf>) -> PyResult<Self> {
        let path = path.unwrap_or_else(|| PathBuf::from("<python>"));
        let file: CameraFile = serde_json::from_str(&json_text(text)?)
            .map_err(|e| err(CliError::input(&path, format!("invalid: {e}"))))?;
        Camera::from_parts(&path, file).map_err(err)
    }

    /// The camera as camera-file JSON text.
    fn to_json(&self) -> PyResult<String> {
        camera_file_json(&self.file).map_err(err)
    }

    /// Camera name.
    #[getter]
    fn name(&self) -> String {
        self.cam.name.clone()
    }
    /// Where the camera came from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }
    /// Sensor rows.
    #[getter]
    fn rows(&self) -> usize {
        self.cam.sensor.rows
    }
    /// Sensor columns.
    #[getter]
    fn cols(&self) -> usize {
        self.cam.sensor.cols
    }
    /// Pixel pitch (µm).
    #[getter]
    fn pixel_pitch_um(&self) -> f64 {
        self.cam.sensor.pixel_pitch_m * 1e6
    }
    /// ADC bits.
    #[getter]
    fn adc_bits(&self) -> u32 {
        self.cam.sensor.adc_bits
    }
    /// Channel letters in QE order.
    #[getter]
    fn channels(&self) -> Vec<String> {
        self.cam.sensor.channel_names.clone()
    }
    /// f-number.
    #[getter]
    fn f_number(&self) -> f64 {
        self.cam.optics.f_number
    }
    /// Focal length (mm).
    #[getter]
    fn focal_length_mm(&self) -> f64 {
        self.cam.optics.focal_length_m * 1e3
    }

    /// Pixel SNR (dB) and its shot/read/DSNU/PRNU components at mean signals `signal_v` (V,
    /// before analog gain), ISETCam `pixelSNR` convention (dark current excluded).
    fn snr_db<'py>(&self, py: Python<'py>, signal_v: Vec<f64>) -> PyResult<Bound<'py, PyDict>> {
        let c: Vec<_> = signal_v
            .iter()
            .map(|&v| camsim_sensor::isetcam::snr_components_db(&self.cam.sensor, v))
            .collect();
        let d = PyDict::new(py);
        let n = c.len();
        d.set_item(
            "snr_db",
            arr(py, c.iter().map(|x| x.snr_db).collect(), &[n])?,
        )?;
        d.set_item(
            "shot_db",
            arr(py, c.iter().map(|x| x.shot_db).collect(), &[n])?,
        )?;
        d.set_item(
            "read_db",
            arr(py, c.iter().map(|x| x.read_db).collect(), &[n])?,
        )?;
        d.set_item(
            "dsnu_db",
            arr(py, c.iter().map(|x| x.dsnu_db).collect(), &[n])?,
        )?;
        d.set_item(
            "prnu_db",
            arr(py, c.iter().map(|x| x.prnu_db).collect(), &[n])?,
        )?;
        Ok(d)
    }

    /// Noise-free expected image (DN, float32, shape (rows, cols)) of one shot of `target`
    /// (a target dict of captures.json, or its JSON text).
    #[pyo3(signature = (target, exposure_s=None, auto_exposure=None, analog_gain=None, simulation=None, base_dir=None))]
    #[allow(clippy::too_many_arguments)]
    fn expected<'py>(
        &self,
        py: Python<'py>,
        target: &Bound<'py, PyAny>,
        exposure_s: Option<f64>,
        auto_exposure: Option<f64>,
        analog_gain: Option<f64>,
        simulation: Option<&Bound<'py, PyAny>>,
        base_dir: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let simulation = simulation.map(json_text).transpose()?;
        let set = self.one_shot(
            &json_text(target)?,
            exposure_s,
            auto_exposure,
            analog_gain,
            1,
            simulation.as_deref(),
            base_dir,
        )?;
        let (outs, _) = run_each(py, &set, 0, true, None)?;
        match outs.into_iter().next() {
            Some(SimOutput::Expected { dn, .. }) => plane_array(py, dn),
            _ => Err(err_msg("no expected image")),
        }
    }

    /// Simulated frames (DN, uint16, shape (frames, rows, cols)) of one shot of `target`,
    /// identical to `camsim simulate --seed SEED` on a capture set with that one shot.
    #[pyo3(signature = (target, exposure_s=None, auto_exposure=None, analog_gain=None, seed=0, frames=1, simulation=None, base_dir=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        target: &Bound<'py, PyAny>,
        exposure_s: Option<f64>,
        auto_exposure: Option<f64>,
        analog_gain: Option<f64>,
        seed: u64,
        frames: usize,
        simulation: Option<&Bound<'py, PyAny>>,
        base_dir: Option<PathBuf>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if frames == 0 {
            return Err(err_msg("frames: must be ≥ 1"));
        }
        let simulation = simulation.map(json_text).transpose()?;
        let set = self.one_shot(
            &json_text(target)?,
            exposure_s,
            auto_exposure,
            analog_gain,
            frames,
            simulation.as_deref(),
            base_dir,
        )?;
        let (outs, _) = run_each(py, &set, seed, false, progress)?;
        let raws = outs
            .into_iter()
            .filter_map(|o| match o {
                SimOutput::Frame { raw, .. } => Some(raw),
                _ => None,
            })
            .collect();
        frames_array(py, raws)
    }

    /// The scene radiance of `target` sampled for this camera's optics (the scene stage of
    /// `simulate`; photons/(s·sr·m²·nm), with the margin the optics need).
    #[pyo3(signature = (target, simulation=None, base_dir=None))]
    fn scene(
        &self,
        py: Python<'_>,
        target: &Bound<'_, PyAny>,
        simulation: Option<&Bound<'_, PyAny>>,
        base_dir: Option<PathBuf>,
    ) -> PyResult<Scene> {
        let simulation = simulation.map(json_text).transpose()?;
        let set = self.one_shot(
            &json_text(target)?,
            Some(0.0),
            None,
            None,
            1,
            simulation.as_deref(),
            base_dir,
        )?;
        let grid = wavelength_grid(&set);
        let scene = py.detach(|| shot_scene(&set, 0, &grid)).map_err(err)?;
        Ok(Scene::from_radiance(scene, grid))
    }

    /// The optics stage: sensor irradiance (photons/(s·m²·nm)) of `scene` through this
    /// camera's optics, on the scene's wavelength bands.
    fn irradiance(&self, py: Python<'_>, scene: &Scene) -> PyResult<Irradiance> {
        // The library's one optics stage (depth-aware for a scene with depth, the uncropped
        // optical image when the camera asks for it).
        let out = py
            .detach(|| {
                camsim_pipeline::chain::camera_irradiance_and_blur(
                    &self.cam,
                    &self.path,
                    &scene.scene,
                    &scene.grid,
                )
            })
            .map_err(err)?;
        Ok(Irradiance::new(out.irradiance, scene.grid.clone()))
    }

    /// Mean electron rate (electrons/s, float32, (rows, cols)) of every pixel for `irradiance`
    /// (QE × CFA and pixel-area integration, then `sensor.pixel_optics` when present; the
    /// image is centred on the sensor).
    fn electron_rate<'py>(
        &self,
        py: Python<'py>,
        irradiance: &Irradiance,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.check_irradiance(irradiance)?;
        let (cam, s) = (&self.cam, &self.cam.sensor);
        let rate = py.detach(|| {
            let mut rate = camsim_sensor::electron_rate(s, &irradiance.irr);
            camsim_pipeline::chain::apply_pixel_optics(cam, &mut rate);
            rate
        });
        arr(py, rate.electrons_per_s, &[s.rows, s.cols])
    }

    /// Expected image (DN, float32, (rows, cols)) for `irradiance` exposed `exposure_s`.
    #[pyo3(signature = (irradiance, exposure_s, analog_gain=None))]
    fn expected_from_irradiance<'py>(
        &self,
        py: Python<'py>,
        irradiance: &Irradiance,
        exposure_s: f64,
        analog_gain: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.check_irradiance(irradiance)?;
        let (cam, s) = (&self.cam, &self.cam.sensor);
        let shot = camsim_sensor::Shot {
            exposure_s,
            analog_gain: analog_gain.unwrap_or(s.analog_gain),
        };
        let dn = py.detach(|| {
            let mut rate = camsim_sensor::electron_rate(s, &irradiance.irr);
            camsim_pipeline::chain::apply_pixel_optics(cam, &mut rate);
            camsim_sensor::expected_dn(s, &rate, &shot)
        });
        arr(py, dn, &[s.rows, s.cols])
    }

    /// One noisy frame (DN, uint16, (rows, cols)) for `irradiance` exposed `exposure_s`, with
    /// every random term drawn from `seed` (frame 0 of shot 0 of the CLI's streams).
    #[pyo3(signature = (irradiance, exposure_s, seed=0, analog_gain=None))]
    fn simulate_from_irradiance<'py>(
        &self,
        py: Python<'py>,
        irradiance: &Irradiance,
        exposure_s: f64,
        seed: u64,
        analog_gain: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.check_irradiance(irradiance)?;
        let (cam, s) = (&self.cam, &self.cam.sensor);
        let shot = camsim_sensor::Shot {
            exposure_s,
            analog_gain: analog_gain.unwrap_or(s.analog_gain),
        };
        let f = py.detach(|| {
            let mut rate = camsim_sensor::electron_rate(s, &irradiance.irr);
            camsim_pipeline::chain::apply_pixel_optics(cam, &mut rate);
            camsim_sensor::expose_with(
                s,
                &rate,
                &shot,
                camsim_sensor::PatternSource::Seeded(seed),
                seed,
                &[0, 0],
            )
        });
        arr(py, f.dn, &[s.rows, s.cols])
    }

    fn __repr__(&self) -> String {
        format!(
            "Camera(name={:?}, {}x{} px, {:.3} µm, f/{})",
            self.cam.name,
            self.cam.sensor.rows,
            self.cam.sensor.cols,
            self.cam.sensor.pixel_pitch_m * 1e6,
            self.cam.optics.f_number
        )
    }
}

/// A validated capture set (captures.json with its camera).
#[pyclass(module = "camsim._camsim", frozen)]
pub struct CaptureSet {
    set: PlCaptureSet,
}

/// What a capture-set simulation produced.
#[pyclass(module = "camsim._camsim", frozen, get_all)]
pub struct SimulationResult {
    /// Shot id → frames (uint16 DN, (frames, rows, cols)) or expected image (float32 DN,
    /// (rows, cols)).
    images: Py<PyDict>,
    /// Shot id → exposure time used (s).
    exposure_s: Py<PyDict>,
}

#[pymethods]
impl CaptureSet {
    /// Read and validate a captures.json; `camera` replaces the camera it names.
    #[staticmethod]
    #[pyo3(signature = (path, camera=None))]
    fn load(path: PathBuf, camera: Option<PathBuf>) -> PyResult<Self> {
        let set = load_captures(&path, camera.as_deref()).map_err(err)?;
        Ok(CaptureSet { set })
    }

    /// Validate a capture set given as a dict (or JSON text) in captures.json form with `camera`; `path` names it in messages
    /// and its folder resolves frames and target files.
    #[staticmethod]
    fn from_json(text: &Bound<'_, PyAny>, camera: &Camera, path: PathBuf) -> PyResult<Self> {
        let raw: CapturesFile = serde_json::from_str(&json_text(text)?)
            .map_err(|e| err(CliError::input(&path, format!("invalid: {e}"))))?;
        let set = captures_with_camera(&path, raw, camera.cam.clone(), camera.path.clone())
            .map_err(err)?;
        Ok(CaptureSet { set })
    }

    /// The captures file.
    #[getter]
    fn path(&self) -> PathBuf {
        self.set.path.clone()
    }
    /// Shot ids in file order.
    #[getter]
    fn shot_ids(&self) -> Vec<String> {
        self.set.shots.iter().map(|s| s.id.clone()).collect()
    }
    /// Default seed of the file (`simulation.seed`), if any.
    #[getter]
    fn seed(&self) -> Option<u64> {
        self.set.simulation.seed
    }
    /// The camera.
    #[getter]
    fn camera(&self) -> PyResult<Camera> {
        let file = read_camera_file(&self.set.camera_path).map_err(err)?;
        Ok(Camera {
            cam: self.set.camera.clone(),
            path: self.set.camera_path.clone(),
            file,
        })
    }

    /// Simulate every frame of every shot (as `camsim simulate`; `seed` defaults to the
    /// file's, else 0), or with `expected=True` each shot's noise-free expected image.
    /// `progress(done, total)` is called after each frame.
    #[pyo3(signature = (seed=None, expected=false, progress=None))]
    fn simulate(
        &self,
        py: Python<'_>,
        seed: Option<u64>,
        expected: bool,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<SimulationResult> {
        let seed = seed.or(self.set.simulation.seed).unwrap_or(0);
        let (outs, exposures) = run_each(py, &self.set, seed, expected, progress)?;
        let images = PyDict::new(py);
        let mut per_shot: Vec<Vec<RawFrame>> = vec![Vec::new(); self.set.shots.len()];
        for o in outs {
            match o {
                SimOutput::Expected { shot, dn } => {
                    images.set_item(&self.set.shots[shot].id, plane_array(py, dn)?)?
                }
                SimOutput::Frame { shot, raw, .. } => per_shot[shot].push(raw),
            }
        }
        if !expected {
            for (shot, frames) in self.set.shots.iter().zip(per_shot) {
                images.set_item(&shot.id, frames_array(py, frames)?)?;
            }
        }
        let ex = PyDict::new(py);
        for (id, t) in exposures {
            ex.set_item(id, t)?;
        }
        Ok(SimulationResult {
            images: images.unbind(),
            exposure_s: ex.unbind(),
        })
    }

    /// `camsim simulate`: write the frames (or expected EXRs) into `out`; returns the files.
    #[pyo3(signature = (out, seed=None, expected=false))]
    fn write(
        &self,
        py: Python<'_>,
        out: PathBuf,
        seed: Option<u64>,
        expected: bool,
    ) -> PyResult<Vec<PathBuf>> {
        let opts = camsim_pipeline::simulate::SimulateOptions {
            out_dir: out,
            seed: seed.or(self.set.simulation.seed).unwrap_or(0),
            expected,
            progress: false,
        };
        let s = py
            .detach(|| camsim_pipeline::simulate::simulate(&self.set, &opts))
            .map_err(err)?;
        Ok(s.files)
    }

    /// The scene radiance of shot `shot_id` sampled for the camera's optics.
    fn scene(&self, py: Python<'_>, shot_id: &str) -> PyResult<Scene> {
        let idx = self.shot_index(shot_id)?;
        let grid = wavelength_grid(&self.set);
        let scene = py
            .detach(|| shot_scene(&self.set, idx, &grid))
            .map_err(err)?;
        Ok(Scene::from_radiance(scene, grid))
    }

    /// `camsim scene`: write the shot's radiance and irradiance EXRs and summary into `out`.
    #[pyo3(signature = (shot_id, out, basis=None))]
    fn write_scene<'py>(
        &self,
        py: Python<'py>,
        shot_id: &str,
        out: PathBuf,
        basis: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let v = py
            .detach(|| camsim_pipeline::scene_cmd::write_scene(&self.set, shot_id, &out, basis))
            .map_err(err)?;
        json_to_py(py, &v.json)
    }

    /// `camsim calibrate`: estimate the sensor's parameters (Appendix A/B, photon transfer);
    /// writes `out`/fitted_camera.json, calibration.json, report.html; returns the summary.
    fn calibrate<'py>(&self, py: Python<'py>, out: PathBuf) -> PyResult<Bound<'py, PyAny>> {
        let v = py
            .detach(|| camsim_pipeline::calibrate_cmd::run_calibrate(&self.set, &out, false))
            .map_err(err)?;
        json_to_py(py, &v.json)
    }

    /// `camsim validate`: simulate every shot and compare with the recording; returns the
    /// summary written to `out`.
    #[pyo3(signature = (out, seed=None))]
    fn validate<'py>(
        &self,
        py: Python<'py>,
        out: PathBuf,
        seed: Option<u64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let seed = seed.or(self.set.simulation.seed).unwrap_or(0);
        let v = py
            .detach(|| camsim_pipeline::validate_cmd::run_validate(&self.set, &out, seed, false))
            .map_err(err)?;
        json_to_py(py, &v.json)
    }

    /// `camsim diagnose`: the physics the camera model leaves out (fit check, locate,
    /// candidate effects, BIC selection); returns report.json written to `out`.
    #[pyo3(signature = (out, bic_threshold=10.0, effects=None))]
    fn diagnose<'py>(
        &self,
        py: Python<'py>,
        out: PathBuf,
        bic_threshold: f64,
        effects: Option<Vec<String>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let opts = camsim_pipeline::diagnose_cmd::DiagnoseCmdOptions {
            bic_threshold,
            effects: effects.unwrap_or_default(),
            progress: false,
        };
        let v = py
            .detach(|| camsim_pipeline::diagnose_cmd::run_diagnose(&self.set, &out, &opts))
            .map_err(err)?;
        json_to_py(py, &v.json)
    }

    fn __repr__(&self) -> String {
        format!(
            "CaptureSet({}, {} shots, camera {:?})",
            self.set.path.display(),
            self.set.shots.len(),
            self.set.camera.name
        )
    }
}

impl CaptureSet {
    fn shot_index(&self, shot_id: &str) -> PyResult<usize> {
        self.set
            .shots
            .iter()
            .position(|s| s.id == shot_id)
            .ok_or_else(|| {
                err(CliError::input(
                    &self.set.path,
                    format!(
                        "no shot with id \"{shot_id}\" (have: {})",
                        self.set
                            .shots
                            .iter()
                            .map(|s| s.id.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ))
            })
    }
}

/// `camsim run`: the whole chain scene → optics → sensor → ISP → display with its report in
/// `out` (no config: the paper's §3 setup). Returns summary.json.
#[pyfunction]
#[pyo3(signature = (out, config=None))]
fn run<'py>(py: Python<'py>, out: PathBuf, config: Option<PathBuf>) -> PyResult<Bound<'py, PyAny>> {
    let s = py
        .detach(|| camsim_pipeline::run::run(config.as_deref(), &out, false))
        .map_err(err)?;
    json_to_py(py, &s.json)
}

/// `camsim study`: evaluate a parameter study (points already finished in `out` are reused);
/// returns the counts.
#[pyfunction]
#[pyo3(signature = (spec, out, max_points=None))]
fn study<'py>(
    py: Python<'py>,
    spec: PathBuf,
    out: PathBuf,
    max_points: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = camsim_pipeline::study::StudyOptions {
        out,
        engine: camsim_pipeline::study::EngineKind::Local,
        max_points,
        ray: camsim_pipeline::study::ray::RayOptions {
            address: None,
            num_cpus: None,
            python: None,
        },
        progress: false,
    };
    let s = py
        .detach(|| camsim_pipeline::study::run_study(&spec, &opts))
        .map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("points", s.points)?;
    d.set_item("evaluated", s.evaluated)?;
    d.set_item("reused", s.reused)?;
    d.set_item("pending", s.pending)?;
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Camera>()?;
    m.add_class::<CaptureSet>()?;
    m.add_class::<SimulationResult>()?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(study, m)?)?;
    Ok(())
}
