//! Write the glTF scenes of the Blender-export features (`cargo run --release -p camsim-render
//! --example make_blender_scenes`):
//!
//! * `scenes/blender/showcase.gltf` (+ `.bin`, `sky.exr`): a normal-mapped tiled floor, a
//!   screen with an emissive texture, a diffuse sphere, lit by an equirectangular environment
//!   named in the scene's extras (`camsim_environment_exr`) — every feature in one small file;
//! * `scenes/mitsuba/envmap.gltf` (+ `.bin`, `envmap_sky.exr`): the Mitsuba 3 cross-check of
//!   environment lighting (a sphere on a ground plane under a smooth grey sky with a
//!   sun-like blob; references by tools/mitsuba_refs.sh envmap).
use camsim_core::exr_io::{write_exr_channels, ExrChannel, ExrHeader};
use camsim_render::gltf_write::{flat_spectrum, quad, sphere, GltfBuilder};
use glam::{Quat, Vec3};
use serde_json::json;
use std::path::{Path, PathBuf};

fn png(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .expect("encode PNG");
    out
}

fn write_rgb_exr(path: &Path, w: usize, h: usize, f: impl Fn(f32, f32) -> [f32; 3]) {
    let mut ch = [vec![0f32; w * h], vec![0f32; w * h], vec![0f32; w * h]];
    for y in 0..h {
        for x in 0..w {
            let p = f((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
            for k in 0..3 {
                ch[k][y * w + x] = p[k];
            }
        }
    }
    let [r, g, b] = ch;
    write_exr_channels(
        path,
        w,
        h,
        vec![
            ExrChannel::new("R", r),
            ExrChannel::new("G", g),
            ExrChannel::new("B", b),
        ],
        &ExrHeader::default(),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    println!("wrote {}", path.display());
}

/// A smooth sky (linear RGB radiance at map coordinates u, v): blue zenith to a pale horizon,
/// a dim ground below, and a Gaussian sun-like blob (σ ≈ 6°) at u = 0.3, v = 0.3.
fn sky(u: f32, v: f32) -> [f32; 3] {
    let up = 1.0 - 2.0 * v; // cos θ
    let base = if up >= 0.0 {
        [0.35 + 0.45 * (1.0 - up), 0.5 + 0.35 * (1.0 - up), 0.9]
    } else {
        [0.12, 0.1, 0.08]
    };
    let du = (u - 0.3).abs().min(1.0 - (u - 0.3).abs()) * 2.0 * std::f32::consts::PI;
    let dv = (v - 0.3) * std::f32::consts::PI;
    let r2 = du * du * (std::f32::consts::PI * 0.3).sin().powi(2) + dv * dv;
    let sun = 25.0 * (-r2 / (2.0 * 0.1f32.powi(2))).exp();
    [base[0] + sun, base[1] + 0.95 * sun, base[2] + 0.8 * sun]
}

fn look_at(b: &mut GltfBuilder, eye: Vec3, target: Vec3, yfov_deg: f64) {
    let c = b.camera("camera", yfov_deg.to_radians(), Some(1.0), 0.01);
    // the camera looks down its −Z with +Y up
    let f = (target - eye).normalize();
    let r = f.cross(Vec3::Y).normalize();
    let u = r.cross(f);
    let q = Quat::from_mat3(&glam::Mat3::from_cols(r, u, -f));
    b.node(
        json!({"name": "camera", "camera": c, "translation": [eye.x, eye.y, eye.z],
               "rotation": [q.x, q.y, q.z, q.w]}),
        true,
    );
}

fn diffuse(b: &mut GltfBuilder, name: &str, rho: f64) -> usize {
    b.material(json!({"name": name,
        "pbrMetallicRoughness": {"baseColorFactor": [rho, rho, rho, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extras": {"spectral_reflectance": flat_spectrum(rho)}}))
}

fn ground(b: &mut GltfBuilder, half: f32, tiles: f32, m: usize) {
    let mut q = quad([
        [-half, 0.0, half],
        [half, 0.0, half],
        [half, 0.0, -half],
        [-half, 0.0, -half],
    ]);
    for uv in q.uvs.iter_mut() {
        uv[0] *= tiles;
        uv[1] *= tiles;
    }
    let mesh = b.mesh("ground", &q, m);
    b.node(json!({"name": "ground", "mesh": mesh}), true);
}

fn envmap_scene(dir: &Path) {
    let mut b = GltfBuilder::new();
    let g = diffuse(&mut b, "ground", 0.5);
    ground(&mut b, 10.0, 1.0, g);
    let s = diffuse(&mut b, "ball", 0.8);
    let mesh = b.mesh("ball", &sphere([0.0, 0.5, 0.0], 0.5, 24, 48, false), s);
    b.node(json!({"name": "ball", "mesh": mesh}), true);
    look_at(
        &mut b,
        Vec3::new(0.0, 1.2, 3.0),
        Vec3::new(0.0, 0.6, 0.0),
        40.0,
    );
    b.scene_extras(json!({"camsim_environment_exr": "envmap_sky.exr",
        "camsim_environment_strength": 1.0, "camsim_environment_rotation_deg": 30.0}));
    // neutral (r = g = b): Mitsuba upsamples RGB with its own coefficient table, whose
    // metamers differ from camsim's by ±1 % between 400 and 700 nm for coloured texels (same
    // colour, different spectra); a grey map is D65-shaped in both, so the comparison checks
    // the orientation, the D65 convention, the sampling and MIS without that difference
    write_rgb_exr(&dir.join("envmap_sky.exr"), 128, 64, |u, v| {
        let c = sky(u, v);
        let y = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        [y, y, y]
    });
    let p = dir.join("envmap.gltf");
    b.write(&p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    println!("wrote {}", p.display());
}

fn showcase(dir: &Path) {
    let mut b = GltfBuilder::new();
    // floor: square tiles with bevelled edges as a tangent-space normal map (32 × 32 texels,
    // repeated 6 times across the floor)
    let n = 32u32;
    let normal_png = png(n, n, |x, y| {
        let edge = |t: u32| -> f32 {
            if t < 3 {
                -0.6
            } else if t >= n - 3 {
                0.6
            } else {
                0.0
            }
        };
        let (nx, ny) = (edge(x), -edge(y)); // +Y of the map is up in the image
        let v = Vec3::new(nx, ny, 1.0).normalize();
        let enc = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
        [enc(v.x), enc(v.y), enc(v.z)]
    });
    let nt = b.png_texture(&normal_png);
    let floor = b.material(json!({"name": "tiles",
        "pbrMetallicRoughness": {"baseColorFactor": [0.55, 0.5, 0.45, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "normalTexture": {"index": nt, "scale": 1.0}}));
    ground(&mut b, 3.0, 6.0, floor);
    // a screen with an emissive texture (a 16 × 8 colour pattern), facing +z
    let emissive_png = png(16, 8, |x, y| {
        let c = [
            [230u8, 60, 40],
            [40, 200, 80],
            [50, 90, 230],
            [240, 220, 60],
        ];
        c[((x / 4) + 2 * (y / 4)) as usize % 4]
    });
    let et = b.png_texture(&emissive_png);
    let screen = b.material(json!({"name": "screen",
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "emissiveFactor": [1.0, 1.0, 1.0], "emissiveTexture": {"index": et},
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}}));
    b.use_extension("KHR_materials_emissive_strength", false);
    let q = quad([
        [-1.2, 0.2, -1.5],
        [1.2, 0.2, -1.5],
        [1.2, 1.4, -1.5],
        [-1.2, 1.4, -1.5],
    ]);
    let mesh = b.mesh("screen", &q, screen);
    b.node(json!({"name": "screen", "mesh": mesh}), true);
    let ball = diffuse(&mut b, "ball", 0.8);
    let mesh = b.mesh("ball", &sphere([0.6, 0.4, 0.0], 0.4, 24, 48, false), ball);
    b.node(json!({"name": "ball", "mesh": mesh}), true);
    look_at(
        &mut b,
        Vec3::new(0.0, 1.3, 3.2),
        Vec3::new(0.0, 0.5, -0.5),
        45.0,
    );
    b.scene_extras(json!({"camsim_environment_exr": "sky.exr",
        "camsim_environment_strength": 1.0, "camsim_environment_rotation_deg": 0.0}));
    write_rgb_exr(&dir.join("sky.exr"), 64, 32, sky);
    let p = dir.join("showcase.gltf");
    b.write(&p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    println!("wrote {}", p.display());
}

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let blender = root.join("blender");
    std::fs::create_dir_all(&blender).expect("create scenes/blender");
    showcase(&blender);
    envmap_scene(&root.join("mitsuba"));
}
