//! `camsim render` and `camsim run` with a glTF scene, end to end through the binary.
use crate::util::{camsim, camsim_ok};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

#[test]
fn render_writes_a_spectral_exr_with_depth_and_harness_channels() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("u.exr");
    let st = camsim_ok(
        camsim()
            .args(["render"])
            .arg(scenes().join("uniform_emitter.gltf"))
            .args([
                "--width",
                "16",
                "--spp",
                "16",
                "--seed",
                "3",
                "--bands",
                "400:700:100",
            ])
            .args([
                "--variance",
                "--mitsuba-channels",
                "--depth-spp",
                "2",
                "--out",
            ])
            .arg(&out),
    );
    let summary: Value = serde_json::from_slice(&st.stdout).unwrap();
    assert_eq!(summary["width"], 16);
    assert_eq!(summary["height"], 16);
    assert!(summary["samples_per_s"].as_f64().unwrap() > 0.0);
    // Fichet layout: bands at the centres 450, 550, 650 nm, W m^-2 sr^-1 per nm, Z in metres
    let exr = camsim_core::exr_io::read_spectral_exr(&out).unwrap();
    assert_eq!(exr.grid.wavelength_nm, vec![450.0, 550.0, 650.0]);
    assert_eq!(exr.emissive_units, camsim_core::exr_io::RADIANCE_UNITS);
    for p in &exr.image.planes {
        let m = p.iter().map(|v| *v as f64).sum::<f64>() / p.len() as f64;
        // ρ·Le = 0.6 (the statistical check is in render/tests/physics.rs)
        assert!((m - 0.6).abs() < 0.1, "band mean {m}");
    }
    let z = exr.depth_m.unwrap();
    assert!(z.data.iter().all(|v| (v - 1.0).abs() < 1e-5));
    let (_, _, chans, _) = camsim_core::exr_io::read_channels(&out).unwrap();
    let names: Vec<&str> = chans.iter().map(|c| c.0.as_str()).collect();
    for n in [
        "band_0400_0500",
        "band_0600_0700",
        "depth.T",
        "depth_center.T",
        "variance.S0.550,000000nm",
        "band_0500_0600.variance",
    ] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
}

#[test]
fn render_reports_bad_input_on_one_line() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("x.exr");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "render".into(),
                d.path().join("none.gltf").display().to_string(),
            ],
            "cannot read",
        ),
        (
            vec![
                "render".into(),
                scenes().join("furnace.gltf").display().to_string(),
                "--bands".into(),
                "380:785:10".into(),
            ],
            "multiple of STEP",
        ),
        (
            vec![
                "render".into(),
                scenes().join("furnace.gltf").display().to_string(),
                "--camera".into(),
                "fisheye".into(),
            ],
            "expected pinhole",
        ),
        (
            vec![
                "render".into(),
                scenes().join("furnace.gltf").display().to_string(),
                "--camera".into(),
                "thinlens".into(),
            ],
            "no extras.thinlens",
        ),
        (
            vec![
                "render".into(),
                scenes().join("furnace.gltf").display().to_string(),
                "--spp".into(),
                "0".into(),
            ],
            "--spp 0",
        ),
        (
            vec![
                "render".into(),
                scenes().join("furnace.gltf").display().to_string(),
                "--camera-name".into(),
                "nope".into(),
            ],
            "no camera named",
        ),
    ];
    for (args, expect) in cases {
        let st = camsim()
            .args(&args)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(st.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&st.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{args:?}: {err}");
        assert!(lines[0].contains(expect), "{args:?}: {err}");
        assert!(!out.exists());
    }
}

#[test]
fn run_accepts_a_gltf_scene() {
    let d = tempfile::tempdir().unwrap();
    let mut cam: Value = serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap();
    cam["sensor"]["rows"] = json!(48);
    cam["sensor"]["cols"] = json!(64);
    let cfg = json!({
        "camera": cam,
        "render": {"scene": scenes().join("color_chart.gltf"), "spp": 2},
        "exposure_s": 0.01,
    });
    let p = d.path().join("run.json");
    std::fs::write(&p, cfg.to_string()).unwrap();
    camsim_ok(
        camsim()
            .arg("run")
            .arg(&p)
            .arg("--out")
            .arg(d.path().join("o")),
    );
    let o = d.path().join("o");
    for f in [
        "scene_radiance.exr",
        "sensor_irradiance.exr",
        "raw.png",
        "rendered.png",
        "summary.json",
    ] {
        assert!(o.join(f).is_file(), "{f} missing");
    }
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(o.join("summary.json")).unwrap()).unwrap();
    assert!(s["raw_mean_dn"].as_f64().unwrap() > 0.0);
    // Physical content: the rendered radiance went through the camera equation. Per band, the
    // mean sensor irradiance equals π·T/(4N²) · mean over the pixels of L(x)·cos⁴θ(x)
    // (tan θ = r/f at the pixel centres, object at infinity: the chart is metres away, so
    // (1 + m)² differs from 1 by < 10⁻²); the diffraction blur keeps the power except what it
    // spreads over the border (Airy radius 1.22·λ·N ≈ 2.7 µm ≈ 1.2 px at 550 nm on a 48 × 64
    // image: ≲ 2 % of a border-heavy scene). Hence 3 %.
    let l = camsim_core::exr_io::read_spectral_exr(&o.join("scene_radiance.exr")).unwrap();
    let e = camsim_core::exr_io::read_spectral_exr(&o.join("sensor_irradiance.exr")).unwrap();
    assert_eq!((l.image.rows, l.image.cols), (48, 64));
    assert_eq!((e.image.rows, e.image.cols), (48, 64));
    let optics = &cam["optics"];
    let n_f = optics["f_number"].as_f64().unwrap();
    let t = optics["transmittance"].as_f64().unwrap();
    let focal_m = optics["focal_length_mm"].as_f64().unwrap() * 1e-3;
    let pitch_m = cam["sensor"]["pixel_pitch_um"].as_f64().unwrap() * 1e-6;
    let factor = std::f64::consts::PI * t / (4.0 * n_f * n_f);
    let cos4: Vec<f64> = (0..48 * 64)
        .map(|i| {
            let y = ((i / 64) as f64 - 23.5) * pitch_m;
            let x = ((i % 64) as f64 - 31.5) * pitch_m;
            (focal_m * focal_m / (focal_m * focal_m + x * x + y * y)).powi(2)
        })
        .collect();
    let (mut worst, mut bands) = (0f64, 0);
    for (k, plane) in l.image.planes.iter().enumerate() {
        let w = l.grid.wavelength_nm[k];
        let Some(ke) = e.grid.wavelength_nm.iter().position(|&x| x == w) else {
            continue;
        };
        let predicted = factor
            * plane
                .iter()
                .zip(&cos4)
                .map(|(&v, c)| v as f64 * c)
                .sum::<f64>()
            / cos4.len() as f64;
        let got = e.image.planes[ke].iter().map(|&v| v as f64).sum::<f64>() / cos4.len() as f64;
        assert!(predicted > 0.0, "{w} nm: no radiance");
        worst = worst.max((got / predicted - 1.0).abs());
        bands += 1;
    }
    eprintln!("glTF run: irradiance vs camera equation over {bands} bands: worst {worst:.4}");
    assert!(bands >= 10, "only {bands} common bands");
    assert!(
        worst <= 0.03,
        "irradiance off the camera equation by {worst}"
    );
    // target and render together are refused
    let cfg = json!({"render": {"scene": "x.gltf"}, "target": {"kind": "macbeth"}});
    std::fs::write(&p, cfg.to_string()).unwrap();
    let st = camsim()
        .arg("run")
        .arg(&p)
        .arg("--out")
        .arg(d.path().join("o2"))
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&st.stderr).contains("not both"));
}
