//! `optics.blur.kind = "lens"` end to end: a camera.json naming a lens prescription loads and
//! `camsim simulate --expected` runs with it; a missing lens file is one error line naming it.
use crate::cli::{camera, captures, write_set};
use crate::util::{camsim, camsim_ok};
use serde_json::json;
use std::path::Path;

fn lens_path() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("lenses/double_gauss_50mm_f2.json")
        .display()
        .to_string()
}

fn centre_dn(dir: &Path) -> (usize, usize, f64) {
    let (rows, cols, chans, _) =
        camsim_core::exr_io::read_channels(&dir.join("out/flat.exr")).unwrap();
    let y = &chans[0].1;
    // Mean of the central 2×2 (one CFA tile).
    let (r, c) = (rows / 2 - 1, cols / 2 - 1);
    let m =
        (y[r * cols + c] + y[r * cols + c + 1] + y[(r + 1) * cols + c] + y[(r + 1) * cols + c + 1])
            as f64
            / 4.0;
    (rows, cols, m)
}

fn simulate(dir: &Path) {
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--expected", "--out", "out"])
            .current_dir(dir),
    );
}

/// 64×64 sensor of 5 µm pixels behind the 50 mm f/2 double Gauss (field of view ±0.26°):
/// the run succeeds, writes a 64×64 expected image, and near the axis (relative illumination
/// ≈ 1, uniform target) the signal is that of the lens's own F/2, not the camera's f/2.8:
/// (2.8/2)² = 1.96 times the no-blur f/2.8 camera's (within 2 %).
#[test]
fn lens_kind_loads_and_simulates() {
    let mut caps = captures(0.0005, 0.02);
    caps["simulation"] = json!({"wavelength_nm": {"start_nm": 400, "stop_nm": 700, "step_nm": 50}});
    let base = tempfile::tempdir().unwrap();
    let mut cam = camera(64, 64);
    cam["sensor"]["pixel_pitch_um"] = json!(5.0);
    write_set(base.path(), &cam, &caps);
    simulate(base.path());
    let lens = tempfile::tempdir().unwrap();
    cam["optics"]["blur"] = json!({"kind": "lens", "lens_file": lens_path()});
    write_set(lens.path(), &cam, &caps);
    let t0 = std::time::Instant::now();
    simulate(lens.path());
    eprintln!("lens simulate: {:?}", t0.elapsed());
    let (r, c, dn_lens) = centre_dn(lens.path());
    assert_eq!((r, c), (64, 64));
    let (_, _, dn_base) = centre_dn(base.path());
    let black = 64.0;
    let ratio = (dn_lens - black) / (dn_base - black);
    eprintln!("centre DN lens {dn_lens:.1} base {dn_base:.1} ratio {ratio:.4}");
    assert!(dn_lens < 4000.0, "clipped: {dn_lens}");
    assert!((ratio / 1.96 - 1.0).abs() < 0.02, "ratio {ratio}");
}

/// A lens_file that does not exist: exit failure, one error line naming the file.
#[test]
fn missing_lens_file_is_one_error_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera(16, 16);
    cam["optics"]["blur"] = json!({"kind": "lens", "lens_file": "no_such_lens.json"});
    write_set(dir.path(), &cam, &captures(0.002, 0.02));
    let st = camsim()
        .args(["simulate", "captures.json", "--expected", "--out", "out"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains("no_such_lens.json"), "{err}");
    assert!(!dir.path().join("out/flat.exr").exists());
}

/// `optics.object_distance_m` with blur kind "lens": the lens is focused on an object 0.5 m
/// from its first vertex, so the camera equation uses the lens's working F-number at that
/// conjugate. Near the axis the signal relative to the object at infinity is
/// (N_w(∞)/N_w(0.5 m))², N_w = 1/(2 n'u') of the paraxial marginal ray (within 2 %); for this
/// near-symmetric lens that is close to the thin-lens (1 + |m|)⁻² (within 5 %).
#[test]
fn object_distance_focuses_the_lens_and_sets_its_working_f_number() {
    let mut caps = captures(0.0005, 0.02);
    caps["simulation"] = json!({"wavelength_nm": {"start_nm": 400, "stop_nm": 700, "step_nm": 50}});
    let mut cam = camera(32, 32);
    cam["sensor"]["pixel_pitch_um"] = json!(5.0);
    cam["optics"]["blur"] = json!({"kind": "lens", "lens_file": lens_path()});
    let far = tempfile::tempdir().unwrap();
    write_set(far.path(), &cam, &caps);
    simulate(far.path());
    let near = tempfile::tempdir().unwrap();
    cam["optics"]["object_distance_m"] = json!(0.5);
    write_set(near.path(), &cam, &caps);
    simulate(near.path());
    let black = 64.0;
    let (_, _, dn_far) = centre_dn(far.path());
    let (_, _, dn_near) = centre_dn(near.path());
    let ratio = (dn_near - black) / (dn_far - black);
    let lens = camsim_lens::LensPrescription::from_json_file(
        lens_path(),
        &camsim_lens::GlassCatalog::bundled(),
    )
    .unwrap();
    let w = lens.primary_nm;
    let nw_far = lens.focus_at(None).unwrap().first_order(w).unwrap();
    let nw_near = lens.focus_at(Some(500.0)).unwrap().first_order(w).unwrap();
    let want = (nw_far.working_f_number / nw_near.working_f_number).powi(2);
    assert!((ratio / want - 1.0).abs() < 0.02, "ratio {ratio} vs {want}");
    let m = nw_near.magnification;
    assert!(m < -0.05 && m > -0.2, "m {m}");
    assert!(
        (want * (1.0 + m.abs()).powi(2) - 1.0).abs() < 0.05,
        "{want} {m}"
    );
}

/// Contrast autofocus (issue 18, `camsim_pipeline::autofocus`): a slanted edge 2 m in front of
/// the f/2 double Gauss on a 32×32 sensor of 5 µm pixels. Scanning the lens position through
/// the one chain and keeping the sharpest image puts the sensor within the depth of focus
/// ±N_w·c (c = 2 pixels, N_w the working F-number at 2 m) of the focus model's best focus for
/// that object (an independent criterion: the polychromatic MTF of traced wavefronts).
///
/// The edge's radiance (5·10¹³–5·10¹⁴ photons/(s·sr·m²·nm)) keeps the light side at ≈ ⅓ of
/// the 20 000 e well in 10 ms: a clipped region has no contrast at any position (the former
/// 10¹⁷ saturated every pixel, so the metric was 0 everywhere and the scan kept its first
/// position, infinity; `contrast_autofocus` now refuses a region more than half clipped).
/// Scan: 5 steps in vergence 0–1/m, then golden section to 0.008/m (the depth of focus is
/// ±0.008/m in object vergence, Δv = Δs'/f²); ≈ 16 positions, ≈ 45–50 s release.
#[test]
fn contrast_autofocus_finds_the_focus_model_plane() {
    use camsim_lens::{FocusMethod, FocusSpec, GlassCatalog, LensPrescription};
    use camsim_pipeline::autofocus::{contrast_autofocus, AutofocusOptions};
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera(32, 32);
    cam["sensor"]["pixel_pitch_um"] = json!(5.0);
    cam["optics"]["object_distance_m"] = json!(2.0);
    cam["optics"]["blur"] = json!({"kind": "lens", "lens_file": lens_path()});
    let caps = json!({"camera": "camera.json",
        "simulation": {"wavelength_nm": {"start_nm": 450, "stop_nm": 650, "step_nm": 50}},
        "shots": [{"id": "edge", "exposure_s": 0.01, "frames": ["e.png"],
        "target": {"kind": "slanted_edge", "dark": 5e13, "light": 5e14, "angle_deg": 5.0,
                   "radiance_unit": "photons"}}]});
    write_set(dir.path(), &cam, &caps);
    let set =
        camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None).unwrap();
    let lens = LensPrescription::from_json_file(lens_path(), &GlassCatalog::bundled()).unwrap();
    let mut opts = camsim_optics::LensBlurOptions::covering(0.5 * 32.0 * 5e-3 * 2f64.sqrt());
    opts.object_distance_mm = Some(2000.0);
    opts.n_fields = 2;
    opts.n_dense_fields = 3;
    opts.wavelengths_nm = vec![450.0, 550.0, 650.0];
    let t0 = std::time::Instant::now();
    let af = contrast_autofocus(
        &set,
        0,
        &lens,
        &opts,
        &AutofocusOptions {
            region: camsim_core::stats::Rect {
                row0: 4,
                row1: 28,
                col0: 4,
                col1: 28,
            },
            near_m: 1.0,
            steps: 5,
            tolerance_per_m: 0.008,
        },
    )
    .unwrap();
    eprintln!(
        "autofocus: {} positions in {:?}; best 1/d = {:.4}/m, image distance {:.4} mm",
        af.samples.len(),
        t0.elapsed(),
        af.best.vergence_per_m,
        af.best.image_distance_mm
    );
    for s in &af.samples {
        eprintln!(
            "  1/d = {:.4}/m, image distance {:.4} mm, contrast {:.5}",
            s.vergence_per_m, s.image_distance_mm, s.contrast
        );
    }
    let model = lens
        .focus(&FocusSpec {
            focus_distance_mm: Some(2000.0),
            method: FocusMethod {
                wavelengths_nm: Some(vec![450.0, 550.0, 650.0]),
                frequency_cyc_per_mm: Some(0.25 / 5e-3),
                max_field_deg: Some(0.0),
                ..Default::default()
            },
        })
        .unwrap();
    let nw = model
        .lens
        .first_order(lens.primary_nm)
        .unwrap()
        .working_f_number;
    let dof_mm = nw * 2.0 * 5e-3;
    let d = af.best.image_distance_mm - model.image_distance_mm;
    assert!(
        d.abs() < dof_mm,
        "autofocus image distance {} vs focus model {} (depth of focus ±{dof_mm} mm)",
        af.best.image_distance_mm,
        model.image_distance_mm
    );
    // the scan saw a real maximum: the ends are blurrier than the kept position
    let c_inf = af.samples[0].contrast;
    assert!(
        af.best.contrast > 1.5 * c_inf,
        "{} vs {c_inf}",
        af.best.contrast
    );
}
