"""Acceptance 2: for the same inputs and seed, Python and the CLI give identical results,
pixel for pixel and number for number."""
import json
import shutil

import numpy as np
import pytest

import camsim
from conftest import run_cli

# A small sensor keeps this quick; the optics (diffraction, cos4) and noise terms are those of
# examples/table1 so every stage runs.
SMALL = {"rows": 60, "cols": 80}


def small_set(repo, tmp_path, frames_ext="raw"):
    cam = json.loads((repo / "examples/table1/camera.json").read_text())
    cam["sensor"].update(SMALL)
    (tmp_path / "camera.json").write_text(json.dumps(cam))
    shots = [
        {"id": "dark", "target": {"kind": "dark"}, "exposure_s": 0.01,
         "frames": [f"dark-0.{frames_ext}", f"dark-1.{frames_ext}"]},
        {"id": "flat", "exposure_s": 0.02,
         "target": {"kind": "uniform", "radiance": {"wavelength_nm": [400, 700],
                                                    "values": [0.01, 0.01]}},
         "frames": [f"flat-0.{frames_ext}"]},
        {"id": "macbeth", "auto_exposure": 0.9,
         "target": {"kind": "macbeth", "illuminant": "tungsten",
                    "mean_luminance_cd_m2": 61, "patch_fraction": 0.8},
         "frames": [f"macbeth-0.{frames_ext}", f"macbeth-1.{frames_ext}"]},
    ]
    caps = {"camera": "camera.json", "shots": shots}
    if frames_ext == "raw":
        caps["raw_format"] = {"bits_per_sample": 16, "endianness": "little"}
    (tmp_path / "captures.json").write_text(json.dumps(caps))
    return tmp_path / "captures.json", caps


def read_raw(path, rows, cols):
    return np.fromfile(path, dtype="<u2").reshape(rows, cols)


def test_frames_identical_to_cli(repo, cli, tmp_path):
    caps_path, caps = small_set(repo, tmp_path)
    out = tmp_path / "cli_out"
    rc, _, err = run_cli(cli, "simulate", caps_path, "--out", out, "--seed", 7)
    assert rc == 0, err
    res = camsim.CaptureSet.load(str(caps_path)).simulate(seed=7)
    n_px = 0
    for shot in caps["shots"]:
        got = res.images[shot["id"]]
        assert got.dtype == np.uint16 and got.shape == (len(shot["frames"]), 60, 80)
        for k, f in enumerate(shot["frames"]):
            want = read_raw(out / f, 60, 80)
            assert np.array_equal(got[k], want), f"{shot['id']} frame {k} differs"
            n_px += want.size
    assert n_px == 5 * 60 * 80
    # The frames are not trivially equal: different seeds differ, noise is present.
    other = camsim.CaptureSet.load(str(caps_path)).simulate(seed=8).images["flat"]
    assert not np.array_equal(other, res.images["flat"])


def test_png_frames_identical_to_cli(repo, cli, tmp_path):
    caps_path, caps = small_set(repo, tmp_path, frames_ext="png")
    out = tmp_path / "cli_out"
    rc, _, err = run_cli(cli, "simulate", caps_path, "--out", out, "--seed", 3)
    assert rc == 0, err
    cs = camsim.CaptureSet.load(str(caps_path))
    res = cs.simulate(seed=3)
    for shot in caps["shots"]:
        for k, f in enumerate(shot["frames"]):
            assert np.array_equal(res.images[shot["id"]][k], camsim.read_frame(str(out / f)))
    # CaptureSet.write is `camsim simulate`: byte-identical files.
    out_py = tmp_path / "py_out"
    files = cs.write(str(out_py), seed=3)
    assert len(files) == 5
    for f in files:
        assert (out_py / f).read_bytes() == (out / f).read_bytes()


def test_expected_identical_to_cli(repo, cli, tmp_path):
    caps_path, caps = small_set(repo, tmp_path)
    out = tmp_path / "cli_exp"
    rc, _, err = run_cli(cli, "simulate", caps_path, "--out", out, "--expected")
    assert rc == 0, err
    res = camsim.CaptureSet.load(str(caps_path)).simulate(expected=True)
    for shot in caps["shots"]:
        want = camsim.read_exr_channels(str(out / f"{shot['id']}.exr"))["Y"]
        got = res.images[shot["id"]]
        assert got.dtype == np.float32 and got.shape == (60, 80)
        assert np.array_equal(got, want)
    # The expected image is the mean of the frames: a bright shot is far above black.
    assert res.images["macbeth"].max() > 10 * res.images["dark"].max()


def test_single_shot_camera_api_matches_cli(repo, cli, tmp_path):
    """Camera.simulate(target, ...) is a one-shot capture set: same frames as the CLI."""
    caps_path, caps = small_set(repo, tmp_path)
    shot = caps["shots"][2]
    one = dict(caps, shots=[shot])
    (tmp_path / "one.json").write_text(json.dumps(one))
    out = tmp_path / "one_out"
    rc, _, err = run_cli(cli, "simulate", tmp_path / "one.json", "--out", out, "--seed", 11)
    assert rc == 0, err
    cam = camsim.Camera.load(str(tmp_path / "camera.json"))
    got = cam.simulate(shot["target"], auto_exposure=0.9, seed=11, frames=2)
    for k, f in enumerate(shot["frames"]):
        assert np.array_equal(got[k], read_raw(out / f, 60, 80))
    exp = cam.expected(shot["target"], auto_exposure=0.9)
    rc, _, err = run_cli(cli, "simulate", tmp_path / "one.json", "--out", tmp_path / "e",
                         "--expected")
    assert rc == 0, err
    assert np.array_equal(exp, camsim.read_exr_channels(str(tmp_path / "e/macbeth.exr"))["Y"])


def test_calibrate_numbers_identical_to_cli(repo, cli, tmp_path):
    caps_path, _ = small_set(repo, tmp_path)
    rc, _, err = run_cli(cli, "simulate", caps_path, "--out", tmp_path, "--seed", 5)
    assert rc == 0, err
    rc, _, err = run_cli(cli, "calibrate", caps_path, "--out", tmp_path / "cal_cli")
    assert rc == 0, err
    summary = camsim.CaptureSet.load(str(caps_path)).calibrate(str(tmp_path / "cal_py"))
    want = json.loads((tmp_path / "cal_cli/calibration.json").read_text())
    assert summary == want
    assert (tmp_path / "cal_py/calibration.json").read_text() == \
        (tmp_path / "cal_cli/calibration.json").read_text()


def test_lens_report_numbers_identical_to_cli(repo, cli, tmp_path):
    lens_path = repo / "lenses/double_gauss_50mm_f2.json"
    rc, out, err = run_cli(cli, "lens", "report", lens_path, "--json")
    assert rc == 0, err
    want = json.loads(out)
    got = camsim.Lens.load(str(lens_path)).report()
    assert got == want


def test_errors_carry_the_cli_message(repo, cli, tmp_path):
    bad = json.loads((repo / "examples/table1/camera.json").read_text())
    bad["sensor"]["adc_bits"] = 40
    (tmp_path / "camera.json").write_text(json.dumps(bad))
    caps = {"camera": "camera.json", "shots": [
        {"id": "d", "target": {"kind": "dark"}, "exposure_s": 0.01, "frames": ["d.png"]}]}
    (tmp_path / "captures.json").write_text(json.dumps(caps))
    rc, _, err = run_cli(cli, "simulate", tmp_path / "captures.json", "--out", tmp_path / "o")
    assert rc == 2
    cli_msg = err.strip().splitlines()[-1].removeprefix("camsim: error: ")
    with pytest.raises(camsim.CamsimError) as e:
        camsim.CaptureSet.load(str(tmp_path / "captures.json"))
    assert str(e.value) == cli_msg
    assert "adc_bits" in cli_msg
    # A bad target key: same message from the captures file and from the camera API path.
    caps["shots"][0]["target"] = {"kind": "uniform", "radiance": 1.0, "colour": 3}
    (tmp_path / "camera.json").write_text((repo / "examples/table1/camera.json").read_text())
    (tmp_path / "captures.json").write_text(json.dumps(caps))
    rc, _, err = run_cli(cli, "simulate", tmp_path / "captures.json", "--out", tmp_path / "o")
    assert rc == 2
    cli_msg = err.strip().splitlines()[-1].removeprefix("camsim: error: ")
    with pytest.raises(camsim.CamsimError) as e:
        camsim.CaptureSet.load(str(tmp_path / "captures.json"))
    assert str(e.value) == cli_msg and ".colour" in cli_msg
