"""camsim: physically based digital camera simulation (ISET pipeline) from Python.

The package binds camsim's Rust library (``camsim-pipeline`` and the stage crates) with
PyO3; it never runs the command line, but gives the same numbers: the same inputs and seed
give the same frames as ``camsim simulate``, pixel for pixel.

Conventions
-----------
* Arrays are NumPy, row-major, axes ``(rows, cols)`` or ``(rows, cols, bands)``; frames are
  ``uint16`` DN ``(frames, rows, cols)``; expected images ``float32`` DN.
* Spectral arrays carry their wavelengths (``.wavelength_nm``, nm). Radiance is in
  photons/(s·sr·m²·nm), irradiance in photons/(s·m²·nm), unless a name says otherwise.
* Units are in the names: ``_nm``, ``_um``, ``_mm``, ``_m``, ``_s``, ``_dn``, ``_deg``.
* Errors raise :class:`CamsimError` with the message the CLI prints.
* Long calls release the GIL; ``progress=callable(done, total)`` reports progress.

Quick start::

    import camsim
    cam = camsim.Camera.load("examples/table1/camera.json")
    frames = cam.simulate({"kind": "macbeth", "illuminant": "D65",
                           "mean_luminance_cd_m2": 100}, exposure_s=0.01, seed=1)
"""
from __future__ import annotations

from typing import Any, Dict, Optional

from . import _camsim
from ._camsim import (  # noqa: F401  (re-exports)
    CamsimError,
    Camera,
    CaptureSet,
    Irradiance,
    Lens,
    LensFieldModel,
    Scene,
    SimulationResult,
    airy_radius_rad,
    airy_radius_um,
    blackbody,
    delta_e_2000,
    delta_e_76,
    delta_e_94,
    diffraction_otf,
    energy_to_photons,
    illuminant,
    lens_command,
    noop,
    psnr_db,
    read_exr_channels,
    read_frame,
    render,
    run,
    scielab,
    set_threads,
    slanted_edge_mtf,
    study,
    wavefront_psf,
    xyz_from_energy,
    xyz_to_lab,
)

__version__ = _camsim.version()

__all__ = [
    "CamsimError",
    "Camera",
    "CaptureSet",
    "Irradiance",
    "Lens",
    "LensFieldModel",
    "Scene",
    "SimulationResult",
    "airy_radius_rad",
    "airy_radius_um",
    "blackbody",
    "camera",
    "delta_e_2000",
    "delta_e_76",
    "delta_e_94",
    "diffraction_otf",
    "energy_to_photons",
    "illuminant",
    "lens_command",
    "psnr_db",
    "read_exr_channels",
    "read_frame",
    "render",
    "run",
    "scielab",
    "set_threads",
    "slanted_edge_mtf",
    "study",
    "wavefront_psf",
    "xyz_from_energy",
    "xyz_to_lab",
]

_OPTICS_KEYS = {
    "f_number",
    "focal_length_mm",
    "transmittance",
    "relative_illumination",
    "blur",
    "diffuser",
    "object_distance_m",
    "camera_equation",
    "exposure_scale",
    "veiling_glare",
    "defocus",
    "distortion",
    "lateral_color",
}


def camera(name: Optional[str] = None, *, optics: Optional[Dict[str, Any]] = None,
           sensor: Optional[Dict[str, Any]] = None, **params: Any) -> Camera:
    """A camera from keyword parameters (the keys of camera.json, docs/config.md).

    Optics keys (``f_number``, ``focal_length_mm``, ``transmittance``,
    ``relative_illumination``, ``blur``, ...) go to the optics section, every other key
    (``rows``, ``cols``, ``pixel_pitch_um``, ``cfa``, ``channels``, ``well_capacity_e``,
    ``conversion_gain_v_per_e``, ``voltage_swing_v``, ``adc_bits``, ``read_noise_v``, ...)
    to the sensor section; ``optics=`` / ``sensor=`` dicts may be given instead or as a base.
    Validation and messages are those of a camera file.
    """
    o = dict(optics or {})
    s = dict(sensor or {})
    for k, v in params.items():
        (o if k in _OPTICS_KEYS else s)[k] = v
    d: Dict[str, Any] = {"optics": o, "sensor": s}
    if name is not None:
        d["name"] = name
    return Camera.from_json(d)
