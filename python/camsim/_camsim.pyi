"""Type stubs of the camsim Rust extension (units in names; arrays row-major).

Radiance: photons/(s·sr·m²·nm). Irradiance: photons/(s·m²·nm). DN: digital numbers.
"""
from __future__ import annotations

from os import PathLike
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

StrPath = Union[str, "PathLike[str]"]
ArrayLike = npt.ArrayLike
Json = Union[str, Mapping[str, Any]]
Progress = Callable[[int, int], Any]

class CamsimError(Exception):
    """An error of camsim: the one-line message the command line prints."""

def version() -> str: ...
def noop(x: float) -> float:
    """Crosses the Python/Rust boundary and returns `x` (overhead benchmarks)."""
def set_threads(n: int) -> None:
    """Worker threads of the global pool (as the CLI's --threads); call once, first."""

class Camera:
    """A validated camera (optics + sensor) of the camera-file format (docs/config.md)."""
    @staticmethod
    def load(path: StrPath) -> Camera:
        """Read and validate a camera JSON file."""
    @staticmethod
    def from_json(text: Json, path: Optional[StrPath] = None) -> Camera:
        """Validate a camera dict (or JSON text); `path` names it in messages and resolves
        its relative file references."""
    def to_json(self) -> str:
        """The camera as camera-file JSON text."""
    @property
    def name(self) -> str: ...
    @property
    def path(self) -> str: ...
    @property
    def rows(self) -> int: ...
    @property
    def cols(self) -> int: ...
    @property
    def pixel_pitch_um(self) -> float: ...
    @property
    def adc_bits(self) -> int: ...
    @property
    def channels(self) -> List[str]:
        """Channel letters in QE order."""
    @property
    def f_number(self) -> float: ...
    @property
    def focal_length_mm(self) -> float: ...
    def snr_db(self, signal_v: Sequence[float]) -> Dict[str, npt.NDArray[np.float64]]:
        """Pixel SNR (dB) and components {snr_db, shot_db, read_db, dsnu_db, prnu_db} at mean
        signals `signal_v` (V before analog gain); ISETCam pixelSNR convention."""
    def expected(self, target: Json, exposure_s: Optional[float] = None,
                 auto_exposure: Optional[float] = None, analog_gain: Optional[float] = None,
                 simulation: Optional[Json] = None,
                 base_dir: Optional[StrPath] = None) -> npt.NDArray[np.float32]:
        """Noise-free expected image, DN, shape (rows, cols), of one shot of `target` (a
        captures.json target dict). Give `exposure_s` (s) or `auto_exposure` (fraction of the
        voltage swing). `simulation`: {wavelength_nm: {start_nm, stop_nm, step_nm},
        oversample}. `base_dir` resolves target files (default: the current folder)."""
    def simulate(self, target: Json, exposure_s: Optional[float] = None,
                 auto_exposure: Optional[float] = None, analog_gain: Optional[float] = None,
                 seed: int = 0, frames: int = 1, simulation: Optional[Json] = None,
                 base_dir: Optional[StrPath] = None,
                 progress: Optional[Progress] = None) -> npt.NDArray[np.uint16]:
        """Simulated frames, DN, shape (frames, rows, cols): identical to `camsim simulate
        --seed SEED` on a capture set with this one shot."""
    def scene(self, target: Json, simulation: Optional[Json] = None,
              base_dir: Optional[StrPath] = None) -> Scene:
        """The scene radiance of `target` sampled for this camera's optics (with margin)."""
    def irradiance(self, scene: Scene) -> Irradiance:
        """The optics stage: sensor irradiance of `scene` on its wavelength bands."""
    def electron_rate(self, irradiance: Irradiance) -> npt.NDArray[np.float32]:
        """Mean electron rate (electrons/s), shape (rows, cols), of every pixel."""
    def expected_from_irradiance(self, irradiance: Irradiance, exposure_s: float,
                                 analog_gain: Optional[float] = None) -> npt.NDArray[np.float32]:
        """Expected image (DN, (rows, cols)) for `irradiance` exposed `exposure_s` (s)."""
    def simulate_from_irradiance(self, irradiance: Irradiance, exposure_s: float, seed: int = 0,
                                 analog_gain: Optional[float] = None) -> npt.NDArray[np.uint16]:
        """One noisy frame (DN, (rows, cols)) for `irradiance` exposed `exposure_s` (s)."""

class SimulationResult:
    """What CaptureSet.simulate produced."""
    @property
    def images(self) -> Dict[str, np.ndarray]:
        """Shot id → frames (uint16 DN, (frames, rows, cols)) or expected image (float32 DN,
        (rows, cols))."""
    @property
    def exposure_s(self) -> Dict[str, float]:
        """Shot id → exposure time used (s)."""

class CaptureSet:
    """A validated capture set (captures.json + its camera)."""
    @staticmethod
    def load(path: StrPath, camera: Optional[StrPath] = None) -> CaptureSet:
        """Read and validate captures.json; `camera` replaces the camera it names."""
    @staticmethod
    def from_json(text: Json, camera: Camera, path: StrPath) -> CaptureSet:
        """Validate a captures dict with `camera`; `path` names it and its folder resolves
        frames and target files."""
    @property
    def path(self) -> str: ...
    @property
    def shot_ids(self) -> List[str]: ...
    @property
    def seed(self) -> Optional[int]:
        """simulation.seed of the file, if any."""
    @property
    def camera(self) -> Camera: ...
    def simulate(self, seed: Optional[int] = None, expected: bool = False,
                 progress: Optional[Progress] = None) -> SimulationResult:
        """Every frame of every shot (as `camsim simulate`), or each shot's expected image."""
    def write(self, out: StrPath, seed: Optional[int] = None, expected: bool = False) -> List[str]:
        """`camsim simulate`: write frames (or expected EXRs) into `out`; the files written."""
    def scene(self, shot_id: str) -> Scene:
        """The scene radiance of a shot sampled for the camera's optics."""
    def write_scene(self, shot_id: str, out: StrPath, basis: Optional[int] = None) -> Dict[str, Any]:
        """`camsim scene`: radiance and irradiance EXRs (W units) and a summary."""
    def calibrate(self, out: StrPath) -> Dict[str, Any]:
        """`camsim calibrate`: the sensor's parameters from dark/flat/narrowband shots
        (Appendix A/B, photon transfer); calibration.json's content."""
    def validate(self, out: StrPath, seed: Optional[int] = None) -> Dict[str, Any]:
        """`camsim validate`: simulation against the recording (paper Figs. 3–6)."""
    def diagnose(self, out: StrPath, bic_threshold: float = 10.0,
                 effects: Optional[Sequence[str]] = None) -> Dict[str, Any]:
        """`camsim diagnose`: the physics the model leaves out; report.json's content."""

def run(out: StrPath, config: Optional[StrPath] = None) -> Dict[str, Any]:
    """`camsim run`: scene → optics → sensor → ISP → display with a report in `out`; no
    config = the paper's §3 setup. Returns summary.json's content."""
def study(spec: StrPath, out: StrPath, max_points: Optional[int] = None) -> Dict[str, int]:
    """`camsim study` (local engine): {points, evaluated, reused, pending}."""

class Scene:
    """Scene spectral radiance, photons/(s·sr·m²·nm), sampled at `sample_pitch_m`."""
    @staticmethod
    def from_array(radiance: ArrayLike, wavelength_nm: Sequence[float], sample_pitch_m: float,
                   unit: str = "photons", depth_m: Optional[ArrayLike] = None,
                   object_distance_m: Optional[float] = None) -> Scene:
        """From a (rows, cols, bands) array; unit "photons" or "W" (W/(sr·m²·nm))."""
    @staticmethod
    def read_exr(path: StrPath, sample_pitch_m: float = 1e-6) -> Scene:
        """Read a spectral OpenEXR (W units converted to photons; Z → depth)."""
    def write_exr(self, path: StrPath) -> None:
        """Write as spectral OpenEXR in W/(sr·m²·nm)."""
    @property
    def radiance(self) -> npt.NDArray[np.float32]:
        """(rows, cols, bands), photons/(s·sr·m²·nm)."""
    @property
    def wavelength_nm(self) -> npt.NDArray[np.float64]: ...
    @property
    def sample_pitch_m(self) -> float: ...
    @property
    def shape(self) -> Tuple[int, int, int]: ...
    @property
    def depth_m(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def illuminant(self) -> Optional[npt.NDArray[np.float64]]:
        """Photons per unit reflectance on the bands, when reflectance × illuminant."""
    def mean_luminance_cd_m2(self) -> float:
        """Mean luminance (cd/m²), exact integrals, SI constants."""
    def mean_luminance_isetcam_cd_m2(self) -> float:
        """Mean luminance (cd/m²), Riemann sums on the bands, ISETCam constants."""
    def scaled_to_isetcam_luminance(self, cd_m2: float) -> Scene: ...

class Irradiance:
    """Sensor irradiance, photons/(s·m²·nm), sampled at `sample_pitch_m`."""
    @staticmethod
    def from_array(irradiance: ArrayLike, wavelength_nm: Sequence[float], sample_pitch_m: float,
                   unit: str = "photons") -> Irradiance: ...
    @property
    def irradiance(self) -> npt.NDArray[np.float32]:
        """(rows, cols, bands), photons/(s·m²·nm)."""
    @property
    def wavelength_nm(self) -> npt.NDArray[np.float64]: ...
    @property
    def sample_pitch_m(self) -> float: ...
    @property
    def shape(self) -> Tuple[int, int, int]: ...
    def write_exr(self, path: StrPath) -> None:
        """Write as spectral OpenEXR in W/(m²·nm)."""

def render(scene: StrPath, out: StrPath, args: Sequence[str] = ...) -> Tuple[Dict[str, Any], Scene]:
    """`camsim render SCENE --out OUT.exr ARGS…` in-process; (summary, the rendered Scene with
    depth)."""
def read_frame(path: StrPath) -> npt.NDArray[np.uint16]:
    """A 16-bit PNG/TIFF frame as DN (rows, cols)."""
def read_exr_channels(path: StrPath) -> Dict[str, npt.NDArray[np.float32]]:
    """Every channel of an OpenEXR's first layer, (rows, cols) each."""
def diffraction_otf(freq_cyc_per_mm: ArrayLike, wavelength_nm: float, f_number: float) -> npt.NDArray[np.float64]:
    """Diffraction-limited OTF of a circular pupil (same shape as the frequencies)."""
def airy_radius_um(wavelength_nm: float, f_number: float) -> float:
    """Airy first-zero radius in the image plane (µm), 1.22 λN."""
def airy_radius_rad(wavelength_nm: float, pupil_diameter_m: float) -> float:
    """Airy first-zero angular radius (rad), 1.22 λ/D."""
def wavefront_psf(wavelength_nm: float, f_number: float, defocus_um: float = 0.0,
                  pitch_um: float = 0.25, pupil_samples: int = 128) -> Tuple[npt.NDArray[np.float64], float]:
    """PSF (sum 1) of a circular pupil with Zernike defocus (RMS µm); (psf, pitch µm)."""

class Lens:
    """A sequential lens prescription (mm, nm, degrees of object-space field)."""
    @staticmethod
    def load(path: StrPath) -> Lens:
        """Project .json, Zemax .zmx, ISET/pbrt .dat or ISETCam lens .json."""
    @staticmethod
    def from_json(text: Json, path: Optional[StrPath] = None) -> Lens: ...
    @property
    def name(self) -> str: ...
    @property
    def wavelengths_nm(self) -> List[float]: ...
    @property
    def primary_nm(self) -> float: ...
    @property
    def surfaces(self) -> int: ...
    def focused(self, wavelength_nm: Optional[float] = None) -> Lens:
        """Image plane at the paraxial focus of `wavelength_nm` (default primary)."""
    def with_image_distance(self, image_distance_mm: float) -> Lens: ...
    def first_order(self, wavelength_nm: Optional[float] = None) -> Dict[str, float]:
        """efl_mm, bfl_mm, f_number, working_f_number, pupils (z from the first vertex), …"""
    def vertex_z_mm(self) -> List[float]: ...
    def spot(self, field_deg: float = 0.0, wavelength_nm: Optional[float] = None, grid: int = 33,
             defocus_mm: float = 0.0, clip: bool = False) -> Dict[str, Any]:
        """{points_mm (N, 2), centroid_mm, rms_radius_um, n_launched}."""
    def polychromatic_rms_um(self, field_deg: float = 0.0, defocus_mm: float = 0.0, grid: int = 33) -> float: ...
    def best_focus_shift_mm(self, field_deg: float = 0.0, grid: int = 33,
                            span_mm: Optional[float] = None) -> float: ...
    def distortion(self, field_deg: float) -> Dict[str, Any]:
        """{paraxial_height_mm, real_height_mm, distortion_pct, chief_height_by_wavelength_mm,
        lateral_colour_um}."""
    def psf(self, field_deg: float = 0.0, wavelength_nm: Optional[float] = None, n: int = 64,
            pad: int = 4) -> Tuple[npt.NDArray[np.float64], float]:
        """Wave-optics PSF (n·pad)², sum 1, centred at (m/2, m/2); (psf, pitch µm)."""
    def mtf(self, freq_cyc_per_mm: Sequence[float], field_deg: float = 0.0,
            wavelength_nm: Optional[float] = None, n: int = 64, pad: int = 4) -> Dict[str, Any]:
        """{freq_cyc_per_mm, tangential, sagittal, opd_rms_waves, opd_pv_waves}."""
    def report(self, field_fractions: Sequence[float] = ..., wavelengths_nm: Optional[Sequence[float]] = None,
               max_field_deg: Optional[float] = None, grid: int = 33,
               mtf_lp_mm: Optional[Sequence[float]] = None, mtf_focus: str = "best",
               clip: bool = False) -> Dict[str, Any]:
        """The numbers of `camsim lens report --json`."""
    def field_model(self, n_fields: int = 5, max_field_deg: Optional[float] = None,
                    wavelengths_nm: Optional[Sequence[float]] = None, kind: str = "wave",
                    psf_n: int = 33, psf_pitch_um: float = 1.0, pupil_n: int = 64,
                    pad: int = 4) -> LensFieldModel: ...

class LensFieldModel:
    """PSFs, distortion and relative illumination over image height (mm) × wavelength (nm)."""
    @staticmethod
    def load(path: StrPath) -> LensFieldModel: ...
    def save(self, path: StrPath) -> None: ...
    @property
    def wavelengths_nm(self) -> List[float]: ...
    @property
    def paraxial_height_mm(self) -> List[float]: ...
    @property
    def psf_n(self) -> int: ...
    @property
    def psf_pitch_um(self) -> float: ...
    @property
    def efl_mm(self) -> float: ...
    @property
    def f_number(self) -> float: ...
    def psf_at(self, x_mm: float, y_mm: float, wavelength_nm: float) -> npt.NDArray[np.float64]:
        """(psf_n, psf_n), sum 1, centred on the chief ray of image point (x_mm, y_mm)."""
    def real_height_mm_at(self, height_mm: float, wavelength_nm: float) -> float: ...
    def relative_illumination_at(self, height_mm: float, wavelength_nm: float) -> float: ...

def lens_command(args: Sequence[str]) -> None:
    """Any `camsim lens …` subcommand in-process, e.g. ["psf", "lens.json", "--out", "DIR"]."""

def energy_to_photons(wavelength_nm: Sequence[float], energy: Sequence[float],
                      constants: str = "si") -> npt.NDArray[np.float64]:
    """E·λ/(hc): W → photons/s per nm; constants "si" or "isetcam"."""
def illuminant(name: str, wavelength_nm: Sequence[float]) -> npt.NDArray[np.float64]:
    """An embedded ISETCam illuminant (energy, relative) at `wavelength_nm`."""
def blackbody(kelvin: float, wavelength_nm: Sequence[float], c1: float = 3.741832e-16,
              c2: float = 1.438786e-2) -> npt.NDArray[np.float64]:
    """Planck radiance W/(sr·m²·nm)."""
def xyz_from_energy(wavelength_nm: Sequence[float], energy: Sequence[float],
                    quadrature: str = "exact") -> Tuple[float, float, float]:
    """CIE 1931 XYZ (K_m = 683 lm/W); quadrature "exact" or "riemann" (ISETCam)."""
def xyz_to_lab(xyz_values: ArrayLike, white_xyz: Sequence[float]) -> npt.NDArray[np.float64]:
    """(..., 3) XYZ → (..., 3) CIELAB."""
def delta_e_76(lab1: ArrayLike, lab2: ArrayLike) -> npt.NDArray[np.float64]: ...
def delta_e_94(lab1: ArrayLike, lab2: ArrayLike) -> npt.NDArray[np.float64]: ...
def delta_e_2000(lab1: ArrayLike, lab2: ArrayLike) -> npt.NDArray[np.float64]:
    """CIEDE2000 over the leading axes of (..., 3) arrays."""
def scielab(xyz_a: ArrayLike, xyz_b: ArrayLike, white_xyz: Sequence[float],
            samples_per_degree: float, formula: str = "cie76") -> Tuple[npt.NDArray[np.float64], float]:
    """S-CIELAB ΔE map (rows, cols) and its mean; formula "cie76" or "ciede2000"."""
def slanted_edge_mtf(image: ArrayLike, roi: Optional[Tuple[int, int, int, int]] = None) -> Dict[str, Any]:
    """ISO 12233 e-SFR; roi = (row0, row1, col0, col1), end-exclusive; frequencies in
    cycles/pixel."""
def psnr_db(a: ArrayLike, b: ArrayLike, peak: float) -> float: ...
