//! Every example of issue 16 as a regression test (acceptance 1): each gives one clear error
//! line (exit 2) or a correct physical result (exit 0, checked), run under
//! `ulimit -v 8000000` with a 30 s kill timeout — no panic, abort or hang.
use super::{camsim_limited, Outcome};
use crate::cli::{camera, captures, write_set};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// A capture folder with `cam` and `caps` (frames not written).
fn set(cam: &Value, caps: &Value) -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    write_set(d.path(), cam, caps);
    d
}

fn simulate(d: &Path) -> Outcome {
    camsim_limited(&["simulate", "captures.json", "--out", "sim"], d)
}

/// One error line naming every `keys`, exit status 2, nothing written to `sim`.
#[track_caller]
fn refused(o: &Outcome, keys: &[&str]) {
    o.assert_refused(keys);
}

fn base() -> (Value, Value) {
    (camera(8, 8), captures(1.0, 0.01))
}

#[test]
fn huge_sensors_are_refused_by_the_budget() {
    for (rows, cols) in [
        (json!(1_000_000_000u64), json!(8)),
        (json!(100_000), json!(100_000)),
        (json!(u64::MAX), json!(8)),
    ] {
        let (mut cam, caps) = base();
        cam["sensor"]["rows"] = rows;
        cam["sensor"]["cols"] = cols;
        let d = set(&cam, &caps);
        refused(
            &simulate(d.path()),
            &["camera.json", "sensor.rows/cols", "memory", "--max-memory"],
        );
        assert!(!d.path().join("sim").exists());
    }
}

#[test]
fn huge_blurs_are_refused_by_the_budget() {
    for blur in [
        json!({"kind": "gaussian", "sigma_um": 1e6}),
        json!({"kind": "gaussian", "sigma_um": 1e308}),
        json!({"kind": "pillbox", "width_um": 1e9}),
    ] {
        let (mut cam, caps) = base();
        cam["optics"]["blur"] = blur.clone();
        let d = set(&cam, &caps);
        refused(&simulate(d.path()), &["optics.blur", "memory"]);
    }
    let (mut cam, caps) = base();
    cam["optics"]["diffuser"] = json!({"fwhm_um": 1e9});
    let d = set(&cam, &caps);
    refused(&simulate(d.path()), &["optics.blur", "memory"]);
}

#[test]
fn bad_wavelength_grids_are_refused() {
    let (cam, mut caps) = base();
    caps["simulation"] =
        json!({"wavelength_nm": {"start_nm": 400, "stop_nm": 700, "step_nm": 1e-9}});
    let d = set(&cam, &caps);
    refused(&simulate(d.path()), &["simulation.wavelength_nm", "bands"]);
    // one band (start = stop) has no width and would lose all the light
    caps["simulation"] = json!({"wavelength_nm": {"start_nm": 550, "stop_nm": 550, "step_nm": 10}});
    let d = set(&cam, &caps);
    refused(
        &simulate(d.path()),
        &["simulation.wavelength_nm", "two wavelengths"],
    );
}

/// Found by the captures fuzzer (issue 16, acceptance 2): a radiance sampled at
/// [400, 1.8e308] nm made the conversion to photons refine the spectrum every 2 nm, for ever.
/// Wavelengths past 1 mm (core::spectrum::MAX_WAVELENGTH_NM) are refused.
#[test]
fn a_spectrum_reaching_1e308_nm_is_refused_at_once() {
    let (cam, mut caps) = base();
    caps["shots"][1]["target"]["radiance"]["wavelength_nm"] = json!([400, 1.7976931348623157e308]);
    let d = set(&cam, &caps);
    let o = simulate(d.path());
    refused(
        &o,
        &[
            "captures.json",
            "shots[1] (flat).target.radiance",
            "wavelength_nm[1]",
            "1 mm",
        ],
    );
    assert!(
        o.elapsed.as_secs_f64() < 10.0,
        "{:.1} s",
        o.elapsed.as_secs_f64()
    );
}

fn run_config(d: &Path, cfg: &Value) -> Outcome {
    std::fs::write(d.join("run.json"), cfg.to_string()).unwrap();
    camsim_limited(&["run", "run.json", "--out", "o"], d)
}

#[test]
fn run_display_and_render_budgets() {
    let d = tempfile::tempdir().unwrap();
    // documented as legal, but 640×480 × 32² samples × bands does not fit in 8 GB
    refused(
        &run_config(
            d.path(),
            &json!({"target": {"kind": "macbeth"}, "display": {"samples_per_pixel": 32}}),
        ),
        &["run.json", "display.samples_per_pixel", "memory"],
    );
    let scene = repo().join("scenes/uniform_emitter.gltf");
    refused(
        &run_config(
            d.path(),
            &json!({"render": {"scene": scene, "spp": 4_000_000_000u64}}),
        ),
        &["run.json", "render.spp", "samples", "--max-work"],
    );
    // radiance of 1e30 W/(sr·m²·nm) (the scene EXR used to be all +Inf)
    refused(
        &run_config(
            d.path(),
            &json!({"target": {"kind": "uniform", "radiance": 1e30}}),
        ),
        &["radiance", "over the limit"],
    );
    assert!(!d.path().join("o").exists());
}

#[test]
fn huge_study_grids_are_refused_before_enumeration() {
    let d = tempfile::tempdir().unwrap();
    let cam: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_codesign/camera.json")).unwrap(),
    )
    .unwrap();
    // 10 parameters × 10 values = 1e10 points
    let params: Vec<Value> = (0..10)
        .map(|i| json!({"name": format!("p{i}"), "path": format!("conditions.x{i}"), "values": (0..10).collect::<Vec<_>>()}))
        .collect();
    let spec = json!({"point": {"camera": cam, "conditions": {"luminance_cd_m2": 100, "exposure_s": 0.01},
                                "metrics": {"snr": {}}},
                      "parameters": params});
    std::fs::write(d.path().join("s.json"), spec.to_string()).unwrap();
    refused(
        &camsim_limited(
            &["study", "s.json", "--out", "o", "--max-points", "1"],
            d.path(),
        ),
        &["s.json", "parameters", "1.000e10 points", "memory"],
    );
}

#[test]
fn study_include_cycles_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    // a file that includes itself
    std::fs::write(
        p.join("self.json"),
        json!({"point": {"camera": {"$file": "self.json"}}}).to_string(),
    )
    .unwrap();
    refused(
        &camsim_limited(&["study", "self.json", "--out", "o"], p),
        &["self.json", "cycle"],
    );
    // a → b → a
    std::fs::write(
        p.join("a.json"),
        json!({"x": {"$file": "b.json"}}).to_string(),
    )
    .unwrap();
    std::fs::write(
        p.join("b.json"),
        json!({"y": {"$file": "a.json"}}).to_string(),
    )
    .unwrap();
    std::fs::write(
        p.join("s.json"),
        json!({"point": {"camera": {"$file": "a.json"}}}).to_string(),
    )
    .unwrap();
    refused(
        &camsim_limited(&["study", "s.json", "--out", "o"], p),
        &["s.json", "a.json", "cycle"],
    );
}

fn lens() -> String {
    repo()
        .join("lenses/cooke_triplet_sasian_50mm_f4.json")
        .display()
        .to_string()
}

#[test]
fn lens_commands_are_budgeted() {
    let d = tempfile::tempdir().unwrap();
    let l = lens();
    refused(
        &camsim_limited(
            &[
                "lens",
                "spot",
                &l,
                "--field-fraction",
                "0",
                "--wavelength-nm",
                "587.6",
                "--rays",
                "1000000000000",
            ],
            d.path(),
        ),
        &["--rays"],
    );
    refused(
        &camsim_limited(
            &["lens", "report", &l, "--grid", "100000", "--out", "o"],
            d.path(),
        ),
        &["--grid"],
    );
    refused(
        &camsim_limited(
            &[
                "lens",
                "field-model",
                &l,
                "--psf-n",
                "100000",
                "--out",
                "fm.json",
            ],
            d.path(),
        ),
        &["--psf-n", "memory"],
    );
    assert!(!d.path().join("o").exists());
    // an MTF frequency of 1e308 cycles/mm used to index out of bounds: far beyond the cutoff
    // the MTF is 0 (a physical result); a non-finite or negative one is refused
    let o = camsim_limited(
        &["lens", "report", &l, "--mtf-lp-mm", "0,1e308", "--json"],
        d.path(),
    );
    o.assert_ok();
    refused(
        &camsim_limited(
            &["lens", "report", &l, "--mtf-lp-mm=-5", "--json"],
            d.path(),
        ),
        &["--mtf-lp-mm"],
    );
}

#[test]
fn lens_files_with_unknown_keys_or_a_stray_primary_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(lens()).unwrap()).unwrap();
    v["surfaces"][0]["conik"] = json!(-1.0);
    std::fs::write(d.path().join("typo.json"), v.to_string()).unwrap();
    refused(
        &camsim_limited(&["lens", "report", "typo.json", "--json"], d.path()),
        &["typo.json", "surfaces[0].conik", "unknown key"],
    );
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(lens()).unwrap()).unwrap();
    v["wavelengths_nm"] = json!([486.1, 587.6, 656.3]);
    v["primary_nm"] = json!(550.0);
    std::fs::write(d.path().join("primary.json"), v.to_string()).unwrap();
    refused(
        &camsim_limited(&["lens", "report", "primary.json", "--json"], d.path()),
        &["primary.json", "primary_nm"],
    );
}

/// uniform_emitter.gltf (+ .bin) copied into `d` with `edit` applied.
fn scene(d: &Path, edit: impl FnOnce(&mut Value)) -> String {
    let s = repo().join("scenes");
    std::fs::copy(s.join("uniform_emitter.bin"), d.join("uniform_emitter.bin")).unwrap();
    let mut v: Value =
        serde_json::from_str(&std::fs::read_to_string(s.join("uniform_emitter.gltf")).unwrap())
            .unwrap();
    edit(&mut v);
    std::fs::write(d.join("scene.gltf"), v.to_string()).unwrap();
    "scene.gltf".into()
}

fn render(d: &Path, scene: &str, spp: &str) -> Outcome {
    camsim_limited(
        &[
            "render", scene, "--width", "8", "--spp", spp, "--out", "r.exr",
        ],
        d,
    )
}

#[test]
fn hostile_gltf_scenes() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    for a in [1e-9, 0.0, -1.0] {
        let s = scene(p, |v| {
            v["cameras"][0]["perspective"]["aspectRatio"] = json!(a)
        });
        refused(&render(p, &s, "1"), &["scene.gltf", "aspectRatio"]);
    }
    let s = scene(p, |v| {
        v["nodes"][2]["rotation"] = json!([0.0, 0.0, 0.0, 0.0])
    });
    refused(
        &render(p, &s, "1"),
        &["scene.gltf", "rotation", "unit quaternion"],
    );
    let s = scene(p, |v| {
        v["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(999)
    });
    refused(&render(p, &s, "1"), &["scene.gltf"]);
    let s = scene(p, |v| {
        v["materials"][0]["extras"]["spectral_emission"]["values"] = json!([1e308, 1e308])
    });
    refused(&render(p, &s, "1"), &["scene.gltf", "spectral_emission"]);
    let s = scene(p, |_| {});
    refused(&render(p, &s, "4000000000"), &["--spp", "--max-work"]);
    assert!(!p.join("r.exr").exists());
}

/// A 1×1 spectral EXR whose header then claims a 100000 × 100000 data window (a few hundred
/// bytes on disk).
fn lying_exr(path: &Path) {
    let grid = camsim_core::spectrum::WavelengthGrid::regular(400.0, 700.0, 300.0).unwrap();
    let img = camsim_core::image::SpectralImage::new(
        1,
        1,
        camsim_core::image::SpectralBasis::Bands(grid),
        vec![vec![1.0], vec![1.0]],
    )
    .unwrap();
    camsim_core::exr_io::write_spectral_exr(path, &img, camsim_core::exr_io::RADIANCE_UNITS, None)
        .unwrap();
    let mut b = std::fs::read(path).unwrap();
    let key = b"dataWindow\0box2i\0";
    let i = b
        .windows(key.len())
        .position(|w| w == key)
        .expect("dataWindow")
        + key.len()
        + 4;
    b[i + 8..i + 12].copy_from_slice(&99_999i32.to_le_bytes());
    b[i + 12..i + 16].copy_from_slice(&99_999i32.to_le_bytes());
    std::fs::write(path, b).unwrap();
}

#[test]
fn an_exr_claiming_a_huge_window_is_refused_from_its_header() {
    let (cam, mut caps) = base();
    caps["shots"][1]["target"] = json!({"kind": "image", "file": "big.exr"});
    let d = set(&cam, &caps);
    lying_exr(&d.path().join("big.exr"));
    assert!(std::fs::metadata(d.path().join("big.exr")).unwrap().len() < 10_000);
    refused(&simulate(d.path()), &["big.exr", "data windows"]);
}

#[test]
fn raw_format_sizes_and_headers_are_checked() {
    let (cam, mut caps) = base();
    caps["raw_format"] = json!({"bits_per_sample": 16, "header_bytes": u64::MAX});
    let d = set(&cam, &caps);
    refused(&simulate(d.path()), &["raw_format.header_bytes"]);
    refused(
        &camsim_limited(&["validate", "captures.json", "--out", "v"], d.path()),
        &["raw_format.header_bytes"],
    );
    caps["raw_format"] =
        json!({"bits_per_sample": 16, "rows": 1_000_000_000u64, "cols": 1_000_000_000u64});
    let d = set(&cam, &caps);
    refused(&simulate(d.path()), &["raw_format.rows/cols"]);
}

/// The DN of a written frame.
fn frame_dn(p: &Path) -> Vec<u16> {
    camsim_pipeline::frames::read_png16(p).unwrap().dn
}

#[test]
fn overflowing_light_saturates_and_never_hangs() {
    let max_dn = 4095;
    // exposure 1e308 s: the flat field is at full well → ADC maximum everywhere
    let (cam, caps) = base();
    let mut caps2 = caps.clone();
    caps2["shots"][1]["exposure_s"] = json!(1e308);
    let d = set(&cam, &caps2);
    let o = simulate(d.path());
    o.assert_ok();
    for f in ["raw/flat-0.png", "raw/flat-1.png"] {
        let dn = frame_dn(&d.path().join("sim").join(f));
        assert!(dn.iter().all(|&v| v == max_dn), "{f}: {:?}", &dn[..8]);
    }
    // dark voltage 1e308 V/s with a 10 s exposure: the dark frame saturates too
    let mut cam2 = cam.clone();
    cam2["sensor"]["dark_voltage_v_per_s"] = json!(1e308);
    let mut caps3 = caps.clone();
    caps3["shots"][0]["exposure_s"] = json!(10.0);
    let d = set(&cam2, &caps3);
    simulate(d.path()).assert_ok();
    let dn = frame_dn(&d.path().join("sim/raw/dark-0.png"));
    assert!(dn.iter().all(|&v| v == max_dn), "{:?}", &dn[..8]);
    // a mean luminance of 1e308 cd/m² is refused (the sun's disc is 1.6e9)
    let mut caps4 = caps.clone();
    caps4["shots"][1]["target"]["mean_luminance_cd_m2"] = json!(1e308);
    let d = set(&cam, &caps4);
    refused(&simulate(d.path()), &["mean_luminance_cd_m2"]);
    // radiance 1e18 used to give a black frame
    let d = set(&cam, &captures(1e18, 0.01));
    refused(&simulate(d.path()), &["radiance", "over the limit"]);
}

#[test]
fn demo_with_an_absurd_prnu_finishes() {
    let d = tempfile::tempdir().unwrap();
    let o = camsim_limited(
        &[
            "demo",
            "diagnose",
            "--effect",
            "prnu=1e308",
            "--rows",
            "8",
            "--cols",
            "8",
            "--out",
            "set",
        ],
        d.path(),
    );
    // either refused in one line, or a set whose frames are valid
    if o.code == Some(0) {
        assert!(d.path().join("set/captures.json").is_file());
    } else {
        o.assert_refused(&["prnu"]);
    }
}

#[test]
fn absurd_thread_counts_are_refused() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &camsim_limited(&["--threads", "10000", "run", "--out", "o"], d.path()),
        &["--threads", "1–256"],
    );
}

#[test]
fn silent_wrong_results_are_now_errors() {
    let (cam, caps) = base();
    let with_target = |t: Value| {
        let mut c = caps.clone();
        c["shots"][1]["target"] = t;
        c
    };
    for (t, key) in [
        (
            json!({"kind": "point_array", "radiance": 1.0, "spacing_px": 0}),
            "spacing_px",
        ),
        (
            json!({"kind": "grid_lines", "radiance": 1.0, "spacing_px": -3}),
            "spacing_px",
        ),
        (
            json!({"kind": "dark", "mean_luminance_cd_m2": 10}),
            "mean_luminance_cd_m2",
        ),
        (
            json!({"kind": "uniform", "radiance": 0.0, "mean_luminance_cd_m2": 10}),
            "mean_luminance_cd_m2",
        ),
    ] {
        let d = set(&cam, &with_target(t));
        refused(&simulate(d.path()), &[key]);
    }
    for (name, key) in [("raw/a.jpg", "frames[0]"), ("raw/noext", "frames[0]")] {
        let mut c = caps.clone();
        c["shots"][1]["frames"] = json!([name]);
        let d = set(&cam, &c);
        refused(&simulate(d.path()), &[key, name]);
    }
    // .dng frames are readable recordings but simulate cannot write DNG (it used to write PNG
    // bytes under that name)
    let mut c = caps.clone();
    c["shots"][1]["frames"] = json!(["raw/a.dng"]);
    let d = set(&cam, &c);
    refused(&simulate(d.path()), &["a.dng", ".dng"]);
    assert!(!d.path().join("sim").exists());
}

#[test]
fn calibrate_refuses_a_frame_of_the_wrong_size() {
    let (cam, caps) = base();
    let d = set(&cam, &caps);
    simulate(d.path()).assert_ok();
    // the recording: simulated frames, one replaced by a 4×4 frame
    let rec = d.path().join("sim");
    std::fs::copy(d.path().join("camera.json"), rec.join("camera.json")).unwrap();
    std::fs::copy(d.path().join("captures.json"), rec.join("captures.json")).unwrap();
    let small = camsim_core::RawFrame {
        rows: 4,
        cols: 4,
        adc_bits: 12,
        dn: vec![100; 16],
        layout: None,
    };
    camsim_pipeline::frames::write_png16(&rec.join("raw/flat-1.png"), &small).unwrap();
    refused(
        &camsim_limited(&["calibrate", "captures.json", "--out", "cal"], &rec),
        &["flat-1.png", "4×4", "8×8"],
    );
    assert!(!rec.join("cal").exists());
}

#[test]
fn noise_profiles_leaves_nothing_after_an_error() {
    let d = tempfile::tempdir().unwrap();
    let file = repo().join("../shared/data/real/noise/darktable_noiseprofiles.json");
    assert!(
        file.is_file(),
        "{} (ln -s /work/shared ../shared)",
        file.display()
    );
    let f = file.display().to_string();
    refused(
        &camsim_limited(
            &[
                "noise-profiles",
                &f,
                "--camera",
                "no such camera",
                "--out",
                "np",
            ],
            d.path(),
        ),
        &["no such camera"],
    );
    assert!(!d.path().join("np").exists(), "a figure was left behind");
}
