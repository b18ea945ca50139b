//! EMVA 1288 (Release 4.0 Linear): `camsim emva1288` and `camsim calibrate --emva1288`
//! against the reference implementation `emva1288` 1.0.2 (installed into .venv-emva1288 by
//! tools/emva1288_setup.sh), against the reference's own camera simulator, and against the
//! configured camera (docs/emva1288.md).
use crate::util::{camsim, camsim_ok};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The reference's python, installing it when missing (idempotent).
fn reference_python() -> PathBuf {
    let setup = std::process::Command::new("bash")
        .arg(repo().join("tools/emva1288_setup.sh"))
        .output()
        .unwrap();
    assert!(
        setup.status.success(),
        "tools/emva1288_setup.sh failed: {}",
        String::from_utf8_lossy(&setup.stderr)
    );
    std::env::var_os("CAMSIM_EMVA1288_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv-emva1288"))
        .join("bin/python")
}

fn reference(python: &Path, args: &[&str]) -> Value {
    let o = std::process::Command::new(python)
        .arg(repo().join("tools/emva1288_ref.py"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "emva1288_ref.py {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// CI size: 48 × 64 pixels, 50 steps to saturation (the standard's minimum), L = 16.
const CI: [&str; 8] = [
    "--rows",
    "48",
    "--cols",
    "64",
    "--steps",
    "50",
    "--spatial-frames",
    "16",
];

fn cameras() -> [(&'static str, PathBuf); 3] {
    [
        ("table1", repo().join("examples/table1/camera.json")),
        (
            "high_gain",
            repo().join("examples/emva1288/high_gain_camera.json"),
        ),
        (
            "strong_prnu_dark",
            repo().join("examples/emva1288/strong_prnu_dark_camera.json"),
        ),
    ]
}

fn run_emva(camera: &Path, out: &Path, extra: &[&str]) -> Value {
    let o = camsim()
        .arg("emva1288")
        .arg(camera)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "camsim emva1288 {}: {}",
        camera.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    datasheet(out)
}

fn datasheet(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("datasheet.json")).unwrap()).unwrap()
}

fn value(ds: &Value, name: &str) -> (f64, f64) {
    let v = &ds["values"][name];
    (
        v["value"].as_f64().unwrap_or(f64::NAN),
        v["uncertainty"].as_f64().unwrap_or(f64::NAN),
    )
}

/// Every scalar of the reference's datasheet that camsim also reports agrees within 1 % or
/// camsim's stated uncertainty, whichever is larger. The reference is evaluated with the
/// saturation point at the variance maximum (the standard's definition); where its own
/// search picks another point, that point must lie on the saturated plateau (variance below
/// 5 % of the maximum), the known behaviour of its backward search (docs/emva1288.md).
fn compare_with_reference(ds: &Value, r: &Value, label: &str) -> usize {
    let std_vals = &r["values_standard_saturation"];
    let s2: Vec<f64> = r["s2_y"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let sat = ds["temporal"]["saturation_index"].as_u64().unwrap() as usize;
    assert_eq!(
        std_vals["index_u_ysat"].as_f64().unwrap() as usize,
        sat,
        "{label}: saturation point"
    );
    let own = r["values"]["index_u_ysat"].as_f64().unwrap() as usize;
    if own != sat {
        // pair variances of N pixels scatter by √(2/N) relative
        let n_px = (ds["spatial"]["bright"]["rows"].as_f64().unwrap()
            * ds["spatial"]["bright"]["cols"].as_f64().unwrap()) as f64;
        let peak_noise = 3.0 * (2.0 / n_px).sqrt() * s2[sat];
        assert!(
            s2[own] < 0.05 * s2[sat] || s2[sat] - s2[own] <= peak_noise,
            "{label}: the reference's own saturation point {own} (σ² = {}) is neither on the \
             plateau beyond the variance maximum {sat} (σ² = {}) nor statistically as high",
            s2[own],
            s2[sat]
        );
        eprintln!(
            "{label}: reference's own saturation search stops at point {own} \
             (σ² = {:.3} DN²); the variance maximum is point {sat} (σ² = {:.1} DN²)",
            s2[own], s2[sat]
        );
    }
    let mut compared = 0;
    for (name, rv) in std_vals.as_object().unwrap() {
        if ds["values"].get(name).is_none() {
            continue;
        }
        let (cv, cu) = value(ds, name);
        let Some(rv) = rv.as_f64() else {
            assert!(
                cv.is_nan(),
                "{label}: {name}: reference gives no value (negative variance), camsim {cv}"
            );
            continue;
        };
        let tol = (0.01 * rv.abs()).max(if cu.is_finite() { cu } else { 0.0 });
        assert!(
            (cv - rv).abs() <= tol,
            "{label}: {name}: camsim {cv} vs emva1288 {rv} (tolerance {tol})"
        );
        compared += 1;
    }
    compared
}

/// Acceptance 1: the Table 1 camera, a high-gain low-noise camera and a camera with strong
/// PRNU and dark current; camsim writes the series, both analyse the same images.
#[test]
fn emva1288_matches_the_reference_implementation_on_three_cameras() {
    let python = reference_python();
    let dir = tempfile::tempdir().unwrap();
    for (label, cam) in cameras() {
        let out = dir.path().join(label);
        let t0 = std::time::Instant::now();
        let ds = run_emva(&cam, &out, &CI);
        let t_camsim = t0.elapsed();
        let r = reference(
            &python,
            &[
                "analyse",
                out.join("EMVA1288descriptor.txt").to_str().unwrap(),
            ],
        );
        let n = compare_with_reference(&ds, &r, label);
        assert!(n >= 25, "{label}: only {n} numbers compared");
        eprintln!(
            "{label}: {n} datasheet numbers agree; camsim (simulate + analyse) {t_camsim:?}, \
             emva1288 analysis {:.2} s",
            r["seconds"].as_f64().unwrap()
        );
        // the report and the reference-format results exist and are complete
        let xml = std::fs::read_to_string(out.join("results.xml")).unwrap();
        assert!(xml.contains("<K>") && xml.contains("<PRNU1288>") && xml.contains("<u_I_mean>"));
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        for f in [
            "photon_transfer.png",
            "snr.png",
            "linearity.png",
            "deviation_linearity.png",
            "spectrogram_dsnu_h.png",
            "spectrogram_prnu_v.png",
            "histogram_dsnu.png",
            "histogram_prnu.png",
            "dark_mean.png",
        ] {
            assert!(html.contains(f), "{label}: report lacks {f}");
            assert!(out.join(f).is_file(), "{label}: {f} missing");
        }
        // `calibrate --emva1288` on the written series gives the same datasheet
        let out2 = dir.path().join(format!("{label}_calibrate"));
        camsim_ok(
            camsim()
                .args(["calibrate", "--emva1288"])
                .arg(out.join("EMVA1288descriptor.txt"))
                .arg("--out")
                .arg(&out2),
        );
        // same numbers up to the descriptor's 0.1 ns rounding of the exposure times
        let again = datasheet(&out2);
        for (name, v) in ds["values"].as_object().unwrap() {
            let (a, b) = (
                value(&again, name).0,
                v["value"].as_f64().unwrap_or(f64::NAN),
            );
            assert!(
                (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-9 * b.abs(),
                "{label}: {name}: calibrate --emva1288 {a} vs emva1288 {b}"
            );
        }
    }
}

/// Acceptance 2: the reference package's own camera simulator writes a series; camsim
/// (`calibrate --emva1288`) recovers the simulator's inputs: K, QE, dark current and PRNU
/// within 3 standard uncertainties (+1 % for K and QE, whose simulator values are set on a
/// grid), temporal dark noise and DSNU likewise, and the saturation capacity within one
/// photon step plus 3 σ of the pixel spread at saturation (the variance peaks when the first
/// pixels clip, below the clip level).
#[test]
fn emva1288_recovers_the_reference_simulators_inputs() {
    let python = reference_python();
    let dir = tempfile::tempdir().unwrap();
    let peer = dir.path().join("peer");
    let truth = reference(
        &python,
        &[
            "simulate",
            peer.to_str().unwrap(),
            "--seed",
            "3",
            "--width",
            "64",
            "--height",
            "48",
            "--steps",
            "60",
            "--L",
            "8",
        ],
    );
    let out = dir.path().join("camsim");
    camsim_ok(
        camsim()
            .args(["calibrate", "--emva1288"])
            .arg(peer.join("EMVA1288descriptor.txt"))
            .arg("--out")
            .arg(&out),
    );
    let ds = datasheet(&out);
    let t = |k: &str| truth[k].as_f64().unwrap();
    for (name, extra_rel) in [
        ("K", 0.0),
        ("QE", 0.0),
        ("sigma_d", 0.0),
        ("u_I_mean", 0.0),
        ("u_I_var", 0.0),
        ("DSNU1288", 0.0),
        ("PRNU1288", 0.0),
    ] {
        let (v, u) = value(&ds, name);
        let tol = 3.0 * u + extra_rel * t(name);
        assert!(
            (v - t(name)).abs() <= tol,
            "{name}: camsim {v} ± {u}, simulator input {}",
            t(name)
        );
    }
    let (v, u) = value(&ds, "u_e_sat");
    let sat = t("u_e_sat");
    let spread = ((0.01 * t("PRNU1288") * sat).powi(2) + sat).sqrt();
    let step_e = u * 1.0;
    assert!(
        v <= sat + step_e && sat - v <= step_e + 3.0 * spread,
        "u_e_sat: camsim {v} (step {step_e}), clip level {sat}, pixel spread {spread}"
    );
}

/// Acceptance 3: the numbers camsim recovers from its own series match the configured
/// camera: K, η, dark noise, dark current, DSNU and PRNU within 3 standard uncertainties,
/// the saturation capacity within one step plus 3 σ of the pixel spread at saturation. The
/// Table 1 camera's 10-bit ADC with black level 0 clips the dark signal at 0 DN (the standard
/// requires an offset that avoids this), so its dark noise and DSNU are not compared.
#[test]
fn emva1288_recovers_the_configured_camera() {
    let dir = tempfile::tempdir().unwrap();
    for (label, cam) in cameras() {
        let out = dir.path().join(label);
        let ds = run_emva(&cam, &out, &CI);
        let c = &ds["configured"];
        let cfg = |k: &str| c[k].as_f64().unwrap();
        let mut checks = vec![
            ("K", cfg("system_gain_dn_per_e")),
            ("QE", 100.0 * cfg("quantum_efficiency")),
            ("PRNU1288", cfg("prnu_percent")),
        ];
        if label != "table1" {
            checks.push(("sigma_d", cfg("dark_noise_e")));
            checks.push(("DSNU1288", cfg("dsnu_e")));
        }
        if cfg("dark_current_e_per_s") > 100.0 {
            checks.push(("u_I_mean", cfg("dark_current_e_per_s")));
            checks.push(("u_I_var", cfg("dark_current_e_per_s")));
        }
        for (name, truth) in checks {
            let (v, u) = value(&ds, name);
            assert!(
                (v - truth).abs() <= 3.0 * u,
                "{label}: {name}: recovered {v} ± {u}, configured {truth}"
            );
        }
        let (v, u) = value(&ds, "u_e_sat");
        let sat = cfg("saturation_e");
        let spread = ((0.01 * cfg("prnu_percent") * sat).powi(2)
            + sat
            + cfg("dsnu_e").powi(2)
            + cfg("dark_noise_e").powi(2))
        .sqrt();
        assert!(
            v <= sat + u && sat - v <= u + 3.0 * spread,
            "{label}: u_e_sat {v} (step {u}), configured saturation {sat}, spread {spread}"
        );
    }
}

/// Same seed → byte-identical datasheet; a bad channel is one clear error line.
#[test]
fn emva1288_is_reproducible_and_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let cam = repo().join("examples/emva1288/high_gain_camera.json");
    let small = [
        "--rows",
        "16",
        "--cols",
        "16",
        "--steps",
        "10",
        "--spatial-frames",
        "4",
    ];
    run_emva(&cam, &dir.path().join("a"), &small);
    run_emva(&cam, &dir.path().join("b"), &small);
    let a = std::fs::read(dir.path().join("a/datasheet.json")).unwrap();
    let b = std::fs::read(dir.path().join("b/datasheet.json")).unwrap();
    assert_eq!(a, b);
    let o = camsim()
        .arg("emva1288")
        .arg(&cam)
        .args([
            "--out",
            dir.path().join("c").to_str().unwrap(),
            "--channel",
            "nir",
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--channel") && err.contains("nir"), "{err}");
    // a broken descriptor names the file and line
    let bad = dir.path().join("bad.txt");
    std::fs::write(&bad, "v 4.0\nn 12 16 16\nb 1000 x\n").unwrap();
    let o = camsim()
        .args(["calibrate", "--emva1288"])
        .arg(&bad)
        .args(["--out", dir.path().join("d").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("bad.txt") && err.contains("line 3"), "{err}");
}

/// Full size (the sensor's own rows × columns, L = 100) against the reference, for the Table 1
/// camera: `cargo test --release --test tests emva1288_full_size -- --ignored`.
#[test]
#[ignore]
fn emva1288_full_size_matches_the_reference() {
    let python = reference_python();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("table1");
    let ds = run_emva(&cameras()[0].1, &out, &[]);
    let r = reference(
        &python,
        &[
            "analyse",
            out.join("EMVA1288descriptor.txt").to_str().unwrap(),
        ],
    );
    let n = compare_with_reference(&ds, &r, "table1 full size");
    assert!(n >= 25);
}
