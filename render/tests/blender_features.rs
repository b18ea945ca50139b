//! glTF as users export it from Blender: normal maps, emissive textures and equirectangular
//! environment lighting, each against a closed form (docs/render.md, "glTF features").
use camsim_core::rng::stream;
use camsim_render::camera::Pinhole;
use camsim_render::envmap::{EnvMap, EnvironmentSpec, RadianceImage, RadianceTexel};
use camsim_render::gltf_load::{load_gltf, pick_camera};
use camsim_render::gltf_write::{flat_spectrum, quad, sphere, GltfBuilder};
use camsim_render::scene::Scene;
use camsim_render::spectral::{cmf_table, rgb_emission, XYZ_TO_SRGB};
use camsim_render::{render, Bands, RenderOutput, RenderSettings};
use glam::{Mat3, Quat, Vec2, Vec3};
use rand::Rng;
use serde_json::json;
use std::path::Path;

fn png(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn settings(spp: u32, bands: &str, max_depth: i32) -> RenderSettings {
    RenderSettings {
        spp,
        seed: 7,
        bands: Bands::parse(bands).unwrap(),
        max_depth,
        variance: true,
        depth_spp: 0,
        ..Default::default()
    }
}

fn render_file(path: &Path, w: u32, s: &RenderSettings) -> (Scene, RenderOutput) {
    let scene = load_gltf(path).unwrap_or_else(|e| panic!("{e}"));
    let c = pick_camera(&scene, None).unwrap().clone();
    let cam = Pinhole {
        perspective: c.perspective(w, w),
    };
    let out = render(&scene, &cam, c.to_world, s, None);
    (scene, out)
}

fn srgb_decode(b: u8) -> f64 {
    camsim_core::colorimetry::srgb_decode(b as f64 / 255.0)
}

/// Relative luminance ∫Lȳ/∫ȳ and linear sRGB (the emission convention's inverse: D65 of unit
/// luminance ↔ RGB (1,1,1)) of band-averaged radiance.
fn rgb_of_bands(bands: &Bands, values: &[f64]) -> [f64; 3] {
    let cmf = cmf_table();
    let (mut xyz, mut ybar) = ([0.0f64; 3], 0.0f64);
    for (w, c) in &cmf {
        ybar += c[1];
        let l = if (*w as f32) >= bands.lo_nm && (*w as f32) < bands.hi_nm() {
            values[bands.index(*w as f32)]
        } else {
            0.0
        };
        for k in 0..3 {
            xyz[k] += l * c[k];
        }
    }
    // relative to ∫ȳ: unit-luminance D65 has Y = 1 and maps to linear sRGB (1, 1, 1)
    let xyz = xyz.map(|v| v / ybar);
    let m = XYZ_TO_SRGB;
    [0, 1, 2].map(|i| m[i][0] * xyz[0] + m[i][1] * xyz[1] + m[i][2] * xyz[2])
}

// ---------------------------------------------------------------- emissive textures

/// A 2 × 2 emissive texture on a quad that fills the view (camera at the origin looking down
/// −z at a 2 × 2 m quad at z = −2, yfov = 2·atan(½)).
fn emissive_texture_scene(dir: &Path, texels: [[u8; 3]; 4], factor: [f64; 3], strength: f64) {
    let mut b = GltfBuilder::new();
    let tex = b.png_texture(&png(2, 2, |x, y| texels[(y * 2 + x) as usize]));
    let m = b.material(json!({"name": "screen",
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "emissiveFactor": factor, "emissiveTexture": {"index": tex},
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}}));
    b.use_extension("KHR_materials_emissive_strength", false);
    let q = quad([
        [-1.0, -1.0, -2.0],
        [1.0, -1.0, -2.0],
        [1.0, 1.0, -2.0],
        [-1.0, 1.0, -2.0],
    ]);
    let mesh = b.mesh("screen", &q, m);
    b.node(json!({"name": "screen", "mesh": mesh}), true);
    let c = b.camera("cam", 2.0 * 0.5f64.atan(), Some(1.0), 0.01);
    b.node(json!({"name": "cam", "camera": c}), true);
    b.write(&dir.join("emissive.gltf")).unwrap();
}

const TEXELS: [[u8; 3]; 4] = [
    [200, 100, 50],
    [30, 180, 90],
    [90, 60, 220],
    [240, 240, 240],
];
const FACTOR: [f64; 3] = [0.8, 1.0, 0.6];
const STRENGTH: f64 = 5.0;

/// The linear RGB radiance of texel `t`: sRGB-decoded × emissiveFactor × emissiveStrength.
fn texel_rgb(t: usize) -> [f64; 3] {
    [0, 1, 2].map(|k| srgb_decode(TEXELS[t][k]) * FACTOR[k] * STRENGTH)
}

/// Seen directly, each texel's radiance is sRGB-decode(texel) × factor × strength upsampled
/// like emissiveFactor: (a) per band, against that upsampling (RadianceTexel, 17³ table) of
/// the independently decoded colour (z-test per band with the renderer's variance), and against the exact Gauss–Newton fit of
/// spectral::rgb_emission within 4 % of the peak (table vs fit: metamers differ in the tails);
/// (b) its luminance and linear sRGB equal the texel's linear RGB (the convention's closed
/// form: RGB (1,1,1) = unit-luminance D65) within 1.5 %.
#[test]
fn emissive_texture_gives_each_texels_radiance() {
    let d = tempfile::tempdir().unwrap();
    emissive_texture_scene(d.path(), TEXELS, FACTOR, STRENGTH);
    let (_, out) = render_file(
        &d.path().join("emissive.gltf"),
        16,
        &settings(64, "380:780:10", 1),
    );
    let bands = out.bands;
    for t in 0..4 {
        // texel (tx, ty) of the image (row 0 = v = 0); the quad's uv (0,0) is its lower-left
        // corner (x = −1, y = −1), so image row 0 is the bottom half of the view
        let (tx, ty) = (t % 2, t / 2);
        let px: Vec<usize> = (0..16 * 16)
            .filter(|i| {
                let (x, y) = (i % 16, i / 16);
                let (ix, iy) = (x / 8, 1 - y / 8);
                let interior = x % 8 != 0 && x % 8 != 7 && y % 8 != 0 && y % 8 != 7;
                interior && ix == tx && iy == ty
            })
            .collect();
        let mean: Vec<f64> = (0..bands.count)
            .map(|b| {
                px.iter()
                    .map(|&i| out.band_planes[b][i] as f64)
                    .sum::<f64>()
                    / px.len() as f64
            })
            .collect();
        let rgb = texel_rgb(t);
        // the documented upsampling of this colour (17³ table): only noise and rounding remain
        let upsampled = RadianceTexel::from_rgb(rgb);
        for b in 0..bands.count {
            let lo = bands.lo_nm + bands.step_nm * b as f32;
            let want = (0..10)
                .map(|k| upsampled.eval(lo + k as f32 + 0.5) as f64)
                .sum::<f64>()
                / 10.0;
            let var = &out.variance_planes.as_ref().unwrap()[b];
            let sd = px.iter().map(|&i| var[i] as f64).sum::<f64>().sqrt() / px.len() as f64;
            let z = (mean[b] - want) / sd.max(1e-9 * want);
            assert!(
                z.abs() < 4.0 && (mean[b] / want - 1.0).abs() < 0.03,
                "texel {t} band {b}: rendered {:.5}, texel spectrum {want:.5}, z {z:.2}",
                mean[b]
            );
        }
        let exact = rgb_emission(rgb);
        let peak = (0..bands.count)
            .map(|b| {
                let lo = bands.lo_nm + bands.step_nm * b as f32;
                (0..10)
                    .map(|k| exact.eval(lo + k as f32 + 0.5) as f64)
                    .sum::<f64>()
                    / 10.0
            })
            .collect::<Vec<_>>();
        let pmax = peak.iter().copied().fold(0.0, f64::max);
        for b in 0..bands.count {
            assert!(
                (mean[b] - peak[b]).abs() < 0.04 * pmax,
                "texel {t} band {b}: rendered {:.4}, rgb_emission {:.4} (peak {pmax:.4})",
                mean[b],
                peak[b]
            );
        }
        let back = rgb_of_bands(&bands, &mean);
        let y = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        assert!(
            (y(back) / y(rgb) - 1.0).abs() < 0.015,
            "texel {t}: luminance {:.4} vs {:.4}",
            y(back),
            y(rgb)
        );
        let m = rgb.iter().copied().fold(0.0, f64::max);
        for k in 0..3 {
            assert!(
                (back[k] - rgb[k]).abs() < 0.03 * m,
                "texel {t}: linear sRGB {back:?} vs {rgb:?}"
            );
        }
    }
}

/// Irradiance from the textured emitter at a point in front of it: next-event estimation
/// (the light sampler with the texture) against a midpoint quadrature of
/// ∫ L(x) cos θ cos θ′ / r² dA over the quad (400 × 400 cells), a z-test.
#[test]
fn textured_emitter_irradiance_matches_quadrature() {
    let d = tempfile::tempdir().unwrap();
    emissive_texture_scene(d.path(), TEXELS, FACTOR, STRENGTH);
    let scene = load_gltf(&d.path().join("emissive.gltf")).unwrap();
    assert_eq!(scene.area_lights.len(), 2);
    let tex = scene.materials[0].emission_texture.as_ref().unwrap();
    let wl = [450.0f32, 520.0, 600.0, 680.0];
    // receiver at (0.3, −0.2, −1.2) facing the quad (+… −z), quad at z = −2 facing +z
    let p = Vec3::new(0.3, -0.2, -1.2);
    let n = Vec3::new(0.1, 0.05, -1.0).normalize();
    let mut want = [0.0f64; 4];
    let k = 400;
    let da = (2.0 / k as f64) * (2.0 / k as f64);
    for j in 0..k {
        for i in 0..k {
            let u = (i as f64 + 0.5) / k as f64;
            let v = (j as f64 + 0.5) / k as f64;
            let x = Vec3::new(-1.0 + 2.0 * u as f32, -1.0 + 2.0 * v as f32, -2.0);
            let to = x - p;
            let r2 = to.length_squared() as f64;
            let w = to.normalize();
            let g = (w.dot(n).max(0.0) * (-w).dot(Vec3::Z).max(0.0)) as f64 / r2;
            let le = tex.eval(Vec2::new(u as f32, v as f32), &wl);
            for s in 0..4 {
                want[s] += le[s] as f64 * g * da;
            }
        }
    }
    let mut rng = stream(3, &[0]);
    let nsamp = 200_000;
    let (mut sum, mut sum2) = ([0.0f64; 4], [0.0f64; 4]);
    let f = |r: &mut camsim_core::rng::CamRng| (r.next_u32() >> 8) as f32 / 16_777_216.0;
    for _ in 0..nsamp {
        let u = f(&mut rng);
        let u2 = Vec2::new(f(&mut rng), f(&mut rng));
        if let Some(ls) = scene.sample_light(p, u, u2, &wl) {
            let c = ls.dir.dot(n).max(0.0) as f64;
            for s in 0..4 {
                let v = ls.weight[s] as f64 * c;
                sum[s] += v;
                sum2[s] += v * v;
            }
        }
    }
    for s in 0..4 {
        let m = sum[s] / nsamp as f64;
        let sd = ((sum2[s] / nsamp as f64 - m * m) / nsamp as f64).sqrt();
        let z = (m - want[s]) / sd;
        eprintln!(
            "λ {}: NEE {m:.5} ± {sd:.5}, quadrature {:.5}, z {z:.2}",
            wl[s], want[s]
        );
        assert!(z.abs() < 4.0, "λ {}: z = {z:.2}", wl[s]);
        assert!((m / want[s] - 1.0).abs() < 0.01);
    }
}

// ---------------------------------------------------------------- normal maps

const RHO: f64 = 0.6;
const E_IRR: f64 = 2.0;

/// A ground quad (y = 0, facing +y, uv u along +x, v along −z) of albedo ρ with an optional
/// normal map of one constant texel, lit by a directional light arriving from direction
/// `from` (unit, pointing to the light), seen from straight above.
fn normal_mapped_plane(
    dir: &Path,
    name: &str,
    texel: Option<[u8; 3]>,
    from: Vec3,
) -> std::path::PathBuf {
    normal_mapped_plane_with(dir, name, texel, from, None, false, false)
}

/// [`normal_mapped_plane`] with a `TANGENT` attribute (the same for all 4 vertices),
/// optionally the ground node mirrored in x (scale (−1, 1, 1)) and optionally the triangles
/// wound clockwise seen from above (geometric normal −y) with the vertex normals still +y.
fn normal_mapped_plane_with(
    dir: &Path,
    name: &str,
    texel: Option<[u8; 3]>,
    from: Vec3,
    tangent: Option<[f32; 4]>,
    mirror_x: bool,
    flip_winding: bool,
) -> std::path::PathBuf {
    let mut b = GltfBuilder::new();
    let mut mat = json!({"name": "ground", "doubleSided": false,
        "pbrMetallicRoughness": {"baseColorFactor": [RHO, RHO, RHO, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extras": {"spectral_reflectance": flat_spectrum(RHO)}});
    if let Some(t) = texel {
        let tex = b.png_texture(&png(4, 4, |_, _| t));
        mat["normalTexture"] = json!({"index": tex, "scale": 1.0});
    }
    let m = b.material(mat);
    let h = 1.0f32;
    let mut q = quad([[-h, 0.0, h], [h, 0.0, h], [h, 0.0, -h], [-h, 0.0, -h]]);
    if flip_winding {
        q.indices = vec![0, 2, 1, 0, 3, 2];
    }
    let mesh = match tangent {
        Some(t) => b.mesh_with_tangents("ground", &q, &[t; 4], m),
        None => b.mesh("ground", &q, m),
    };
    let sx = if mirror_x { -1.0 } else { 1.0 };
    b.node(
        json!({"name": "ground", "mesh": mesh, "scale": [sx, 1.0, 1.0]}),
        true,
    );
    // the light travels along −from: rotate −Z onto −from
    let r = Quat::from_rotation_arc(-Vec3::Z, -from);
    let l = b.light(json!({"type": "directional", "intensity": 1.0,
        "extras": {"spectral_irradiance": flat_spectrum(E_IRR)}}));
    b.node(
        json!({"name": "sun", "rotation": [r.x, r.y, r.z, r.w],
        "extensions": {"KHR_lights_punctual": {"light": l}}}),
        true,
    );
    // camera 1 m above, looking down (−Z → −Y), seeing the middle of the plane
    let c = b.camera("cam", 40f64.to_radians(), Some(1.0), 0.01);
    let rc = Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2);
    b.node(
        json!({"name": "cam", "camera": c, "translation": [0.0, 1.0, 0.0],
        "rotation": [rc.x, rc.y, rc.z, rc.w]}),
        true,
    );
    let p = dir.join(format!("{name}.gltf"));
    b.write(&p).unwrap();
    p
}

/// A flat normal map (128, 128, 255) renders exactly the image without a map (same seed,
/// byte-identical bands), also with indirect light.
#[test]
fn flat_normal_map_changes_nothing() {
    let d = tempfile::tempdir().unwrap();
    let from = Vec3::new(0.3, 1.0, 0.2).normalize();
    let a = normal_mapped_plane(d.path(), "plain", None, from);
    let b = normal_mapped_plane(d.path(), "flat", Some([128, 128, 255]), from);
    let s = settings(8, "380:780:40", -1);
    let (sa, oa) = render_file(&a, 12, &s);
    let (sb, ob) = render_file(&b, 12, &s);
    assert!(sa.materials[0].normal_map.is_none());
    assert!(sb.materials[0].normal_map.is_some());
    assert!(sb.shading.iter().all(|t| t.tangent != u32::MAX));
    assert_eq!(oa.band_planes, ob.band_planes);
}

/// A constant normal map tilted by 45° towards +u on a Lambertian plane under a directional
/// light: L = ρ E max(0, n′·l)/π (the cosine law with the perturbed normal), exact (a
/// directional light and one bounce carry no noise); light below the geometric surface gives
/// L = 0 even where n′·l > 0 (no leak).
#[test]
fn tilted_normal_map_follows_the_cosine_law_and_does_not_leak() {
    let d = tempfile::tempdir().unwrap();
    // texel (218, 128, 218): n_t ∝ (2·218/255 − 1, 0, 2·218/255 − 1) = 45° towards +T
    let texel = [218u8, 128, 218];
    // +T = ∂p/∂u = +x on this plane, so n′ = (sin 45°, cos 45°, 0)
    let n_prime = Vec3::new(1.0, 1.0, 0.0).normalize();
    for beta_deg in [0.0f32, 30.0, 45.0, 80.0, -40.0, 100.0, 120.0] {
        let b = beta_deg.to_radians();
        let from = Vec3::new(b.sin(), b.cos(), 0.0);
        let p = normal_mapped_plane(d.path(), &format!("tilt{beta_deg}"), Some(texel), from);
        // one band: every wavelength slot lands in it (no wavelength-count noise)
        let (_, out) = render_file(&p, 8, &settings(2, "400:700:300", 2));
        let want = if from.y > 0.0 {
            RHO * E_IRR * n_prime.dot(from).max(0.0) as f64 / std::f64::consts::PI
        } else {
            0.0 // below the geometric surface: no light, whatever n′ says
        };
        for bnd in 0..out.bands.count {
            for (i, v) in out.band_planes[bnd].iter().enumerate() {
                assert!(
                    (*v as f64 - want).abs() < 1e-4 * want.max(1.0),
                    "β {beta_deg}°: band {bnd} pixel {i}: {v} vs {want}"
                );
            }
        }
    }
}

// ---------------------------------------------------------------- environment maps

fn write_env_exr(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) {
    let mut ch = [vec![0f32; w * h], vec![0f32; w * h], vec![0f32; w * h]];
    for y in 0..h {
        for x in 0..w {
            let p = f(x, y);
            for k in 0..3 {
                ch[k][y * w + x] = p[k];
            }
        }
    }
    let [r, g, b] = ch;
    camsim_core::exr_io::write_exr_channels(
        path,
        w,
        h,
        vec![
            camsim_core::exr_io::ExrChannel::new("R", r),
            camsim_core::exr_io::ExrChannel::new("G", g),
            camsim_core::exr_io::ExrChannel::new("B", b),
        ],
        &Default::default(),
    )
    .unwrap();
}

/// A test environment: a sky gradient, a bright sun-like patch, a black band.
fn test_env_rgb(x: usize, y: usize, w: usize, h: usize) -> [f32; 3] {
    let v = (y as f32 + 0.5) / h as f32;
    let u = (x as f32 + 0.5) / w as f32;
    if (u - 0.3).abs() < 0.04 && (v - 0.25).abs() < 0.05 {
        return [40.0, 35.0, 25.0];
    }
    if (0.55..0.62).contains(&v) {
        return [0.0; 3];
    }
    [
        0.2 + 0.5 * (1.0 - v),
        0.3 + 0.4 * (1.0 - v),
        0.6 * (1.0 - v) + 0.1 * u,
    ]
}

/// The environment sampler against its density: chi-square over (θ, φ) bins; the density of
/// every sample equals pdf(dir), and the density integrates to 1 over the sphere.
#[test]
fn environment_sampler_matches_its_density() {
    let (w, h) = (64usize, 32usize);
    let rgb: Vec<[f32; 3]> = (0..w * h)
        .map(|i| test_env_rgb(i % w, i / w, w, h))
        .collect();
    let env = EnvMap::new(
        RadianceImage::from_rgb(w as u32, h as u32, &rgb),
        Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(0.3),
    );
    // sampled densities agree with pdf(), and ∫ pdf dω = 1 (midpoint rule on a fine grid)
    let mut rng = stream(5, &[0]);
    let f = |r: &mut camsim_core::rng::CamRng| (r.next_u32() >> 8) as f32 / 16_777_216.0;
    for _ in 0..2000 {
        let s = env.sample(Vec2::new(f(&mut rng), f(&mut rng))).unwrap();
        let p = env.pdf(s.dir);
        assert!((p / s.pdf - 1.0).abs() < 1e-3, "{} vs {}", p, s.pdf);
    }
    let (nt, np) = (800, 1600);
    let mut total = 0.0f64;
    for j in 0..nt {
        let th = std::f64::consts::PI * (j as f64 + 0.5) / nt as f64;
        for i in 0..np {
            let ph = 2.0 * std::f64::consts::PI * (i as f64 + 0.5) / np as f64;
            let dir = Vec3::new(
                (th.sin() * ph.cos()) as f32,
                th.cos() as f32,
                (th.sin() * ph.sin()) as f32,
            );
            total += env.pdf(dir) as f64 * th.sin();
        }
    }
    total *= (std::f64::consts::PI / nt as f64) * (2.0 * std::f64::consts::PI / np as f64);
    assert!((total - 1.0).abs() < 5e-3, "∫ pdf dω = {total}");
    let p = crate::samplers::chi_square(
        200_000,
        24,
        |r| {
            let u = Vec2::new(
                (r.next_u32() >> 8) as f32 / 16_777_216.0,
                (r.next_u32() >> 8) as f32 / 16_777_216.0,
            );
            env.sample(u).map(|s| s.dir)
        },
        |d| env.pdf(d.normalize()) as f64,
        11,
    );
    assert!(p > 1e-3, "p = {p}");
}

/// Orientation (Mitsuba's envmap convention): the image's top row is +y, its centre +z, u = ¼
/// is +x; eval of a direction returns the texel the direction maps to.
#[test]
fn environment_orientation_is_mitsubas() {
    let (w, h) = (8usize, 4usize);
    let rgb: Vec<[f32; 3]> = (0..w * h).map(|i| [i as f32 + 1.0, 0.0, 0.0]).collect();
    let env = EnvMap::new(
        RadianceImage::from_rgb(w as u32, h as u32, &rgb),
        Mat3::IDENTITY,
    );
    let texel = |d: Vec3| {
        let uv = env.uv_of(d.normalize());
        ((uv.y * h as f32) as usize, (uv.x * w as f32) as usize)
    };
    assert_eq!(texel(Vec3::Y).0, 0);
    assert_eq!(texel(-Vec3::Y).0, h - 1);
    assert_eq!(texel(Vec3::new(0.0, 0.1, 1.0)), (1, w / 2));
    assert_eq!(texel(Vec3::new(1.0, 0.1, 0.0)), (1, w / 4));
    assert_eq!(texel(Vec3::new(-1.0, -0.1, 0.0)), (2, 3 * w / 4));
    for (u, v) in [(0.1f32, 0.2f32), (0.6, 0.7), (0.9, 0.45)] {
        let d = env.dir_of(Vec2::new(u, v));
        let back = env.uv_of(d);
        assert!((back - Vec2::new(u, v)).length() < 1e-5);
    }
}

/// Furnace: a white (ρ = 1) Lambertian sphere inside a constant environment is invisible —
/// every pixel, sphere or background, has the environment's radiance (z-test per band), with
/// environment next-event estimation and BSDF sampling combined by MIS.
#[test]
fn white_sphere_in_constant_environment_is_invisible() {
    let d = tempfile::tempdir().unwrap();
    let exr = d.path().join("const.exr");
    write_env_exr(&exr, 16, 8, |_, _| [0.5, 0.5, 0.5]);
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "white",
        "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extras": {"spectral_reflectance": flat_spectrum(1.0)}}));
    let mut sp = sphere([0.0, 0.0, -3.0], 1.0, 24, 48, false);
    sp.normals.clear();
    let mesh = b.mesh("ball", &sp, m);
    b.node(json!({"name": "ball", "mesh": mesh}), true);
    let c = b.camera("cam", 45f64.to_radians(), Some(1.0), 0.01);
    b.node(json!({"name": "cam", "camera": c}), true);
    b.scene_extras(json!({"camsim_environment_exr": "const.exr"}));
    let p = d.path().join("scene.gltf");
    b.write(&p).unwrap();
    let (scene, out) = render_file(&p, 16, &settings(32, "380:780:50", -1));
    assert!(scene.environment.is_some());
    let texel = RadianceTexel::from_rgb([0.5, 0.5, 0.5]);
    let var = out.variance_planes.as_ref().unwrap();
    let n = (out.width * out.height) as f64;
    for bnd in 0..out.bands.count {
        let lo = out.bands.lo_nm + out.bands.step_nm * bnd as f32;
        let want = (0..50)
            .map(|k| texel.eval(lo + k as f32 + 0.5) as f64)
            .sum::<f64>()
            / 50.0;
        let mean = out.band_planes[bnd].iter().map(|v| *v as f64).sum::<f64>() / n;
        let sd = var[bnd].iter().map(|v| *v as f64).sum::<f64>().sqrt() / n;
        let z = (mean - want) / sd.max(1e-12);
        assert!(
            z.abs() < 4.0,
            "band {bnd}: mean {mean:.5}, environment {want:.5}, z {z:.2}"
        );
        assert!(
            (mean / want - 1.0).abs() < 0.02,
            "band {bnd}: {mean} vs {want}"
        );
    }
}

/// Render settings override the scene's environment, and bad environment input gives one
/// error line naming the file.
#[test]
fn environment_settings_and_errors() {
    let d = tempfile::tempdir().unwrap();
    let exr = d.path().join("sky.exr");
    write_env_exr(&exr, 8, 4, |x, y| test_env_rgb(x, y, 8, 4));
    let bad = d.path().join("neg.exr");
    write_env_exr(
        &bad,
        4,
        2,
        |x, _| if x == 3 { [-1.0, 0.0, 0.0] } else { [1.0; 3] },
    );
    let spec = |f: &Path, s: f64| EnvironmentSpec {
        exr: f.to_path_buf(),
        strength: s,
        rotation_y_deg: 0.0,
    };
    let e = camsim_render::envmap::load_environment(&spec(&bad, 1.0))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("neg.exr") && e.contains("x 3") && !e.contains('\n'),
        "{e}"
    );
    let e = camsim_render::envmap::load_environment(&spec(&exr, -2.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("strength") && !e.contains('\n'), "{e}");
    let e = camsim_render::envmap::load_environment(&spec(&d.path().join("none.exr"), 1.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("none.exr") && !e.contains('\n'), "{e}");
    let env = camsim_render::envmap::load_environment(&spec(&exr, 2.0)).unwrap();
    // strength multiplies the radiance
    let env1 = camsim_render::envmap::load_environment(&spec(&exr, 1.0)).unwrap();
    let wl = [550.0f32; 4];
    let dir = Vec3::new(0.2, 0.5, -0.4).normalize();
    assert!((env.eval(dir, &wl)[0] / env1.eval(dir, &wl)[0] - 2.0).abs() < 1e-5);
}

/// An override (`--environment`) replaces the scene's extras without reading them: a scene
/// whose extras name a missing map fails to load on its own (one line naming the file) and
/// loads with an override, lit by the override's map (at its strength), also at a time.
#[test]
fn environment_override_does_not_read_the_scenes_map() {
    let d = tempfile::tempdir().unwrap();
    let exr = d.path().join("sky.exr");
    write_env_exr(&exr, 8, 4, |x, y| test_env_rgb(x, y, 8, 4));
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "white",
        "extras": {"spectral_reflectance": flat_spectrum(1.0)}}));
    let mesh = b.mesh("ball", &sphere([0.0, 0.0, -3.0], 1.0, 6, 12, false), m);
    b.node(json!({"name": "ball", "mesh": mesh}), true);
    let c = b.camera("cam", 45f64.to_radians(), Some(1.0), 0.01);
    b.node(json!({"name": "cam", "camera": c}), true);
    b.scene_extras(json!({"camsim_environment_exr": "missing.exr"}));
    let p = d.path().join("scene.gltf");
    b.write(&p).unwrap();
    let e = load_gltf(&p)
        .err()
        .expect("missing map refused")
        .to_string();
    assert!(e.contains("missing.exr") && !e.contains('\n'), "{e}");
    let spec = EnvironmentSpec {
        exr: exr.clone(),
        strength: 3.0,
        rotation_y_deg: 0.0,
    };
    let want = camsim_render::envmap::load_environment(&spec).unwrap();
    let wl = [550.0f32, 450.0, 650.0, 600.0];
    let dir = Vec3::new(0.2, 0.5, -0.4).normalize();
    for t in [None, Some(0.0)] {
        let scene = camsim_render::gltf_load::load_gltf_with_environment(&p, t, &spec).unwrap();
        let got = scene.environment.as_ref().expect("override applied");
        assert_eq!(got.eval(dir, &wl), want.eval(dir, &wl));
    }
    let e = camsim_render::gltf_load::load_gltf_with_environment(&p, Some(f64::NAN), &spec)
        .err()
        .expect("NaN time refused")
        .to_string();
    assert!(e.contains("must be finite"), "{e}");
}

/// Unbiased environment sampling with the bilinear lookup: the irradiance ∫ L(ω) max(0, n·ω)
/// dω of a map with black texels next to bright ones, estimated with the environment sampler
/// (L/pdf), equals a fine midpoint quadrature of the same lookup (z-test).
#[test]
fn environment_sampling_estimates_irradiance_without_bias() {
    let (w, h) = (32usize, 16usize);
    let rgb: Vec<[f32; 3]> = (0..w * h)
        .map(|i| test_env_rgb(i % w, i / w, w, h))
        .collect();
    let env = EnvMap::new(
        RadianceImage::from_rgb(w as u32, h as u32, &rgb),
        Mat3::from_rotation_y(0.4),
    );
    let wl = [430.0f32, 510.0, 590.0, 670.0];
    for n in [Vec3::Y, Vec3::new(0.6, -0.3, 0.5).normalize()] {
        let (nt, np) = (600, 1200);
        let mut want = [0.0f64; 4];
        for j in 0..nt {
            let th = std::f64::consts::PI * (j as f64 + 0.5) / nt as f64;
            for i in 0..np {
                let ph = 2.0 * std::f64::consts::PI * (i as f64 + 0.5) / np as f64;
                let d = Vec3::new(
                    (th.sin() * ph.cos()) as f32,
                    th.cos() as f32,
                    (th.sin() * ph.sin()) as f32,
                );
                let c = d.dot(n).max(0.0) as f64 * th.sin();
                if c > 0.0 {
                    let l = env.eval(d, &wl);
                    for k in 0..4 {
                        want[k] += l[k] as f64 * c;
                    }
                }
            }
        }
        let dw = (std::f64::consts::PI / nt as f64) * (2.0 * std::f64::consts::PI / np as f64);
        let want = want.map(|v| v * dw);
        let mut rng = stream(17, &[0]);
        let f = |r: &mut camsim_core::rng::CamRng| (r.next_u32() >> 8) as f32 / 16_777_216.0;
        let ns = 400_000;
        let (mut s1, mut s2) = ([0.0f64; 4], [0.0f64; 4]);
        for _ in 0..ns {
            if let Some(s) = env.sample(Vec2::new(f(&mut rng), f(&mut rng))) {
                let c = s.dir.dot(n).max(0.0);
                if c > 0.0 {
                    let l = env.eval(s.dir, &wl);
                    for k in 0..4 {
                        let v = (l[k] * c / s.pdf) as f64;
                        s1[k] += v;
                        s2[k] += v * v;
                    }
                }
            }
        }
        for k in 0..4 {
            let m = s1[k] / ns as f64;
            let sd = ((s2[k] / ns as f64 - m * m) / ns as f64).sqrt();
            let z = (m - want[k]) / sd;
            eprintln!(
                "n {n:?} λ {}: sampled {m:.5} ± {sd:.5}, quadrature {:.5}",
                wl[k], want[k]
            );
            assert!(z.abs() < 4.0, "λ {}: z = {z:.2}", wl[k]);
        }
    }
}

/// The glTF `TANGENT` attribute is used when present: T = +z tilts n′ towards +z; under a
/// mirroring node (scale (−1, 1, 1)) T is transformed and its handedness w flipped, so a map
/// tilting towards +B (bitangent w·N×T = −z on the unmirrored plane) still tilts towards −z.
/// Both against ρE·max(0, n′·l)/π, exact.
#[test]
fn tangent_attribute_and_mirroring_follow_the_cosine_law() {
    let d = tempfile::tempdir().unwrap();
    let s2 = std::f32::consts::FRAC_1_SQRT_2;
    // (texel, TANGENT, mirror, expected n′)
    let cases = [
        (
            [218u8, 128, 218],
            [0.0f32, 0.0, 1.0, 1.0],
            false,
            Vec3::new(0.0, s2, s2),
        ),
        (
            [128u8, 218, 218],
            [1.0f32, 0.0, 0.0, 1.0],
            true,
            Vec3::new(0.0, s2, -s2),
        ),
        (
            [128u8, 218, 218],
            [1.0f32, 0.0, 0.0, 1.0],
            false,
            Vec3::new(0.0, s2, -s2),
        ),
    ];
    for (k, (texel, tan, mirror, n_prime)) in cases.into_iter().enumerate() {
        for beta_deg in [0.0f32, 30.0, 60.0, -30.0] {
            let b = beta_deg.to_radians();
            // light in the plane of n′ and +y, β from the zenith towards n′
            let side = Vec3::new(n_prime.x, 0.0, n_prime.z).normalize();
            let from = Vec3::Y * b.cos() + side * b.sin();
            let p = normal_mapped_plane_with(
                d.path(),
                &format!("t{k}_{beta_deg}"),
                Some(texel),
                from,
                Some(tan),
                mirror,
                false,
            );
            let (_, out) = render_file(&p, 8, &settings(2, "400:700:300", 2));
            let want = RHO * E_IRR * n_prime.dot(from).max(0.0) as f64 / std::f64::consts::PI;
            for v in &out.band_planes[0] {
                assert!(
                    (*v as f64 - want).abs() < 1e-4,
                    "case {k} β {beta_deg}°: {v} vs {want}"
                );
            }
        }
    }
}

/// Generated tangents take their handedness from the side the vertex normals face, as the
/// shading frame B = w·(N × T) does: a plane wound clockwise (geometric normal −y) with vertex
/// normals +y and a map tilting towards +B (B = ∂p/∂v′ = +z on this plane, v′ = −v) tilts n′
/// towards +z exactly as the counter-clockwise plane does (ρE·max(0, n′·l)/π, exact). With the
/// handedness taken from the geometric normal, the clockwise plane tilted towards −z.
#[test]
fn generated_tangents_follow_the_vertex_normals_side() {
    let d = tempfile::tempdir().unwrap();
    let s2 = std::f32::consts::FRAC_1_SQRT_2;
    let n_prime = Vec3::new(0.0, s2, s2);
    for flip in [false, true] {
        for beta_deg in [0.0f32, 30.0, 60.0, -30.0] {
            let b = beta_deg.to_radians();
            let from = Vec3::Y * b.cos() + Vec3::Z * b.sin();
            let p = normal_mapped_plane_with(
                d.path(),
                &format!("w{flip}_{beta_deg}"),
                Some([128u8, 218, 218]),
                from,
                None,
                false,
                flip,
            );
            let (_, out) = render_file(&p, 8, &settings(2, "400:700:300", 2));
            let want = RHO * E_IRR * n_prime.dot(from).max(0.0) as f64 / std::f64::consts::PI;
            for v in &out.band_planes[0] {
                assert!(
                    (*v as f64 - want).abs() < 1e-4,
                    "clockwise {flip} β {beta_deg}°: {v} vs {want}"
                );
            }
        }
    }
}

/// glTF's emission is emissiveFactor × emissiveTexture: an all-black texture emits nothing,
/// whatever the factor (the scene has no other light, so the image is black).
#[test]
fn black_emissive_texture_emits_nothing() {
    let d = tempfile::tempdir().unwrap();
    emissive_texture_scene(d.path(), [[0, 0, 0]; 4], FACTOR, STRENGTH);
    let (scene, out) = render_file(
        &d.path().join("emissive.gltf"),
        8,
        &settings(4, "380:780:40", 2),
    );
    assert!(
        scene.materials.iter().all(|m| !m.emits()),
        "a black emissive texture made an emitter"
    );
    let worst = out
        .band_planes
        .iter()
        .flat_map(|p| p.iter())
        .fold(0f32, |a, v| a.max(v.abs()));
    assert_eq!(worst, 0.0, "black emissive texture: radiance {worst}");
    // the same scene with a grey texture does emit (the check above is not vacuous)
    emissive_texture_scene(d.path(), [[128, 128, 128]; 4], FACTOR, STRENGTH);
    let (_, out) = render_file(
        &d.path().join("emissive.gltf"),
        8,
        &settings(4, "380:780:40", 2),
    );
    assert!(out
        .band_planes
        .iter()
        .flat_map(|p| p.iter())
        .any(|v| *v > 0.0));
}
