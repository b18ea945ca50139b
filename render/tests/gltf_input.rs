//! glTF input: the loader's conventions (node hierarchy, mirrored transforms, .glb, textures,
//! cameras by name) and its errors — each bad file gives one clear line, never a panic.
use camsim_render::camera::Pinhole;
use camsim_render::gltf_load::{load_gltf, pick_camera};
use camsim_render::gltf_write::{flat_spectrum, quad, GltfBuilder};
use camsim_render::{render, Bands, RenderError, RenderSettings};
use serde_json::json;
use std::path::Path;

/// One emissive quad facing +z at z = −2 in front of a camera at the origin.
fn emitter_scene() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "em", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(3.0)}}));
    let q = quad([
        [-1.0, -1.0, -2.0],
        [1.0, -1.0, -2.0],
        [1.0, 1.0, -2.0],
        [-1.0, 1.0, -2.0],
    ]);
    let mesh = b.mesh("quad", &q, m);
    b.node(json!({"name": "quad", "mesh": mesh}), true);
    let c = b.camera("cam", 30f64.to_radians(), Some(1.0), 0.01);
    b.node(json!({"name": "main", "camera": c}), true);
    b
}

fn err_of(p: &Path) -> String {
    match load_gltf(p) {
        Ok(_) => panic!("{} loaded but should not", p.display()),
        Err(e) => {
            let s = e.to_string();
            assert!(!s.contains('\n'), "multi-line error: {s}");
            assert!(matches!(e, RenderError::Scene { .. }));
            s
        }
    }
}

fn mean_band0(path: &Path) -> f64 {
    let scene = load_gltf(path).unwrap();
    let c = pick_camera(&scene, None).unwrap();
    let cam = Pinhole {
        perspective: c.perspective(16, 16),
    };
    let s = RenderSettings {
        spp: 4,
        bands: Bands::parse("500:600:100").unwrap(),
        depth_spp: 0,
        ..Default::default()
    };
    let out = render(&scene, &cam, c.to_world, &s, None);
    out.band_planes[0].iter().map(|v| *v as f64).sum::<f64>() / 256.0
}

#[test]
fn gltf_and_glb_load_alike() {
    let d = tempfile::tempdir().unwrap();
    let b = emitter_scene();
    let (p1, p2, p3) = (
        d.path().join("a.gltf"),
        d.path().join("b.glb"),
        d.path().join("c.gltf"),
    );
    b.write(&p1).unwrap();
    b.write_glb(&p2).unwrap();
    b.write_embedded(&p3).unwrap();
    for p in [&p1, &p2, &p3] {
        let s = load_gltf(p).unwrap();
        assert_eq!(s.tris.len(), 2);
        // the quad fills the 30° view (tan 15° · 2 m = 0.54 m < 1 m): every pixel sees Le = 3
        assert!((mean_band0(p) - 3.0).abs() < 1e-5);
    }
    // camera by name
    let s = load_gltf(&p1).unwrap();
    assert!(pick_camera(&s, Some("main")).is_ok());
    let e = pick_camera(&s, Some("nope")).unwrap_err();
    assert!(e.contains("main"), "{e}");
}

/// World = parent · child, vertices baked; a mirroring parent (det < 0) flips the winding so
/// the front face (and its one-sided emission) stays where the geometry says.
#[test]
fn node_hierarchy_and_mirroring() {
    let d = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "em", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(2.0)}}));
    // quad at z = +2 facing −z (towards the origin) in local space...
    let q = quad([
        [-1.0, -1.0, 2.0],
        [-1.0, 1.0, 2.0],
        [1.0, 1.0, 2.0],
        [1.0, -1.0, 2.0],
    ]);
    let mesh = b.mesh("quad", &q, m);
    // ...mirrored by the parent's scale z → −z: it lands at z = −2 and must face +z
    let child = b.node(
        json!({"name": "child", "mesh": mesh, "translation": [0.0, 0.0, 0.5]}),
        false,
    );
    b.node(json!({"name": "parent", "scale": [1.0, 1.0, -1.0], "translation": [0.0, 0.0, 0.5], "children": [child]}), true);
    let c = b.camera("cam", 30f64.to_radians(), Some(1.0), 0.01);
    b.node(json!({"name": "cam", "camera": c}), true);
    let p = d.path().join("m.gltf");
    b.write(&p).unwrap();
    let s = load_gltf(&p).unwrap();
    // parent·child: z = 0.5 − (2 + 0.5) = −2
    for t in &s.tris {
        assert!(((t.v0.z) + 2.0).abs() < 1e-6);
    }
    for sh in &s.shading {
        assert!(sh.ng.z > 0.99, "normal {:?}", sh.ng);
        assert!(sh.n[0].z > 0.99, "shading normal {:?}", sh.n[0]);
    }
    assert!((mean_band0(&p) - 2.0).abs() < 1e-5);
}

/// A base-colour texture is sampled at the hit's UV: a red/blue texture gives a red half and
/// a blue half (with the spectra of the fitted RGB).
#[test]
fn base_color_texture_is_sampled_at_the_hit() {
    let d = tempfile::tempdir().unwrap();
    let mut png = Vec::new();
    let img = image::RgbImage::from_fn(2, 1, |x, _| {
        if x == 0 {
            image::Rgb([230, 20, 20])
        } else {
            image::Rgb([20, 20, 230])
        }
    });
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let mut b = GltfBuilder::new();
    let tex = b.png_texture(&png);
    let m = b.material(json!({"name": "tex", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0,
        "baseColorTexture": {"index": tex}}}));
    let em = b.material(json!({"name": "sky", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(1.0)}}));
    // plane facing +z at z = −2 with u along +x; behind the camera an emitter sphere
    let q = quad([
        [-1.0, -1.0, -2.0],
        [1.0, -1.0, -2.0],
        [1.0, 1.0, -2.0],
        [-1.0, 1.0, -2.0],
    ]);
    let mesh = b.mesh("plane", &q, m);
    b.node(json!({"name": "plane", "mesh": mesh}), true);
    let sky = b.mesh(
        "sky",
        &camsim_render::gltf_write::sphere([0.0; 3], 10.0, 16, 32, true),
        em,
    );
    b.node(json!({"name": "sky", "mesh": sky}), true);
    let c = b.camera("cam", 30f64.to_radians(), Some(1.0), 0.01);
    b.node(json!({"name": "cam", "camera": c}), true);
    let p = d.path().join("t.gltf");
    b.write(&p).unwrap();
    let scene = load_gltf(&p).unwrap();
    let cam = Pinhole {
        perspective: scene.cameras[0].perspective(16, 16),
    };
    let s = RenderSettings {
        spp: 16,
        bands: Bands::parse("400:700:100").unwrap(),
        depth_spp: 0,
        ..Default::default()
    };
    let out = render(&scene, &cam, scene.cameras[0].to_world, &s, None);
    let half = |b: usize, left: bool| -> f64 {
        let mut v = 0.0;
        for y in 0..16 {
            for x in 0..16 {
                if (x < 8) == left {
                    v += out.band_planes[b][y * 16 + x] as f64;
                }
            }
        }
        v / 128.0
    };
    // blue (400–500) brighter on the right, red (600–700) brighter on the left
    assert!(
        half(2, true) > 3.0 * half(2, false),
        "red {} vs {}",
        half(2, true),
        half(2, false)
    );
    assert!(
        half(0, false) > 3.0 * half(0, true),
        "blue {} vs {}",
        half(0, false),
        half(0, true)
    );
}

#[test]
fn missing_buffer_is_a_clear_error() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.gltf");
    emitter_scene().write(&p).unwrap();
    std::fs::remove_file(d.path().join("a.bin")).unwrap();
    let e = err_of(&p);
    assert!(
        e.contains("buffer 0") && e.contains("a.bin") && e.contains("cannot load"),
        "{e}"
    );
    // a truncated buffer
    emitter_scene().write(&p).unwrap();
    let bin = std::fs::read(d.path().join("a.bin")).unwrap();
    std::fs::write(d.path().join("a.bin"), &bin[..bin.len() / 2]).unwrap();
    let e = err_of(&p);
    assert!(e.contains("byteLength"), "{e}");
}

#[test]
fn unsupported_required_extension_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.gltf");
    let mut b = emitter_scene();
    b.use_extension("KHR_draco_mesh_compression", true);
    b.write(&p).unwrap();
    let e = err_of(&p);
    assert!(
        e.contains("KHR_draco_mesh_compression") && e.contains("extensionsRequired"),
        "{e}"
    );
    // used but not required: fine
    let mut b = emitter_scene();
    b.use_extension("KHR_materials_clearcoat", false);
    b.write(&p).unwrap();
    assert!(load_gltf(&p).is_ok());
}

#[test]
fn nan_vertices_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.gltf");
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "w"}));
    let mut q = quad([
        [-1.0, -1.0, -2.0],
        [1.0, -1.0, -2.0],
        [1.0, 1.0, -2.0],
        [-1.0, 1.0, -2.0],
    ]);
    q.positions[2][1] = f32::NAN;
    let mesh = b.mesh("bad", &q, m);
    b.node(json!({"name": "bad", "mesh": mesh}), true);
    let c = b.camera("cam", 0.5, None, 0.01);
    b.node(json!({"camera": c}), true);
    b.write(&p).unwrap();
    let e = err_of(&p);
    assert!(e.contains("POSITION[2]") && e.contains("not finite"), "{e}");
}

#[test]
fn a_scene_without_camera_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.gltf");
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "w"}));
    let mesh = b.mesh(
        "q",
        &quad([
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ]),
        m,
    );
    b.node(json!({"mesh": mesh}), true);
    b.write(&p).unwrap();
    let e = err_of(&p);
    assert!(e.contains("no camera"), "{e}");
}

#[test]
fn other_bad_inputs_give_one_line_errors() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.gltf");
    // not a file
    assert!(err_of(&d.path().join("missing.gltf")).contains("cannot read"));
    // not JSON
    std::fs::write(&p, "{ nope").unwrap();
    assert!(err_of(&p).contains("not a valid glTF"));
    // out-of-range accessor index (validation)
    let mut doc = emitter_scene().document("a.bin");
    emitter_scene().write(&p).unwrap();
    doc["meshes"][0]["primitives"][0]["indices"] = json!(99);
    std::fs::write(&p, doc.to_string()).unwrap();
    assert!(err_of(&p).contains("invalid glTF"));
    // a Mitsuba BSDF without an explicit GGX distribution (Mitsuba's default is beckmann)
    let mut b = emitter_scene();
    b.material(json!({"name": "x"}));
    let mut doc = b.document("a.bin");
    doc["materials"][0]["extras"]["mitsuba_bsdf"] =
        json!({"type": "roughconductor", "material": "Au", "alpha": 0.2});
    std::fs::write(&p, doc.to_string()).unwrap();
    let e = err_of(&p);
    assert!(e.contains("ggx") && e.contains("beckmann"), "{e}");
    // an unknown metal
    doc["materials"][0]["extras"]["mitsuba_bsdf"] =
        json!({"type": "roughconductor", "material": "Xx", "alpha": 0.2, "distribution": "ggx"});
    std::fs::write(&p, doc.to_string()).unwrap();
    assert!(err_of(&p).contains("unknown metal \"Xx\""));
    // a malformed spectral extra
    doc["materials"][0]["extras"] =
        json!({"spectral_emission": {"wavelength_nm": [500, 400], "values": [1, 1]}});
    std::fs::write(&p, doc.to_string()).unwrap();
    assert!(err_of(&p).contains("spectral_emission"));
    // a bad thin lens
    let mut doc = emitter_scene().document("a.bin");
    doc["nodes"][1]["extras"] =
        json!({"thinlens": {"aperture_radius": -1.0, "focus_distance": 2.0}});
    std::fs::write(&p, doc.to_string()).unwrap();
    assert!(err_of(&p).contains("thinlens"));
    // an index past the vertex count
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "w"}));
    let mut q = quad([
        [0.0, 0.0, -1.0],
        [1.0, 0.0, -1.0],
        [1.0, 1.0, -1.0],
        [0.0, 1.0, -1.0],
    ]);
    q.indices[4] = 7;
    let mesh = b.mesh("q", &q, m);
    b.node(json!({"mesh": mesh}), true);
    let c = b.camera("cam", 0.5, None, 0.01);
    b.node(json!({"camera": c}), true);
    b.write(&p).unwrap();
    assert!(err_of(&p).contains("out of range"));
}
