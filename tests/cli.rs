//! End-to-end tests of `camsim simulate` as ../shared/spec/capture-format.md specifies it:
//! outputs, the expected image against the closed-form baseline model, determinism across
//! thread counts, and one clear error line (and nothing written) for bad input.
use crate::util::{camsim, camsim_ok};
use serde_json::{json, Value};
use std::path::Path;

/// A small camera: constant QE 0.5 on 400–700 nm, no blur, cos⁴ fall-off.
pub fn camera(rows: usize, cols: usize) -> Value {
    json!({
        "name": "test",
        "optics": {"f_number": 2.8, "focal_length_mm": 3.0, "transmittance": 0.9,
                   "relative_illumination": "cos4", "blur": {"kind": "none"}},
        "sensor": {"rows": rows, "cols": cols, "pixel_pitch_um": 2.0, "fill_factor": 0.6,
                   "cfa": ["gb", "rg"],
                   "channels": {"r": {"wavelength_nm": [400, 700], "values": [0.5, 0.5]},
                                "g": {"wavelength_nm": [400, 700], "values": [0.5, 0.5]},
                                "b": {"wavelength_nm": [400, 700], "values": [0.5, 0.5]}},
                   "well_capacity_e": 20000, "conversion_gain_v_per_e": 5.0e-5, "voltage_swing_v": 1.0,
                   "analog_gain": 1.0, "analog_offset_v": 0.0, "adc_bits": 12, "black_level_dn": 64.0,
                   "dark_voltage_v_per_s": 1.0e-3, "read_noise_v": 1.0e-3, "dsnu_sigma_v": 1.0e-3,
                   "prnu_sigma_percent": 1.0}
    })
}

pub fn captures(radiance_w: f64, exposure_s: f64) -> Value {
    json!({"camera": "camera.json", "shots": [
        {"id": "dark", "target": {"kind": "dark"}, "exposure_s": 0.01, "frames": ["raw/dark-0.png"]},
        {"id": "flat", "exposure_s": exposure_s,
         "target": {"kind": "uniform", "radiance": {"wavelength_nm": [400, 700], "values": [radiance_w, radiance_w]}},
         "frames": ["raw/flat-0.png", "raw/flat-1.png"]}
    ]})
}

pub fn write_set(dir: &Path, camera: &Value, captures: &Value) {
    std::fs::write(
        dir.join("camera.json"),
        serde_json::to_string_pretty(camera).unwrap(),
    )
    .unwrap();
    std::fs::write(
        dir.join("captures.json"),
        serde_json::to_string_pretty(captures).unwrap(),
    )
    .unwrap();
}

fn read_exr_y(path: &Path) -> (usize, usize, Vec<f32>) {
    let (rows, cols, chans, _) = camsim_core::exr_io::read_channels(path).unwrap();
    assert_eq!(chans.len(), 1);
    assert_eq!(chans[0].0, "Y");
    (rows, cols, chans[0].1.clone())
}

/// The baseline model (spec steps 1–7, no noise) in closed form for the flat field above.
fn baseline_dn(row: usize, col: usize, rows: usize, cols: usize, radiance_w: f64, t: f64) -> f64 {
    let (h, c) = (6.626_070_15e-34, 299_792_458.0);
    // ∫ QE L_photons dλ = 0.5 · L · ∫_400^700 λ/(hc) dλ  (λ in m, dλ in nm)
    let int = 0.5 * radiance_w * (700.0f64.powi(2) - 400.0f64.powi(2)) / 2.0 * 1e-9 / (h * c);
    let (n, f, p) = (2.8, 3.0e-3, 2.0e-6);
    // cos⁴θ, tan θ = r/f, averaged over the pixel square (20×20 midpoint rule)
    let (x0, y0) = (
        (col as f64 - cols as f64 / 2.0) * p,
        (row as f64 - rows as f64 / 2.0) * p,
    );
    let mut r4 = 0.0;
    for i in 0..20 {
        for j in 0..20 {
            let x = x0 + (i as f64 + 0.5) / 20.0 * p;
            let y = y0 + (j as f64 + 0.5) / 20.0 * p;
            let cos2 = f * f / (f * f + x * x + y * y);
            r4 += cos2 * cos2 / 400.0;
        }
    }
    let e_irr = std::f64::consts::PI * 0.9 / (4.0 * n * n) * r4 * int;
    let electrons = t * p * p * 0.6 * e_irr;
    let dark = t * 1.0e-3 / 5.0e-5;
    let v = (electrons + dark).min(20000.0) * 5.0e-5;
    v.min(1.0) / 1.0 * 4095.0 + 64.0
}

#[test]
fn expected_matches_closed_form_baseline() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (64, 96);
    let (l, t) = (0.002, 0.02);
    write_set(dir.path(), &camera(rows, cols), &captures(l, t));
    let out = dir.path().join("out");
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--expected", "--out", "out"])
            .current_dir(dir.path()),
    );
    let (r, c, y) = read_exr_y(&out.join("flat.exr"));
    assert_eq!((r, c), (rows, cols));
    for &(row, col) in &[(32, 48), (0, 0), (63, 95), (10, 70)] {
        let want = baseline_dn(row, col, rows, cols, l, t);
        let got = y[row * cols + col] as f64;
        assert!(
            (got - want).abs() < 1e-4 * want,
            "pixel ({row},{col}): {got} vs {want}"
        );
    }
    // corners are darker than the centre by cos⁴
    assert!(y[0] < y[32 * cols + 48]);
    let (_, _, dark) = read_exr_y(&out.join("dark.exr"));
    let want_dark = 0.01 * 1.0e-3 / 1.0 * 4095.0 + 64.0;
    assert!((dark[100] as f64 - want_dark).abs() < 1e-4);
}

#[test]
fn frames_are_16bit_png_at_their_paths_and_deterministic_across_threads() {
    let dir = tempfile::tempdir().unwrap();
    write_set(dir.path(), &camera(48, 64), &captures(0.002, 0.02));
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = format!("out{threads}");
        camsim_ok(
            camsim()
                .args([
                    "--threads",
                    threads,
                    "simulate",
                    "captures.json",
                    "--out",
                    &out,
                    "--seed",
                    "7",
                ])
                .current_dir(dir.path()),
        );
        outs.push(dir.path().join(out));
    }
    for f in ["raw/dark-0.png", "raw/flat-0.png", "raw/flat-1.png"] {
        let a = std::fs::read(outs[0].join(f)).unwrap();
        let b = std::fs::read(outs[1].join(f)).unwrap();
        assert_eq!(a, b, "{f} differs between 1 and 2 threads");
        let frame = camsim_pipeline::frames::read_png16(&outs[0].join(f)).unwrap();
        assert_eq!((frame.rows, frame.cols), (48, 64));
    }
    // two frames of one shot differ (new temporal noise), nothing else was written
    let a = camsim_pipeline::frames::read_png16(&outs[0].join("raw/flat-0.png")).unwrap();
    let b = camsim_pipeline::frames::read_png16(&outs[0].join("raw/flat-1.png")).unwrap();
    assert_ne!(a.dn, b.dn);
    let names: Vec<_> = std::fs::read_dir(&outs[0])
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "only raw/ in the output: {names:?}");
    // another seed gives other frames
    let st = camsim()
        .args(["simulate", "captures.json", "--out", "out3", "--seed", "8"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(st.status.success());
    assert_ne!(
        std::fs::read(outs[0].join("raw/flat-0.png")).unwrap(),
        std::fs::read(dir.path().join("out3/raw/flat-0.png")).unwrap()
    );
}

/// Runs simulate on a broken set and checks: non-zero exit, one line on stderr that names the
/// file and contains `needle`, and no output folder.
fn assert_bad(dir: &Path, needles: &[&str]) {
    let st = camsim()
        .args(["simulate", "captures.json", "--out", "out"])
        .current_dir(dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr).to_string();
    assert!(!st.status.success(), "should fail: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' not in: {err}");
    }
    assert!(!dir.join("out").exists(), "nothing may be written on error");
}

#[test]
fn bad_input_gives_one_clear_line_and_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    // malformed JSON
    write_set(dir, &camera(8, 8), &captures(0.01, 0.01));
    std::fs::write(
        dir.join("captures.json"),
        "{\"camera\": \"camera.json\", \"shots\": [",
    )
    .unwrap();
    assert_bad(dir, &["captures.json", "invalid"]);
    // unknown key (misspelt prnu_sigma_percent)
    let mut cam = camera(8, 8);
    cam["sensor"]["prnu_sigma_pct"] = json!(1.0);
    write_set(dir, &cam, &captures(0.01, 0.01));
    assert_bad(dir, &["camera.json", "prnu_sigma_pct"]);
    // missing camera file
    write_set(dir, &camera(8, 8), &captures(0.01, 0.01));
    std::fs::remove_file(dir.join("camera.json")).unwrap();
    assert_bad(dir, &["camera.json", "cannot read"]);
    // non-increasing wavelengths
    let mut caps = captures(0.01, 0.01);
    caps["shots"][1]["target"]["radiance"] = json!({"wavelength_nm": [500, 400], "values": [1, 1]});
    write_set(dir, &camera(8, 8), &caps);
    assert_bad(
        dir,
        &[
            "captures.json",
            "shots[1] (flat).target.radiance",
            "increasing",
        ],
    );
    // negative radiance
    let mut caps = captures(0.01, 0.01);
    caps["shots"][1]["target"]["radiance"] =
        json!({"wavelength_nm": [400, 700], "values": [0.1, -0.2]});
    write_set(dir, &camera(8, 8), &caps);
    assert_bad(dir, &["captures.json", "negative radiance"]);
    // unknown CFA letter
    let mut cam = camera(8, 8);
    cam["sensor"]["cfa"] = json!(["gx", "rg"]);
    write_set(dir, &cam, &captures(0.01, 0.01));
    assert_bad(dir, &["camera.json", "sensor.cfa", "'x'"]);
    // a recorded frame of the wrong size
    write_set(dir, &camera(8, 8), &captures(0.01, 0.01));
    std::fs::create_dir_all(dir.join("raw")).unwrap();
    let wrong = camsim_core::RawFrame {
        rows: 4,
        cols: 8,
        adc_bits: 12,
        dn: vec![0; 32],
        layout: None,
    };
    camsim_pipeline::frames::write_png16(&dir.join("raw/flat-0.png"), &wrong).unwrap();
    assert_bad(dir, &["flat-0.png", "4×8", "8×8"]);
    // a recorded frame of the wrong bit depth (8-bit PNG)
    let img = image::GrayImage::new(8, 8);
    img.save(dir.join("raw/flat-0.png")).unwrap();
    assert_bad(dir, &["flat-0.png", "16-bit"]);
    std::fs::remove_dir_all(dir.join("raw")).unwrap();
    // unknown target kind
    let mut caps = captures(0.01, 0.01);
    caps["shots"][1]["target"] = json!({"kind": "moon"});
    write_set(dir, &camera(8, 8), &caps);
    assert_bad(dir, &["captures.json", "unknown target kind \"moon\""]);
    // adc bits beyond the 16-bit frame format
    let mut cam = camera(8, 8);
    cam["sensor"]["adc_bits"] = json!(20);
    write_set(dir, &cam, &captures(0.01, 0.01));
    assert_bad(dir, &["camera.json", "adc_bits"]);
}

#[test]
fn shipped_example_runs() {
    let dir = tempfile::tempdir().unwrap();
    let ex = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/table1/captures.json");
    camsim_ok(
        camsim()
            .args(["simulate"])
            .arg(&ex)
            .arg("--out")
            .arg(dir.path().join("o")),
    );
    let f = camsim_pipeline::frames::read_png16(&dir.path().join("o/raw/macbeth-0.png")).unwrap();
    assert_eq!((f.rows, f.cols), (480, 640));
    // auto-exposure to 90 % of the swing: the brightest pixels sit near 0.9 · 1023
    let max = *f.dn.iter().max().unwrap() as f64;
    assert!(max > 0.8 * 1023.0 && max <= 1023.0, "max DN {max}");
}

#[test]
fn frames_are_written_in_the_recording_format() {
    let dir = tempfile::tempdir().unwrap();
    let mut caps = captures(0.002, 0.02);
    caps["shots"][1]["frames"] = json!(["raw/flat-0.tif", "raw/flat-1.png"]);
    write_set(dir.path(), &camera(16, 24), &caps);
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--out", "o", "--seed", "5"])
            .current_dir(dir.path()),
    );
    let tif = camsim_pipeline::raw_input::read_frame(&dir.path().join("o/raw/flat-0.tif")).unwrap();
    assert_eq!((tif.rows, tif.cols), (16, 24));
    assert_eq!(
        &std::fs::read(dir.path().join("o/raw/flat-0.tif")).unwrap()[..2],
        b"II",
        "a TIFF file"
    );
    // same seed, shot and frame index → the same frame as when it is written as PNG
    caps["shots"][1]["frames"] = json!(["raw/flat-0.png", "raw/flat-1.png"]);
    write_set(dir.path(), &camera(16, 24), &caps);
    let st = camsim()
        .args(["simulate", "captures.json", "--out", "p", "--seed", "5"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(st.status.success());
    let png = camsim_pipeline::frames::read_png16(&dir.path().join("p/raw/flat-0.png")).unwrap();
    assert_eq!(tif.dn, png.dn);
}

/// `camsim scene`: spectral EXR of a shot's radiance and irradiance plus the §2.A linear-model
/// round-trip error; a Macbeth chart is (nearly) rank ≤ 24, so more basis terms never do worse.
#[test]
fn scene_command_writes_spectral_exr_and_linear_model_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera(48, 72);
    cam["optics"]["blur"] = json!({"kind": "diffraction"});
    let caps = json!({"camera": "camera.json", "shots": [{"id": "chart", "exposure_s": 0.01,
        "target": {"kind": "macbeth", "illuminant": "D65", "mean_luminance_cd_m2": 100, "patch_fraction": 0.8},
        "frames": ["c.png"]}]});
    write_set(dir.path(), &cam, &caps);
    let mut errs = Vec::new();
    for k in ["1", "3", "6"] {
        let out = format!("s{k}");
        camsim_ok(
            camsim()
                .args([
                    "scene",
                    "captures.json",
                    "--shot",
                    "chart",
                    "--basis",
                    k,
                    "--out",
                    &out,
                ])
                .current_dir(dir.path()),
        );
        let rep: Value = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join(&out).join("chart_scene.json")).unwrap(),
        )
        .unwrap();
        assert!((rep["mean_luminance_cd_m2"].as_f64().unwrap() - 100.0).abs() < 0.1);
        errs.push(rep["linear_model"]["relative_rms_error"].as_f64().unwrap());
        let e = camsim_core::exr_io::read_spectral_exr(
            &dir.path().join(&out).join("chart_radiance.exr"),
        )
        .unwrap();
        assert_eq!(e.emissive_units, "W.m^-2.sr^-1");
        assert_eq!(e.grid.len(), 31);
        let i = camsim_core::exr_io::read_spectral_exr(
            &dir.path().join(&out).join("chart_irradiance.exr"),
        )
        .unwrap();
        assert_eq!(i.emissive_units, "W.m^-2");
    }
    assert!(errs[0] > errs[1] && errs[1] >= errs[2], "errors {errs:?}");
    assert!(
        errs[2] < 0.05,
        "6 basis functions capture Macbeth radiance to a few %: {errs:?}"
    );
}

/// Headerless raw frames: written and read back in the layout `raw_format` gives, and the
/// real 768×512 RGGB uint16le mosaic in ../shared reads with a plausible 14-bit range.
#[test]
fn headerless_raw_frames_round_trip_and_real_raw_reads() {
    let dir = tempfile::tempdir().unwrap();
    let mut caps = captures(0.002, 0.02);
    caps["shots"][1]["frames"] = json!(["raw/flat-0.raw", "raw/flat-1.png"]);
    caps["raw_format"] = json!({"bits_per_sample": 16, "endianness": "big", "header_bytes": 4});
    write_set(dir.path(), &camera(16, 24), &caps);
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--out", "o", "--seed", "5"])
            .current_dir(dir.path()),
    );
    let bytes = std::fs::read(dir.path().join("o/raw/flat-0.raw")).unwrap();
    assert_eq!(bytes.len(), 4 + 16 * 24 * 2);
    let set =
        camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None).unwrap();
    let fmt = set.raw_format.unwrap();
    let f =
        camsim_pipeline::raw_input::read_raw(&dir.path().join("o/raw/flat-0.raw"), &fmt).unwrap();
    assert_eq!(u16::from_be_bytes([bytes[4], bytes[5]]), f.dn[0]);
    assert!(f.dn.iter().any(|&v| v > 64), "a lit frame");
    // a raw file of the wrong length is one clear error
    let bad = camsim_pipeline::raw_input::RawFormat { rows: 10, ..fmt };
    let e = camsim_pipeline::raw_input::read_raw(&dir.path().join("o/raw/flat-0.raw"), &bad)
        .unwrap_err()
        .one_line();
    assert!(e.contains("flat-0.raw") && e.contains("bytes"), "{e}");
    // real data (MIT): a 14-bit Nikon crop, black 600, white 15520 upstream
    let real = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(
        "../shared/data/real/captures/mushfiqulalam_bayer/DSC_1339_768x512_rggb_uint16le.raw",
    );
    let fmt = camsim_pipeline::raw_input::RawFormat {
        rows: 512,
        cols: 768,
        bytes_per_sample: 2,
        little_endian: true,
        header_bytes: 0,
    };
    let r = camsim_pipeline::raw_input::read_raw(&real, &fmt).unwrap();
    let max = *r.dn.iter().max().unwrap();
    let min = *r.dn.iter().min().unwrap();
    assert!(
        max < 16384 && min >= 400 && max > 2000,
        "14-bit range with a ~600 pedestal: {min}..{max}"
    );
}
