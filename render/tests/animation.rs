//! glTF animations (node translation, LINEAR / STEP, clamped outside the keyframes): the
//! loader places objects and the camera where the animation has them at a time, checked
//! against the closed-form pinhole projection `x = W/2 + (X/Z)·(H/2)/tan(yfov/2)` of the
//! moving-bar scene, and a render at two times against the same projection.
use camsim_render::gltf_load::{load_gltf, load_gltf_nodes_at_time};
use camsim_render::gltf_write::{flat_spectrum, quad, GltfBuilder};
use camsim_render::job::{node_film_position_px, prepare_at_time, CameraChoice, RenderJob};
use camsim_render::test_scenes::{moving_bar, moving_bar_spec as bar};
use camsim_render::{render, Bands, RenderSettings};
use serde_json::json;
use std::path::{Path, PathBuf};

fn write_bar(dir: &Path) -> PathBuf {
    let p = dir.join("moving_bar.gltf");
    moving_bar().write(&p).unwrap();
    p
}

fn job(path: &Path, w: u32, h: u32, spp: u32) -> RenderJob {
    RenderJob {
        scene: path.to_path_buf(),
        camera_name: None,
        camera: CameraChoice::Pinhole,
        width: w,
        height: Some(h),
        aperture_radius_m: None,
        focus_distance_m: None,
        yfov_rad: None,
        settings: RenderSettings {
            spp,
            seed: 7,
            bands: Bands::new(500.0, 600.0, 100.0).unwrap(),
            max_depth: 1,
            depth_spp: 0,
            environment: None,
            ..RenderSettings::default()
        },
    }
}

/// Closed form: the film x (px) of world x at depth Z for a W × H film.
fn film_x(x_m: f64, w: f64, h: f64) -> f64 {
    let t = (bar::YFOV_DEG.to_radians() / 2.0).tan();
    w / 2.0 + (x_m / bar::BAR_DISTANCE_M) * (h / 2.0) / t
}

#[test]
fn bar_node_follows_the_linear_animation_and_clamps() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_bar(dir.path());
    let j = job(&p, 96, 200, 1);
    for t in [-0.01f64, 0.0, 0.0123, 0.05, 0.1, 0.3] {
        let tc = t.clamp(0.0, bar::LAST_KEYFRAME_S);
        let x = bar::BAR_X0_M + bar::BAR_VELOCITY_M_PER_S * tc;
        let got = node_film_position_px(&j, "bar", t).unwrap();
        let want = film_x(x, 96.0, 200.0);
        assert!(
            (got[0] - want).abs() < 2e-3 && (got[1] - 100.0).abs() < 1e-3,
            "t = {t}: {got:?} vs ({want}, 100)"
        );
    }
    // the static load keeps the node's own translation (x0)
    let (_, nodes) = load_gltf_nodes_at_time(&p, 0.0).unwrap();
    let n = nodes
        .iter()
        .find(|n| n.name.as_deref() == Some("bar"))
        .unwrap();
    assert!((n.to_world.w_axis.x - bar::BAR_X0_M).abs() < 1e-6);
    assert!(load_gltf(&p).is_ok());
}

/// The bar scene with STEP keyframes on the bar, or a LINEAR animation on the camera.
fn variant(dir: &Path, name: &str, camera_moves: bool) -> PathBuf {
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "em", "doubleSided": true,
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(1.0)}}));
    let q = quad([
        [-0.05, -1.0, 0.0],
        [0.05, -1.0, 0.0],
        [0.05, 1.0, 0.0],
        [-0.05, 1.0, 0.0],
    ]);
    let mesh = b.mesh("bar", &q, m);
    let bar_node = b.node(
        json!({"name": "bar", "mesh": mesh, "translation": [0.0, 0.0, -2.0]}),
        true,
    );
    let c = b.camera("cam", bar::YFOV_DEG.to_radians(), None, 0.01);
    let cam_node = b.node(json!({"name": "cam", "camera": c}), true);
    if camera_moves {
        // camera slides +x at 4 m/s: the bar's image moves −x
        b.translation_animation(
            "pan",
            cam_node,
            &[0.0, 1.0],
            &[[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]],
            "LINEAR",
        );
    } else {
        b.translation_animation(
            "jump",
            bar_node,
            &[0.0, 0.01, 0.02],
            &[[0.0, 0.0, -2.0], [0.1, 0.0, -2.0], [0.3, 0.0, -2.0]],
            "STEP",
        );
    }
    let p = dir.join(format!("{name}.gltf"));
    b.write(&p).unwrap();
    p
}

#[test]
fn step_keyframes_hold_and_camera_motion_moves_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let p = variant(dir.path(), "step", false);
    let j = job(&p, 64, 64, 1);
    for (t, x) in [
        (0.0, 0.0),
        (0.0099, 0.0),
        (0.01, 0.1),
        (0.015, 0.1),
        (0.02, 0.3),
        (1.0, 0.3),
    ] {
        let got = node_film_position_px(&j, "bar", t).unwrap()[0];
        assert!(
            (got - film_x(x, 64.0, 64.0)).abs() < 2e-3,
            "STEP t = {t}: {got}"
        );
    }
    let p = variant(dir.path(), "pan", true);
    let j = job(&p, 64, 64, 1);
    for t in [0.0, 0.01, 0.25] {
        let got = node_film_position_px(&j, "bar", t).unwrap()[0];
        let want = film_x(-4.0 * t, 64.0, 64.0);
        assert!((got - want).abs() < 2e-3, "pan t = {t}: {got} vs {want}");
    }
}

#[test]
fn unsupported_animation_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_bar(dir.path());
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    doc["animations"][0]["samplers"][0]["interpolation"] = json!("CUBICSPLINE");
    let bad = dir.path().join("bad.gltf");
    std::fs::write(&bad, doc.to_string()).unwrap();
    let e = load_gltf_nodes_at_time(&bad, 0.0)
        .err()
        .expect("refused")
        .to_string();
    assert!(
        !e.contains('\n') && e.contains("animations[0].channels[0]") && e.contains("CUBICSPLINE"),
        "{e}"
    );
    // a static load ignores animations
    assert!(load_gltf(&bad).is_ok());
    let e = load_gltf_nodes_at_time(&p, f64::NAN)
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("NaN"), "{e}");
}

/// Column centroid of the bar (radiance above the wall's) in a render at time t.
fn bar_centroid_px(j: &RenderJob, t: f64) -> f64 {
    let pj = prepare_at_time(j, Some(t)).unwrap();
    let out = render(
        &pj.scene,
        pj.camera.as_ref(),
        pj.camera_to_world,
        &j.settings,
        None,
    );
    let plane = &out.band_planes[0];
    let (mut m0, mut m1) = (0.0, 0.0);
    for (i, v) in plane.iter().enumerate() {
        let c = (i % out.width) as f64 + 0.5; // film x of the pixel centre
        let w = (*v as f64 - bar::WALL_RADIANCE).max(0.0);
        m0 += w;
        m1 += w * c;
    }
    m1 / m0
}

#[test]
fn render_at_a_time_puts_the_bar_where_the_projection_says() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_bar(dir.path());
    let (w, h) = (96u32, 48u32);
    let j = job(&p, w, h, 16);
    for t in [0.0, 0.004, 0.011] {
        let x = bar::BAR_X0_M + bar::BAR_VELOCITY_M_PER_S * t;
        let want = film_x(x, w as f64, h as f64);
        let got = bar_centroid_px(&j, t);
        // pixel-footprint sampling noise of the two edge columns: 16 spp per pixel over 48
        // rows gives a centroid standard error far below 0.05 px
        assert!(
            (got - want).abs() < 0.05,
            "t = {t}: centroid {got} vs {want}"
        );
    }
}
