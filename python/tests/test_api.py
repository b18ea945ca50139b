"""The Python API itself: arrays and wavelengths, the staged pipeline, statistics of the
simulated noise, metrics against closed forms and published data, errors, progress and GIL."""
import json
import threading
import time

import numpy as np
import pytest

import camsim


def mono_camera(rows=64, cols=64, **kw):
    """A one-channel sensor with shot noise only (every other term off), no blur, no fall-off."""
    p = dict(rows=rows, cols=cols, pixel_pitch_um=2.0, cfa=["g"], channels={"g": {"wavelength_nm": [400, 700], "values": [0.5, 0.5]}},
             well_capacity_e=1e6, conversion_gain_v_per_e=1e-4, voltage_swing_v=1.0,
             adc_bits=12, f_number=2.8, focal_length_mm=1000.0, relative_illumination="none",
             blur={"kind": "none"})
    p.update(kw)
    return camsim.camera("mono", **p)


UNIFORM = {"kind": "uniform", "radiance": 0.02}
T_FLAT = 6e-4  # s: about 2,000 electrons per pixel (rate 3.3e6 e/s), far below the 10,000 e swing


def test_camera_from_kwargs_and_json_roundtrip():
    cam = mono_camera()
    assert (cam.rows, cam.cols, cam.channels, cam.adc_bits) == (64, 64, ["g"], 12)
    assert cam.pixel_pitch_um == pytest.approx(2.0)
    again = camsim.Camera.from_json(json.loads(cam.to_json()))
    assert again.to_json() == cam.to_json()


def test_shot_noise_statistics():
    """Mean (z-test) and variance (chi-square) of a flat frame against the expected image:
    DN = k·n with n ~ Poisson(μ), k = g·(2^bits − 1)/swing; var = k²μ + 1/12 (quantisation)."""
    cam = mono_camera()
    exp = cam.expected(UNIFORM, exposure_s=T_FLAT)
    assert exp.shape == (64, 64) and exp.dtype == np.float32
    mu_dn = float(exp.mean())
    assert np.ptp(exp) < 1e-3 * mu_dn  # uniform, no fall-off
    k = 1e-4 * 4095 / 1.0
    mu_e = mu_dn / k
    assert 500 < mu_e < 5000  # a well-exposed frame, far from clipping
    frame = cam.simulate(UNIFORM, exposure_s=T_FLAT, seed=1)[0].astype(float)
    n = frame.size
    var_pred = k * k * mu_e + 1 / 12
    z = (frame.mean() - mu_dn) / np.sqrt(var_pred / n)
    assert abs(z) < 4, z
    ratio = frame.var(ddof=1) / var_pred
    assert abs(ratio - 1) < 4 * np.sqrt(2 / (n - 1)), ratio
    # same seed → same frame; different seed → different frame
    assert np.array_equal(cam.simulate(UNIFORM, exposure_s=T_FLAT, seed=1)[0], frame)
    assert not np.array_equal(cam.simulate(UNIFORM, exposure_s=T_FLAT, seed=2)[0], frame)


def test_staged_pipeline_equals_one_call(repo):
    """scene → irradiance → expected_from_irradiance gives camera.expected (the general path
    against the uniform fast path, which the Rust test bounds at 1e-6)."""
    d = json.loads((repo / "examples/table1/camera.json").read_text())
    d["sensor"].update(rows=40, cols=50)
    d["optics"]["blur"] = {"kind": "none"}
    cam = camsim.Camera.from_json(d)
    target = {"kind": "uniform", "radiance": {"wavelength_nm": [400, 550, 700], "values": [0.002, 0.004, 0.001]}}
    scene = cam.scene(target)
    assert scene.radiance.shape == scene.shape and scene.radiance.shape[2] == scene.wavelength_nm.size
    irr = cam.irradiance(scene)
    assert irr.irradiance.shape[2] == irr.wavelength_nm.size
    staged = cam.expected_from_irradiance(irr, 0.05)
    direct = cam.expected(target, exposure_s=0.05)
    np.testing.assert_allclose(staged, direct, rtol=1e-5)
    assert direct.max() > 50


def test_scene_arrays_and_exr_roundtrip(tmp_path):
    wl = np.arange(400.0, 701.0, 20.0)
    rng = np.random.default_rng(0)
    rad = rng.uniform(0.0, 1e16, size=(8, 12, wl.size))
    s = camsim.Scene.from_array(rad, wl, 2e-6)
    assert s.radiance.dtype == np.float32 and s.radiance.shape == (8, 12, wl.size)
    np.testing.assert_allclose(s.radiance, rad, rtol=1e-7)
    np.testing.assert_array_equal(s.wavelength_nm, wl)
    p = tmp_path / "s.exr"
    s.write_exr(str(p))
    back = camsim.Scene.read_exr(str(p), 2e-6)
    np.testing.assert_array_equal(back.wavelength_nm, wl)
    np.testing.assert_allclose(back.radiance, s.radiance, rtol=1e-6)
    # W input → photons: L_q = L_e λ/(h c)
    w = camsim.Scene.from_array(np.ones((2, 2, wl.size)), wl, 1e-6, unit="W")
    h, c = 6.62607015e-34, 299792458.0
    np.testing.assert_allclose(w.radiance[0, 0], wl * 1e-9 / (h * c), rtol=1e-6)


def test_delta_e_2000_published_pairs():
    """Sharma, Wu & Dalal (2005), Color Res. Appl. 30(1), Table 1."""
    pairs = [
        ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
        ((50.0, 3.1571, -77.2803), (50.0, 0.0, -82.7485), 2.8615),
        ((50.0, 2.8361, -74.0200), (50.0, 0.0, -82.7485), 3.4412),
        ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
        ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
        ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ]
    a = np.array([p[0] for p in pairs])
    b = np.array([p[1] for p in pairs])
    got = camsim.delta_e_2000(a, b)
    np.testing.assert_allclose(got, [p[2] for p in pairs], atol=5e-5)
    assert camsim.delta_e_2000(a.reshape(2, 3, 3), b.reshape(2, 3, 3)).shape == (2, 3)


def test_scielab_uniform_equals_cielab():
    """Filtering leaves a uniform image unchanged, so S-CIELAB of two uniform images is their
    ΔE*ab."""
    white = [95.047, 100.0, 108.883]
    xa = np.broadcast_to([20.0, 30.0, 15.0], (16, 16, 3))
    xb = np.broadcast_to([18.0, 27.0, 16.5], (16, 16, 3))
    de_map, mean = camsim.scielab(xa, xb, white, 40.0)
    want = float(camsim.delta_e_76(camsim.xyz_to_lab([20.0, 30.0, 15.0], white),
                                   camsim.xyz_to_lab([18.0, 27.0, 16.5], white)))
    assert de_map.shape == (16, 16)
    np.testing.assert_allclose(de_map, want, rtol=1e-6)
    assert mean == pytest.approx(want, rel=1e-6)
    zero, m0 = camsim.scielab(xa, xa, white, 40.0)
    assert m0 == 0.0 and not zero.any()


def test_slanted_edge_mtf_of_box_pixels():
    """An ideal edge area-sampled by square pixels has MTF |sinc(f)| (f in cycles/pixel)."""
    rows, cols, angle = 64, 64, np.radians(5.0)
    sub = 16
    y, x = np.mgrid[0:rows * sub, 0:cols * sub] / sub
    edge = (x - cols / 2 - (y - rows / 2) * np.tan(angle) > 0).astype(float)
    img = edge.reshape(rows, sub, cols, sub).mean(axis=(1, 3))
    r = camsim.slanted_edge_mtf(img)
    f, m = r["frequencies_cycles_per_pixel"], r["mtf"]
    assert m[0] == pytest.approx(1.0)
    for q in [0.1, 0.25, 0.4]:
        assert np.interp(q, f, m) == pytest.approx(abs(np.sinc(q)), abs=0.02)
    assert abs(r["angle_deg"]) == pytest.approx(5.0, abs=0.2)


def test_errors_are_camsim_errors():
    with pytest.raises(camsim.CamsimError, match="kind"):
        mono_camera().expected({"kind": "no-such-kind"}, exposure_s=0.01)
    with pytest.raises(camsim.CamsimError, match="adc_bits"):
        mono_camera(adc_bits=0)
    with pytest.raises(camsim.CamsimError, match="bands"):
        camsim.Scene.from_array(np.ones((2, 2, 3)), [400.0, 500.0], 1e-6)
    with pytest.raises(camsim.CamsimError):
        camsim.Lens.load("/no/such/lens.json")


def test_progress_and_gil(repo):
    cam = mono_camera(rows=300, cols=400)
    seen = []
    cam.simulate(UNIFORM, exposure_s=0.01, seed=0, frames=3,
                 progress=lambda d, t: seen.append((d, t)))
    assert seen == [(1, 3), (2, 3), (3, 3)]
    with pytest.raises(ZeroDivisionError):
        cam.simulate(UNIFORM, exposure_s=0.01, frames=2, progress=lambda d, t: 1 / 0)
    # While one thread simulates, this one keeps running (the GIL is released).
    ticks = 0
    t = threading.Thread(target=lambda: cam.simulate(UNIFORM, exposure_s=T_FLAT, seed=0,
                                                     frames=40))
    t0 = time.perf_counter()
    t.start()
    while t.is_alive():
        ticks += 1
        time.sleep(0.001)
    t.join()
    elapsed = time.perf_counter() - t0
    if elapsed > 0.2:
        assert ticks > 0.2 * elapsed / 0.001 * 0.1, (ticks, elapsed)
