"""Acceptance 3: ISETCam oracle cases (../shared/oracles/isetcam, ISETCam under Octave via
pyisetcam) reproduced from Python. The tolerances are the cases' own."""
import json

import numpy as np
import pytest

import camsim


def case(shared, name):
    return json.loads((shared / "oracles/isetcam/cases" / f"{name}.json").read_text())


def vals(v):
    return np.asarray(v["values"], dtype=float).reshape(v["shape"])


def test_utility_energy_quanta_1d(shared):
    c = case(shared, "utility_energy_quanta_1d")
    w, e = vals(c["inputs"]["wave_nm"]), vals(c["inputs"]["energy_W"])
    got = camsim.energy_to_photons(w, e, constants="isetcam")
    np.testing.assert_allclose(got, vals(c["expected"]["photons"]), rtol=1e-9)
    # the SI 2019 Planck constant differs from ISETCam's in the 5th digit: not the same numbers
    si = camsim.energy_to_photons(w, e, constants="si")
    assert np.max(np.abs(si / got - 1)) > 1e-6


def test_metrics_xyz_from_energy_1d(shared):
    c = case(shared, "metrics_xyz_from_energy_1d")
    w = vals(c["inputs"]["wave_nm"])
    e = vals(c["inputs"]["energy_W_per_sr_m2_nm"])
    got = camsim.xyz_from_energy(w, e, quadrature="riemann")
    np.testing.assert_allclose(got, vals(c["expected"]["xyz"]), rtol=1e-7)


def test_metrics_xyz_to_lab_1d(shared):
    c = case(shared, "metrics_xyz_to_lab_1d")
    got = camsim.xyz_to_lab(vals(c["inputs"]["xyz"]), list(vals(c["inputs"]["white_point_xyz"])))
    np.testing.assert_allclose(got, vals(c["expected"]["lab"]), rtol=c["tolerance"]["rtol"])


def test_metrics_delta_e_ab_1976_1d(shared):
    c = case(shared, "metrics_delta_e_ab_1976_1d")
    white = list(vals(c["inputs"]["white_point_xyz"]))
    lab1 = camsim.xyz_to_lab(vals(c["inputs"]["xyz1"]), white)
    lab2 = camsim.xyz_to_lab(vals(c["inputs"]["xyz2"]), white)
    got = float(camsim.delta_e_76(lab1, lab2))
    assert got == pytest.approx(c["expected"]["delta_e_ab"], rel=c["tolerance"]["rtol"])


def test_optics_airy_disk_small(shared):
    c = case(shared, "optics_airy_disk_small")
    q = c["inputs"]["radius_um_query"]
    tol = c["tolerance"]["rtol"]
    r_um = camsim.airy_radius_um(q["wavelength_nm"], q["f_number"])
    assert r_um == pytest.approx(c["expected"]["radius_um"], rel=tol)
    q = c["inputs"]["radius_angle_query"]
    r_rad = camsim.airy_radius_rad(q["wavelength_nm"], q["pupil_diameter_m"])
    assert r_rad == pytest.approx(c["expected"]["radius_rad"], rel=tol)
    assert np.degrees(r_rad) == pytest.approx(c["expected"]["radius_deg"], rel=tol)


def test_oi_otfwavelength_diffraction_small(shared):
    c = case(shared, "oi_otfwavelength_diffraction_small")
    n = c["inputs"]["optics"]["f_number"]
    wl = vals(c["inputs"]["wavelength_nm"])
    fx_mm = vals(c["inputs"]["fx_cycles_per_um"]) * 1e3
    want = vals(c["expected"]["otf"])  # (frequency, wavelength)
    got = np.stack([camsim.diffraction_otf(fx_mm, w, n) for w in wl], axis=1)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, atol=c["tolerance"]["atol"], rtol=0)
    assert want.max() > 0.99 and (want > 0.1).sum() > 100  # not a case of zeros


def test_sensor_snr_components_small(shared, repo):
    c = case(shared, "sensor_snr_components_small")
    i = c["inputs"]
    base = json.loads((repo / "examples/table1/camera.json").read_text())
    base["sensor"].update(conversion_gain_v_per_e=i["conversion_gain_V_per_e"],
                          read_noise_v=i["read_noise_V"], dsnu_sigma_v=i["dsnu_sigma_V"],
                          prnu_sigma_percent=i["prnu_percent"])
    cam = camsim.Camera.from_json(base)
    got = cam.snr_db(list(vals(i["volts"])))
    atol = c["tolerance"]["atol_dB"]
    np.testing.assert_allclose(got["snr_db"], vals(c["expected"]["snr"]), atol=atol, rtol=0)
    for k in ["shot", "read", "dsnu", "prnu"]:
        want = vals(c["expected"][f"snr_{k}"])
        finite = np.isfinite(want)
        np.testing.assert_allclose(got[f"{k}_db"][finite], want[finite], atol=atol, rtol=0)


def test_scene_uniform_bb_small(shared):
    c = case(shared, "scene_uniform_bb_small")
    tol = c["tolerance"]["rtol"]
    wl = np.arange(400.0, 701.0, 10.0)
    energy = camsim.blackbody(4500.0, wl)
    photons = camsim.energy_to_photons(wl, energy, constants="isetcam")
    cube = np.broadcast_to(photons, (16, 16, wl.size))
    scene = camsim.Scene.from_array(cube, wl, 1e-6).scaled_to_isetcam_luminance(100.0)
    got = scene.radiance
    assert got.shape == (16, 16, 31) and got.dtype == np.float32
    np.testing.assert_allclose(got[5, 7], vals(c["expected"]["pixel_spectrum_photons"]), rtol=tol)
    want = np.load(shared / "oracles/isetcam/data/scene_uniform_bb_small__photons.npy")
    np.testing.assert_allclose(got, want, rtol=tol)
    assert scene.mean_luminance_isetcam_cd_m2() == pytest.approx(100.0, rel=1e-5)
