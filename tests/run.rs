//! `camsim run`: the paper's §3 study end to end (issue: processor, display, metrics).
use crate::util::{camsim, camsim_ok};
use camsim_pipeline::plots::check_figure;
use serde_json::{json, Value};
use std::path::Path;

fn run_ok(args: &[&str], dir: &Path) -> Value {
    camsim_ok(camsim().args(args).current_dir(dir));
    let out = args
        .iter()
        .position(|a| *a == "--out")
        .map(|i| args[i + 1])
        .unwrap_or("out/run");
    serde_json::from_str(&std::fs::read_to_string(dir.join(out).join("summary.json")).unwrap())
        .unwrap()
}

#[test]
fn default_run_writes_every_product_and_real_figures() {
    let d = tempfile::tempdir().unwrap();
    let s = run_ok(&["run", "--out", "o"], d.path());
    let o = d.path().join("o");
    for f in [
        "scene_radiance.exr",
        "sensor_irradiance.exr",
        "raw.png",
        "rendered.png",
        "display_radiance.exr",
        "summary.json",
        "report.html",
    ] {
        assert!(o.join(f).is_file(), "{f} missing");
    }
    // the spectral EXRs are in the Fichet layout at the sensor's resolution
    for f in [
        "scene_radiance.exr",
        "sensor_irradiance.exr",
        "display_radiance.exr",
    ] {
        let e = camsim_core::exr_io::read_spectral_exr(&o.join(f)).unwrap();
        assert_eq!((e.image.rows, e.image.cols), (480, 640), "{f}");
        assert_eq!(e.grid.wavelength_nm.first(), Some(&400.0));
        assert!(e.image.plane_means().iter().sum::<f64>() > 0.0);
    }
    // raw is the sensor's 16-bit mosaic
    let raw = camsim_pipeline::frames::read_png16(&o.join("raw.png")).unwrap();
    assert_eq!((raw.rows, raw.cols), (480, 640));
    // the paper's setup: Table 1 camera, tungsten Macbeth at 61 cd/m²
    assert!((s["scene_mean_luminance_cd_m2"].as_f64().unwrap() - 61.0).abs() < 0.01);
    assert_eq!(s["sensor"]["pixel_pitch_um"].as_f64().unwrap(), 2.2);
    let de = s["delta_e_2000"]["mean"].as_f64().unwrap();
    assert!(de > 0.3 && de < 8.0, "mean ΔE2000 {de}");
    headline_delta_e_is_the_noise_free_value_within_its_noise(&s, d.path());
    // The headline recomputed from the reported patch values (desired and rendered linear
    // sRGB) by an independent colour path (IEC 61966-2-1 matrix at its published 4 digits,
    // CIE 15 Lab with the exact constants, D65 white = M·(1, 1, 1)) and Sharma's CIEDE2000.
    // Tolerance: the 4-digit matrix against camsim's full-precision one moves Lab by ≲ 10⁻³,
    // so the mean of 24 ΔE2000 agrees to 0.01.
    let patches = s["patches"].as_array().unwrap();
    assert_eq!(patches.len(), 24);
    let rgb = |v: &Value| -> [f64; 3] { [0, 1, 2].map(|k| v[k].as_f64().unwrap()) };
    let recomputed = patches
        .iter()
        .map(|p| {
            delta_e_2000_reference(
                rgb(&p["desired_linear_srgb"]),
                rgb(&p["rendered_linear_srgb"]),
            )
        })
        .sum::<f64>()
        / 24.0;
    assert!(
        (recomputed - de).abs() <= 0.01,
        "reported mean ΔE2000 {de} vs recomputed from the patches {recomputed}"
    );
    // every figure the report shows exists and shows something (not a blank canvas)
    let html = std::fs::read_to_string(o.join("report.html")).unwrap();
    let figs = s["figures"].as_array().unwrap();
    assert!(figs.len() >= 6);
    for f in figs {
        let f = f.as_str().unwrap();
        assert!(
            html.contains(&format!("src=\"{f}\"")),
            "report does not show {f}"
        );
        let c = check_figure(&o.join(f)).unwrap();
        assert!(c.distinct_colours >= 8, "{f}: {c:?}");
        assert!(c.non_white_per_mille >= 20, "{f}: {c:?}");
    }
    // per-patch SNR rises with the patch signal (shot-noise limited): white > black patch
    let g = &s["patch_snr"]["g"];
    assert!(g[18]["snr_db"].as_f64().unwrap() > g[23]["snr_db"].as_f64().unwrap() + 6.0);
}

/// The §3 headline against the same run without temporal noise and fixed-pattern noise
/// (shot, read, DSNU and PRNU off; the dark current's mean kept, its shot noise is
/// < 0.1 e here), so that its tolerances are the noise's. `g = ∂ΔE2000/∂r` below is taken by
/// central differences of [`delta_e_2000_reference`] at the noise-free value; each run reports
/// its patch means before the output's clipping and rounding (`before_output_linear_srgb`)
/// and their standard errors (from 8 × 8 block means).
/// * **Noise** (before the output, where the chain is smooth): per patch, the difference of
///   the two runs' ΔE2000 is to first order `g · (r_noisy − r_free)`, so the mean over the 24
///   patches satisfies `|D| ≤ 4·σ_D`, `σ_D = √(Σ_p σ_p²)/24`,
///   `σ_p² = Σ_c g_c²·(SE²_noisy + SE²_free)` (false-failure rate 6e-5), and every patch
///   `≤ 5·σ_p` (24 × 5.7e-7).
/// * **The output, noise-free** (a patch's pixels are then equal, so clipping commutes with
///   the mean): the headline's patch value (decoded 8-bit codes) is the clipped value before
///   the output within half a code, `b_c = ½·decode′(code)/255` in linear units, so its ΔE2000
///   within `Σ_c |g_c|·b_c` (+5 % for the curvature over half a code).
/// * **The headline, noisy vs noise-free**: within `4·σ_D` plus both runs' rounding bounds
///   plus, for a channel whose noise-free value lies within 4 pixel σ of a clipping limit,
///   the clipping's bias of the mean, at most `σ_px/√(2π)` with
///   `σ_px ≤ SE·√pixels` (block means of correlated pixels overstate it).
///
/// The noise-free headline must also exceed twice the noise tolerance: the noise may not be
/// what makes it.
fn headline_delta_e_is_the_noise_free_value_within_its_noise(noisy: &Value, dir: &Path) {
    let mut cam: Value = serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap();
    cam["sensor"]["noise"] =
        json!({"shot": false, "dark": true, "read": false, "dsnu": false, "prnu": false});
    let mut cfg: Value = serde_json::from_str(camsim_pipeline::run::DEFAULT_CONFIG).unwrap();
    cfg["camera"] = cam;
    std::fs::write(dir.join("noise_free.json"), cfg.to_string()).unwrap();
    let free = run_ok(&["run", "noise_free.json", "--out", "free"], dir);
    let rgb = |v: &Value| -> [f64; 3] { [0, 1, 2].map(|k| v[k].as_f64().unwrap()) };
    let grad = |want: [f64; 3], at: [f64; 3]| -> [f64; 3] {
        let h = 1e-6;
        [0, 1, 2].map(|c| {
            let (mut up, mut dn) = (at, at);
            up[c] += h;
            dn[c] -= h;
            (delta_e_2000_reference(want, up) - delta_e_2000_reference(want, dn)) / (2.0 * h)
        })
    };
    // Half an 8-bit code of the sRGB encoding, in linear units, at linear value v.
    let half_code = |v: f64| {
        let e = camsim_isp::srgb_encode(v.clamp(0.0, 1.0));
        let dec = |e: f64| camsim_isp::srgb_decode(e.clamp(0.0, 1.0));
        0.5 * (dec(e + 0.5 / 255.0) - dec(e - 0.5 / 255.0)).abs()
    };
    let (pn, pf) = (
        noisy["patches"].as_array().unwrap(),
        free["patches"].as_array().unwrap(),
    );
    assert_eq!((pn.len(), pf.len()), (24, 24));
    let (mut d_sum, mut var_sum, mut de_free) = (0.0, 0.0, 0.0);
    let (mut round_bound, mut clip_bound) = (0.0, 0.0);
    for (i, (a, b)) in pn.iter().zip(pf).enumerate() {
        let want = rgb(&a["desired_linear_srgb"]);
        assert_eq!(want, rgb(&b["desired_linear_srgb"]), "patch {i}: targets");
        let (rn, rf) = (
            rgb(&a["before_output_linear_srgb"]),
            rgb(&b["before_output_linear_srgb"]),
        );
        let (sn, sf) = (
            rgb(&a["before_output_linear_srgb_standard_error"]),
            rgb(&b["before_output_linear_srgb_standard_error"]),
        );
        let (en, ef) = (
            delta_e_2000_reference(want, rn),
            delta_e_2000_reference(want, rf),
        );
        let g = grad(want, rf);
        let var_p: f64 = (0..3)
            .map(|c| g[c] * g[c] * (sn[c] * sn[c] + sf[c] * sf[c]))
            .sum();
        assert!(
            (en - ef).abs() <= 5.0 * var_p.sqrt(),
            "patch {i}: ΔE2000 before the output, noisy {en:.4} vs noise-free {ef:.4} (σ {:.4})",
            var_p.sqrt()
        );
        d_sum += en - ef;
        var_sum += var_p;
        // The noise-free output: the clipped value within half a code.
        let clipped = rf.map(|v| v.clamp(0.0, 1.0));
        let gc = grad(want, clipped);
        let b_p = 1.05
            * (0..3)
                .map(|c| gc[c].abs() * half_code(clipped[c]))
                .sum::<f64>();
        let (e8, ec) = (
            delta_e_2000_reference(want, rgb(&b["rendered_linear_srgb"])),
            delta_e_2000_reference(want, clipped),
        );
        assert!(
            (e8 - ec).abs() <= b_p,
            "noise-free patch {i}: ΔE2000 of the output {e8:.4} vs the clipped value {ec:.4} (bound {b_p:.4})"
        );
        de_free += e8 / 24.0;
        round_bound += 2.0 * b_p / 24.0;
        let pixels = a["pixels"].as_f64().unwrap();
        for c in 0..3 {
            let s_px = sn[c] * pixels.sqrt();
            if rf[c] < 4.0 * s_px || rf[c] > 1.0 - 4.0 * s_px {
                clip_bound += gc[c].abs() * s_px / (2.0 * std::f64::consts::PI).sqrt() / 24.0;
            }
        }
    }
    let (d, sigma_d) = (d_sum / 24.0, var_sum.sqrt() / 24.0);
    let de = noisy["delta_e_2000"]["mean"].as_f64().unwrap();
    eprintln!(
        "mean ΔE2000 before the output, noisy − noise-free = {d:+.4} (σ {sigma_d:.4}); headline \
         noisy {de:.4}, noise-free {de_free:.4} (rounding bound {round_bound:.4}, clipping bound \
         {clip_bound:.4})"
    );
    assert!(
        d.abs() <= 4.0 * sigma_d,
        "mean ΔE2000 before the output, noisy − noise-free = {d:+.4} beyond 4σ = {:.4}",
        4.0 * sigma_d
    );
    let tol = 4.0 * sigma_d + round_bound + clip_bound;
    assert!(
        (de - de_free).abs() <= tol,
        "headline ΔE2000 {de:.4} vs noise-free {de_free:.4}: beyond {tol:.4}"
    );
    assert!(
        de_free > 2.0 * tol,
        "noise-free ΔE2000 {de_free} is within twice the noise tolerance {tol}"
    );
}

/// ΔE2000 between two linear-sRGB colours by a path independent of camsim's colour code:
/// XYZ by the IEC 61966-2-1 matrix, CIELAB (CIE 15:2004, ε = 216/24389, κ = 24389/27) against
/// the sRGB white, CIEDE2000 of camsim_metrics (tested on Sharma et al.'s data).
fn delta_e_2000_reference(a: [f64; 3], b: [f64; 3]) -> f64 {
    const M: [[f64; 3]; 3] = [
        [0.4124, 0.3576, 0.1805],
        [0.2126, 0.7152, 0.0722],
        [0.0193, 0.1192, 0.9505],
    ];
    let xyz = |c: [f64; 3]| -> [f64; 3] {
        [0, 1, 2].map(|r| M[r][0] * c[0] + M[r][1] * c[1] + M[r][2] * c[2])
    };
    let white = xyz([1.0, 1.0, 1.0]);
    let lab = |c: [f64; 3]| -> camsim_core::colorimetry::Lab {
        let (eps, kappa) = (216.0 / 24389.0, 24389.0 / 27.0);
        let x = xyz(c);
        let f = |t: f64| {
            if t > eps {
                t.cbrt()
            } else {
                (kappa * t + 16.0) / 116.0
            }
        };
        let (fx, fy, fz) = (f(x[0] / white[0]), f(x[1] / white[1]), f(x[2] / white[2]));
        camsim_core::colorimetry::Lab {
            l: 116.0 * fy - 16.0,
            a: 500.0 * (fx - fy),
            b: 200.0 * (fy - fz),
        }
    };
    camsim_metrics::delta_e_2000(lab(a), lab(b))
}

fn small_config(dir: &Path, processor: Value) -> std::path::PathBuf {
    let mut cam: Value = serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap();
    cam["sensor"]["rows"] = json!(120);
    cam["sensor"]["cols"] = json!(180);
    cam["optics"]["blur"] = json!({"kind": "none"});
    let cfg = json!({
        "camera": cam,
        "target": {"kind": "macbeth", "illuminant": "tungsten", "mean_luminance_cd_m2": 61, "patch_fraction": 0.8},
        "processor": processor,
    });
    let p = dir.join(format!("cfg-{}.json", processor.to_string().len()));
    std::fs::write(&p, cfg.to_string()).unwrap();
    p
}

/// Paper §3: the fitted 3×3 correction is what brings the tungsten capture close to the D65
/// targets; without it (white balance only) the colour error is much larger.
#[test]
fn colour_correction_reduces_delta_e() {
    let d = tempfile::tempdir().unwrap();
    let with = small_config(d.path(), json!({"color_correction": "macbeth_d65"}));
    let without = small_config(
        d.path(),
        json!({"color_correction": "none", "demosaic": "bilinear"}),
    );
    let a = run_ok(&["run", with.to_str().unwrap(), "--out", "a"], d.path());
    let b = run_ok(&["run", without.to_str().unwrap(), "--out", "b"], d.path());
    let (da, db) = (
        a["delta_e_2000"]["mean"].as_f64().unwrap(),
        b["delta_e_2000"]["mean"].as_f64().unwrap(),
    );
    assert!(da < 0.6 * db, "with CCM {da}, without {db}");
}

fn assert_bad_run(dir: &Path, cfg: &str, needles: &[&str]) {
    let p = dir.join("bad.json");
    std::fs::write(&p, cfg).unwrap();
    let st = camsim()
        .args(["run", "bad.json", "--out", "o"])
        .current_dir(dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr).to_string();
    assert!(!st.status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' not in {err}");
    }
    assert!(!dir.join("o").exists(), "nothing may be written");
}

#[test]
fn bad_run_configs_give_one_clear_error() {
    let d = tempfile::tempdir().unwrap();
    let t = r#""target": {"kind": "macbeth"}"#;
    assert_bad_run(
        d.path(),
        &format!(r#"{{{t}, "display": {{"name": "CRT-Nope"}}}}"#),
        &["bad.json", "CRT-Nope", "lcdExample"],
    );
    assert_bad_run(
        d.path(),
        &format!(r#"{{{t}, "processor": {{"demosaic": "magic"}}}}"#),
        &["bad.json", "magic", "malvar"],
    );
    assert_bad_run(
        d.path(),
        &format!(r#"{{{t}, "processor": {{"white_balance": "auto"}}}}"#),
        &["bad.json", "white_balance"],
    );
    assert_bad_run(
        d.path(),
        r#"{"target": {"kind": "macbeth"}, "procesor": {}}"#,
        &["bad.json", "procesor"],
    );
    assert_bad_run(d.path(), r#"{"target": "#, &["bad.json", "invalid"]);
}

#[test]
fn figures_module_draws_every_kind() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    let xs: Vec<f64> = (0..30).map(|i| i as f64).collect();
    let ys: Vec<f64> = xs.iter().map(|x| x * 0.9 + 3.0).collect();
    camsim_pipeline::plots::scatter(
        &p.join("s.png"),
        "scatter",
        &xs,
        &ys,
        None,
        ("x", "y"),
        true,
    )
    .unwrap();
    camsim_pipeline::plots::histogram(&p.join("h.png"), "hist", &ys, 10, "v").unwrap();
    camsim_pipeline::plots::bar_chart(
        &p.join("b.png"),
        "bars",
        &xs.iter().map(|x| x.to_string()).collect::<Vec<_>>(),
        &ys,
        "v",
    )
    .unwrap();
    camsim_pipeline::plots::line_plot(
        &p.join("l.png"),
        "lines",
        &[(
            "a".into(),
            xs.iter().zip(&ys).map(|(a, b)| (*a, *b)).collect(),
        )],
        ("x", "y"),
    )
    .unwrap();
    for f in ["s.png", "h.png", "b.png", "l.png"] {
        let c = check_figure(&p.join(f)).unwrap();
        assert_eq!((c.width, c.height), (720, 480));
        assert!(
            c.distinct_colours > 8 && c.non_white_per_mille > 10,
            "{f}: {c:?}"
        );
    }
    // a blank canvas fails the check that the tests rely on
    let blank = vec![255u8; 30 * 20 * 3];
    camsim_pipeline::plots::rgb8_png(&p.join("blank.png"), &blank, 20, 30).unwrap();
    let c = check_figure(&p.join("blank.png")).unwrap();
    assert_eq!((c.distinct_colours, c.non_white_per_mille), (1, 0));
}
