//! Closed-form checks of the renderer on the scenes of scenes/ (built in code by
//! camsim_render::test_scenes): z-tests of image means against the exact answer with the
//! renderer's own per-pixel variance estimates, exact depth, thin lens → pinhole, and
//! thread-count independence.
use camsim_render::camera::{Camera, Pinhole, ThinLens};
use camsim_render::gltf_load::load_gltf;
use camsim_render::gltf_write::GltfBuilder;
use camsim_render::scene::Scene;
use camsim_render::test_scenes;
use camsim_render::{render, Bands, RenderOutput, RenderSettings};
use glam::{Mat4, Vec2};

fn load(b: &GltfBuilder, name: &str) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(format!("{name}.gltf"));
    b.write(&p).unwrap();
    let s = load_gltf(&p).unwrap_or_else(|e| panic!("{e}"));
    (dir, s)
}

fn pinhole(scene: &Scene, w: u32, h: u32) -> (Pinhole, Mat4) {
    let c = &scene.cameras[0];
    (
        Pinhole {
            perspective: c.perspective(w, h),
        },
        c.to_world,
    )
}

fn settings(spp: u32, bands: &str) -> RenderSettings {
    RenderSettings {
        spp,
        seed: 1,
        bands: Bands::parse(bands).unwrap(),
        variance: true,
        depth_spp: 0,
        ..Default::default()
    }
}

/// z-score of the mean over `pixels` of band `b` against `expected`, using the per-pixel
/// variance estimates (pixels are independent).
fn z_of(
    out: &RenderOutput,
    b: usize,
    pixels: &[usize],
    expected: impl Fn(usize) -> f64,
) -> (f64, f64) {
    let var = out.variance_planes.as_ref().unwrap();
    let n = pixels.len() as f64;
    let (mut d, mut v) = (0.0, 0.0);
    for &i in pixels {
        d += out.band_planes[b][i] as f64 - expected(i);
        v += var[b][i] as f64;
    }
    let z = (d / n) / (v.sqrt() / n);
    (z, d / n)
}

fn all_pixels(out: &RenderOutput) -> Vec<usize> {
    (0..out.width * out.height).collect()
}

/// Furnace: a closed sphere of albedo ρ emitting Le has L = Le/(1 − ρ) everywhere; with a
/// path-length limit N (Mitsuba's max_depth), L = Le(1 − ρᴺ)/(1 − ρ).
#[test]
fn furnace_radiance_is_le_over_one_minus_rho() {
    let (_d, scene) = load(&test_scenes::furnace(0.5, 1.0), "furnace");
    let (cam, m) = pinhole(&scene, 24, 24);
    let s = settings(64, "380:780:40");
    let out = render(&scene, &cam, m, &s, None);
    let px = all_pixels(&out);
    let mut zs = Vec::new();
    for b in 0..out.bands.count {
        let (z, bias) = z_of(&out, b, &px, |_| 2.0);
        zs.push(z);
        assert!(z.abs() < 4.0, "band {b}: z = {z:.2} (bias {bias:.4})");
    }
    // the whole image over all bands
    let zall: f64 = zs.iter().sum::<f64>() / (zs.len() as f64).sqrt();
    assert!(zall.abs() < 4.0, "overall z {zall}");
    // a path-length limit: N = 3 → 1 + ρ + ρ² = 1.75; N = 1 → Le
    for (n, expect) in [(3, 1.75), (1, 1.0)] {
        let s = RenderSettings {
            max_depth: n,
            ..settings(16, "380:780:100")
        };
        let out = render(&scene, &cam, m, &s, None);
        for b in 0..out.bands.count {
            let (z, bias) = z_of(&out, b, &px, |_| expect);
            let var_zero = out.variance_planes.as_ref().unwrap()[b]
                .iter()
                .all(|v| *v == 0.0);
            if var_zero {
                // max_depth 1: emission only, no noise at all
                assert!(bias.abs() < 1e-5, "max_depth {n}: bias {bias}");
            } else {
                assert!(
                    z.abs() < 4.0,
                    "max_depth {n} band {b}: z = {z:.2} (bias {bias:.4})"
                );
            }
        }
    }
}

/// Lambertian plane under a uniform non-reflecting emitter sphere: E = π Le, L = ρ Le.
#[test]
fn lambertian_plane_under_uniform_emitter() {
    let (_d, scene) = load(&test_scenes::uniform_emitter(0.6, 1.0), "uniform");
    let (cam, m) = pinhole(&scene, 24, 24);
    let out = render(&scene, &cam, m, &settings(32, "380:780:50"), None);
    let px = all_pixels(&out);
    for b in 0..out.bands.count {
        let (z, bias) = z_of(&out, b, &px, |_| 0.6);
        assert!(z.abs() < 4.0, "band {b}: z = {z:.2} (bias {bias:.4})");
        assert!(bias.abs() < 0.02, "band {b}: bias {bias}");
    }
    // the plane fills the view: planar depth is exactly the camera height (1 m)
    for (i, z) in out.depth_z_m.iter().enumerate() {
        assert!((z - 1.0).abs() < 1e-5, "pixel {i}: Z = {z}");
    }
}

/// Point light over a Lambertian plane: L(r) = ρ I h / (π (h² + r²)^{3/2}); single scattering
/// only (the plane cannot see itself), so the image is noise-free apart from the pixel jitter.
#[test]
fn point_source_inverse_square_and_cosine() {
    let (rho, i0, h) = (0.8, 10.0, 1.0);
    let (_d, scene) = load(&test_scenes::point_source(rho, i0, h), "point");
    let (w, hh) = (33u32, 33u32);
    let (cam, m) = pinhole(&scene, w, hh);
    let out = render(&scene, &cam, m, &settings(64, "400:700:50"), None);
    // expected per pixel: average of the closed form over the pixel footprint on the plane;
    // z-test per band over 4 rings of pixels (the spectral estimator is noisy per pixel)
    let persp = cam.perspective;
    let cam_h = 2.0 * h as f32;
    let n = (w * hh) as usize;
    let mut expect = vec![0f64; n];
    let mut ring = vec![0usize; n];
    for y in 0..hh as usize {
        for x in 0..w as usize {
            let mut e = 0.0f64;
            let k = 8;
            for a in 0..k {
                for b in 0..k {
                    let f = Vec2::new(
                        x as f32 + (a as f32 + 0.5) / k as f32,
                        y as f32 + (b as f32 + 0.5) / k as f32,
                    );
                    let d = persp.film_to_plane(f) * cam_h; // camera space, z = −2h
                    let r2 = (d.x * d.x + d.y * d.y) as f64;
                    e += rho * i0 * h / (std::f64::consts::PI * (h * h + r2).powf(1.5));
                }
            }
            expect[y * w as usize + x] = e / (k * k) as f64;
            let r = ((x as f64 + 0.5 - 16.5).powi(2) + (y as f64 + 0.5 - 16.5).powi(2)).sqrt();
            ring[y * w as usize + x] = ((r / 6.0) as usize).min(3);
        }
    }
    for g in 0..4 {
        let px: Vec<usize> = (0..n).filter(|&i| ring[i] == g).collect();
        for b in 0..out.bands.count {
            let (z, bias) = z_of(&out, b, &px, |i| expect[i]);
            assert!(
                z.abs() < 4.0,
                "ring {g} band {b}: z = {z:.2} (bias {bias:.4})"
            );
        }
    }
}

/// Macbeth chart under a D65-shaped uniform emitter: each patch's band value is the band
/// average of ρ(λ)·Le(λ) (exact integral of the piecewise-linear product).
#[test]
fn color_chart_patches_are_reflectance_times_illuminant() {
    let (_d, scene) = load(&test_scenes::color_chart(), "chart");
    let (w, h) = (96u32, 96u32);
    let (cam, m) = pinhole(&scene, w, h);
    let bands = "400:700:50";
    let out = render(&scene, &cam, m, &settings(16, bands), None);
    let d65 = test_scenes::d65_unit_at_560();
    let d65s = camsim_core::Spectrum::sampled(
        (0..=94).map(|i| 360.0 + 5.0 * i as f64).collect(),
        (0..=94).map(|i| d65.eval(360.0 + 5.0 * i as f64)).collect(),
    )
    .unwrap();
    let refl = camsim_core::data::macbeth_reflectances_row_major().unwrap();
    let refl5: Vec<camsim_core::Spectrum> = refl
        .iter()
        .map(|s| {
            camsim_core::Spectrum::sampled(
                (0..=94).map(|i| 360.0 + 5.0 * i as f64).collect(),
                (0..=94).map(|i| s.eval(360.0 + 5.0 * i as f64)).collect(),
            )
            .unwrap()
        })
        .collect();
    let persp = cam.perspective;
    let mut worst_z = 0.0f64;
    for (i, s) in refl5.iter().enumerate() {
        let ([x, z], side) = test_scenes::chart_patch(i);
        // pixels whose whole footprint lies inside the patch (camera 2 m above; image up = −z)
        let px: Vec<usize> = (0..(w * h) as usize)
            .filter(|&k| {
                let (cx, cy) = ((k % w as usize) as f32, (k / w as usize) as f32);
                [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
                    .iter()
                    .all(|(dx, dy)| {
                        let p = persp.film_to_plane(Vec2::new(cx + dx, cy + dy)) * 1.999;
                        let (wx, wz) = (p.x, -p.y);
                        (wx - x).abs() < side / 2.0 - 0.005 && (wz - z).abs() < side / 2.0 - 0.005
                    })
            })
            .collect();
        assert!(px.len() >= 20, "patch {i}: only {} pixels", px.len());
        for b in 0..out.bands.count {
            let (lo, hi) = out.bands.edges(b);
            let boxf = camsim_core::Spectrum::sampled(vec![lo, hi], vec![1.0, 1.0]).unwrap();
            let prod = camsim_core::Spectrum::multiply(s, &d65s);
            let expect =
                camsim_core::Spectrum::integrate_product(&prod, &boxf).unwrap() / (hi - lo);
            let (zv, bias) = z_of(&out, b, &px, |_| expect);
            worst_z = worst_z.max(zv.abs());
            assert!(
                zv.abs() < 4.5,
                "patch {i} band {b}: z = {zv:.2}, bias {bias:.4} of {expect:.4}"
            );
        }
    }
    eprintln!("worst |z| over 24 patches × 6 bands: {worst_z:.2}");
}

/// A thin lens with a vanishing aperture renders the pinhole image (same seed, same paths).
#[test]
fn thin_lens_tends_to_pinhole() {
    let scene = camsim_render::gltf_load::load_gltf(std::path::Path::new(&format!(
        "{}/../scenes/showcase.gltf",
        env!("CARGO_MANIFEST_DIR")
    )))
    .unwrap();
    let c = &scene.cameras[0];
    let p = Pinhole {
        perspective: c.perspective(32, 32),
    };
    let t = ThinLens {
        perspective: c.perspective(32, 32),
        aperture_radius_m: 1e-7,
        focus_distance_m: 3.7,
    };
    let s = settings(8, "380:780:100");
    let a = render(&scene, &p, c.to_world, &s, None);
    let b = render(&scene, &t, c.to_world, &s, None);
    let (mut sa, mut sb, mut diff) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..a.bands.count {
        for i in 0..a.band_planes[k].len() {
            sa += a.band_planes[k][i] as f64;
            sb += b.band_planes[k][i] as f64;
            diff += (a.band_planes[k][i] - b.band_planes[k][i]).abs() as f64;
        }
    }
    assert!((sa - sb).abs() / sa < 1e-3, "{sa} vs {sb}");
    assert!(diff / sa < 0.02, "mean absolute difference {}", diff / sa);
    assert_eq!(a.depth_z_m, b.depth_z_m);
}

/// Thin-lens defocus: a small emitter off the focal plane images as a disc of radius
/// a·|F − z|/z on the focal plane (Mitsuba's thin-lens model), here checked through the
/// second moment of the blur (a uniform disc of radius R has ⟨x²⟩ = R²/4).
#[test]
fn thin_lens_blur_matches_the_circle_of_confusion() {
    use camsim_render::gltf_write::{quad, sphere};
    use serde_json::json;
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "em", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "extras": {"spectral_reflectance": camsim_render::gltf_write::flat_spectrum(0.0), "spectral_emission": camsim_render::gltf_write::flat_spectrum(1.0)}}));
    let z_obj = 1.0f32;
    let r = 0.02f32;
    let mesh = b.mesh("dot", &sphere([0.0, 0.0, -z_obj], r, 8, 16, false), m);
    b.node(json!({"name": "dot", "mesh": mesh}), true);
    let _ = quad; // (kept for symmetry with other scenes)
    let c = b.camera("cam", 20f64.to_radians(), Some(1.0), 0.001);
    b.node(json!({"name": "cam", "camera": c}), true);
    let (_d, scene) = load(&b, "dot");
    let (a, f) = (0.05f32, 4.0f32);
    let n = 64u32;
    let sc = &scene.cameras[0];
    let cam = ThinLens {
        perspective: sc.perspective(n, n),
        aperture_radius_m: a,
        focus_distance_m: f,
    };
    let out = render(
        &scene,
        &cam,
        sc.to_world,
        &settings(256, "500:600:100"),
        None,
    );
    let img = &out.band_planes[0];
    let (mut s0, mut sx2) = (0.0f64, 0.0f64);
    let c0 = n as f64 / 2.0;
    for y in 0..n as usize {
        for x in 0..n as usize {
            let v = img[y * n as usize + x] as f64;
            s0 += v;
            sx2 += v * ((x as f64 + 0.5 - c0).powi(2) + (y as f64 + 0.5 - c0).powi(2)) / 2.0;
        }
    }
    let var_px = sx2 / s0;
    // blur radius on the focal plane, in pixels: R = a|F − z|/z / (F tan(fov/2)) · N/2
    let r_focal = a as f64 * (f - z_obj).abs() as f64 / z_obj as f64;
    let px_per_m = n as f64 / 2.0 / (f as f64 * (10f64.to_radians()).tan());
    let r_px = r_focal * px_per_m;
    // the dot itself (radius r at z) adds its own image (r F/z on the focal plane) and the
    // pixel box adds 1/12
    let dot_px = r as f64 * f as f64 / z_obj as f64 * px_per_m;
    let expect = r_px * r_px / 4.0 + dot_px * dot_px / 4.0 + 1.0 / 12.0;
    assert!(
        (var_px - expect).abs() / expect < 0.08,
        "⟨x²⟩ = {var_px:.3} px², expected {expect:.3} (R = {r_px:.2} px)"
    );
    // total flux does not depend on the aperture: compare with the pinhole render
    let p = Pinhole {
        perspective: sc.perspective(n, n),
    };
    let outp = render(&scene, &p, sc.to_world, &settings(256, "500:600:100"), None);
    let sp: f64 = outp.band_planes[0].iter().map(|v| *v as f64).sum();
    assert!((s0 - sp).abs() / sp < 0.05, "flux {s0} vs pinhole {sp}");
}

/// Depth: Z is the planar depth of the central ray, exact for a tilted plane.
#[test]
fn planar_depth_is_exact_for_a_plane() {
    use camsim_render::gltf_write::{flat_spectrum, quad};
    use serde_json::json;
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "w", "pbrMetallicRoughness": {"metallicFactor": 0.0}, "extras": {"spectral_reflectance": flat_spectrum(0.5)}}));
    // plane z = −3 − 0.5 x (tilted), large
    let q = quad([
        [-10.0, -10.0, 2.0],
        [10.0, -10.0, -8.0],
        [10.0, 10.0, -8.0],
        [-10.0, 10.0, 2.0],
    ]);
    let mesh = b.mesh("plane", &q, m);
    b.node(json!({"name": "plane", "mesh": mesh}), true);
    let c = b.camera("cam", 50f64.to_radians(), Some(1.5), 0.01);
    b.node(json!({"name": "cam", "camera": c}), true);
    let (_d, scene) = load(&b, "plane");
    let sc = &scene.cameras[0];
    let cam = Pinhole {
        perspective: sc.perspective(48, 32),
    };
    let out = render(
        &scene,
        &cam,
        sc.to_world,
        &RenderSettings {
            depth_spp: 4,
            ..settings(1, "500:600:100")
        },
        None,
    );
    for y in 0..32 {
        for x in 0..48 {
            let d = cam
                .perspective
                .film_to_plane(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            // along the ray p = t·d (d.z = −1): z = −Z, plane z = −3 − 0.5x → Z = 3/(1 − 0.5 d.x)
            let z_expect = 3.0 / (1.0 - 0.5 * d.x as f64);
            let got = out.depth_z_m[y * 48 + x] as f64;
            assert!(
                (got - z_expect).abs() < 1e-4 * z_expect,
                "({x},{y}): Z {got} vs {z_expect}"
            );
            let t_expect = z_expect * (d.length() as f64);
            let tc = out.depth_center_m[y * 48 + x] as f64;
            assert!((tc - t_expect).abs() < 1e-4 * t_expect);
        }
    }
}

/// The image does not depend on the number of threads (per-pixel random streams).
#[test]
fn output_is_identical_at_one_and_two_threads() {
    let scene = camsim_render::gltf_load::load_gltf(std::path::Path::new(&format!(
        "{}/../scenes/showcase.gltf",
        env!("CARGO_MANIFEST_DIR")
    )))
    .unwrap();
    let c = &scene.cameras[0];
    let cam = ThinLens {
        perspective: c.perspective(24, 24),
        aperture_radius_m: 0.03,
        focus_distance_m: 3.7,
    };
    let s = RenderSettings {
        depth_spp: 2,
        ..settings(4, "380:780:20")
    };
    let run = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| render(&scene, &cam as &dyn Camera, c.to_world, &s, None))
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.band_planes, b.band_planes);
    assert_eq!(a.variance_planes, b.variance_planes);
    assert_eq!(a.depth_mean_m, b.depth_mean_m);
    // and a different seed gives a different image
    let s2 = RenderSettings {
        seed: 2,
        ..s.clone()
    };
    let c2 = render(&scene, &cam, c.to_world, &s2, None);
    assert_ne!(a.band_planes, c2.band_planes);
}

/// A glass sphere in a uniform radiance field (closed, non-reflecting emitter sphere): a
/// non-absorbing smooth dielectric leaves the field unchanged (radiance / n² is conserved), so
/// every pixel sees Le; a rough one may only lose the single-scattering microfacet deficit.
#[test]
fn glass_in_a_uniform_field_is_invisible() {
    use camsim_render::gltf_write::{flat_spectrum, sphere};
    use serde_json::json;
    // rough: the single-scattering GGX model may only lose energy, by less than 6 % here
    for (rough, max_loss) in [(0.0, 0.0), (0.3, 0.06)] {
        let mut b = GltfBuilder::new();
        let em = b.material(json!({"name": "sky", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
            "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(1.0)}}));
        let sky = b.mesh("sky", &sphere([0.0; 3], 10.0, 16, 32, true), em);
        b.node(json!({"name": "sky", "mesh": sky}), true);
        let g = b.material(json!({"name": "glass", "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": rough},
            "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.5}}}));
        let gs = b.mesh("glass", &sphere([0.0, 0.0, -3.0], 1.0, 48, 96, false), g);
        b.node(json!({"name": "glass", "mesh": gs}), true);
        let c = b.camera("cam", 40f64.to_radians(), Some(1.0), 0.01);
        b.node(json!({"name": "cam", "camera": c}), true);
        let (_d, scene) = load(&b, "glass");
        let (cam, m) = pinhole(&scene, 24, 24);
        let out = render(&scene, &cam, m, &settings(32, "400:700:100"), None);
        let px = all_pixels(&out);
        for band in 0..out.bands.count {
            let (z, bias) = z_of(&out, band, &px, |_| 1.0);
            if max_loss == 0.0 {
                assert!(
                    z.abs() < 4.0,
                    "smooth glass band {band}: z = {z:.2} (bias {bias:.4})"
                );
            } else {
                assert!(
                    bias < 4.0 * (bias / z).abs() && bias > -max_loss,
                    "rough glass band {band}: bias {bias:.4} (z {z:.2})"
                );
            }
        }
    }
}

/// Asking for the variance does not change the image: the same seed gives the same band means
/// (to f64 summation order) with and without variance planes.
#[test]
fn variance_option_leaves_the_means_unchanged() {
    let scene = camsim_render::gltf_load::load_gltf(std::path::Path::new(&format!(
        "{}/../scenes/showcase.gltf",
        env!("CARGO_MANIFEST_DIR")
    )))
    .unwrap();
    let c = &scene.cameras[0];
    let cam = Pinhole {
        perspective: c.perspective(16, 16),
    };
    let with = settings(8, "380:780:20");
    let without = RenderSettings {
        variance: false,
        ..with.clone()
    };
    let a = render(&scene, &cam, c.to_world, &with, None);
    let b = render(&scene, &cam, c.to_world, &without, None);
    assert!(a.variance_planes.is_some() && b.variance_planes.is_none());
    let mut nonzero = 0;
    for (pa, pb) in a.band_planes.iter().zip(&b.band_planes) {
        for (x, y) in pa.iter().zip(pb) {
            assert!((x - y).abs() <= 1e-6 * x.abs().max(1e-30), "{x} vs {y}");
            nonzero += (*x > 0.0) as usize;
        }
    }
    assert!(
        nonzero > 1000,
        "only {nonzero} non-zero values: the test is not testing"
    );
}
