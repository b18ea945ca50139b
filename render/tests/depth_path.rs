//! The depth path (pinhole radiance + depth → layered defocus) against the thin-lens camera:
//! the circle-of-confusion formula against traced thin-lens rays, a fronto-parallel plane
//! (exact case) against a Monte Carlo thin-lens image, and the Mitsuba thin-lens scene
//! (occlusions) against camsim's own thin-lens render, with the error reported.
use camsim_core::rng::stream;
use camsim_render::camera::{Camera, Perspective, Pinhole, ThinLens};
use camsim_render::depth_path::{convolve, defocus_layered, Kernel, ThinLensDefocus};
use camsim_render::gltf_load::{load_gltf, pick_camera};
use camsim_render::{render, Bands, RenderSettings};
use glam::Vec2;
use rand::RngExt;
use rayon::prelude::*;
use std::path::Path;

fn persp(w: u32, h: u32) -> Perspective {
    Perspective {
        width_px: w,
        height_px: h,
        yfov_rad: 40f32.to_radians(),
        znear_m: 0.01,
        zfar_m: f32::INFINITY,
    }
}

/// c(z) = R |1/z − 1/D| H / (2 tan(θ/2)) equals the film distance between the pinhole
/// projection of the point a film position focuses on at depth z and the point seen through
/// the aperture edge.
#[test]
fn circle_of_confusion_matches_traced_thin_lens_rays() {
    let (w, h) = (96, 64);
    let cam = ThinLens {
        perspective: persp(w, h),
        aperture_radius_m: 0.02,
        focus_distance_m: 2.0,
    };
    let d = ThinLensDefocus {
        aperture_radius_m: 0.02,
        focus_distance_m: 2.0,
        yfov_rad: 40f64.to_radians(),
        height_px: h as usize,
    };
    for z in [0.7f32, 1.3, 2.0, 3.5, 9.0] {
        for f in [Vec2::new(48.0, 32.0), Vec2::new(10.5, 55.25)] {
            // the lens sample (1, 0.5) maps to the aperture edge (concentric map)
            let r = cam
                .generate_ray(f, Vec2::new(1.0, 0.5), &[550.0; 4])
                .unwrap();
            let t = (-z - r.origin_m.z) / r.direction.z;
            let p = r.origin_m + r.direction * t;
            let px = cam.perspective.project(p).unwrap();
            let got = (px - f).length() as f64;
            let expect = d.coc_radius_px(z as f64);
            assert!(
                (got - expect).abs() < 1e-3 * (1.0 + expect),
                "z {z}: traced {got:.5} px vs c(z) {expect:.5} px"
            );
        }
    }
    // the pillbox is normalised and has the disc's area
    let k = Kernel::pillbox(3.3);
    assert!((k.values.iter().sum::<f32>() - 1.0).abs() < 1e-6);
    let nonzero_area: f64 = k
        .values
        .iter()
        .map(|v| (*v as f64 > 0.0) as u8 as f64)
        .sum();
    assert!(nonzero_area > std::f64::consts::PI * 3.3 * 3.3);
}

/// A fronto-parallel plane with a sinusoidal texture (10 px period): the thin lens blurs it by
/// the disc MTF 2J₁(2πfc)/(2πfc) (c = CoC radius, f = 0.1 cycle/px); the depth path (one
/// layer) reproduces that modulation and the thin-lens image pixel by pixel.
#[test]
fn depth_path_matches_thin_lens_on_a_plane() {
    let (w, h) = (64usize, 64usize);
    let cam = ThinLens {
        perspective: persp(w as u32, h as u32),
        aperture_radius_m: 0.06,
        focus_distance_m: 2.5,
    };
    let pin = Pinhole {
        perspective: persp(w as u32, h as u32),
    };
    let z = 1.2f64;
    let px_per_m = h as f64 / (2.0 * (20f64.to_radians()).tan()) / z; // film px per metre at z
    let period_px = 10.0;
    let tex =
        |x: f64, _y: f64| 0.5 + 0.3 * (2.0 * std::f64::consts::PI * x * px_per_m / period_px).cos();
    let image = |c: &dyn Camera, spp: usize, seed: u64| -> Vec<f32> {
        (0..h)
            .into_par_iter()
            .flat_map_iter(|j| {
                let mut rng = stream(seed, &[j as u64]);
                (0..w)
                    .map(|i| {
                        let mut s = 0.0;
                        for _ in 0..spp {
                            let f = Vec2::new(
                                i as f32 + rng.random::<f32>(),
                                j as f32 + rng.random::<f32>(),
                            );
                            let r = c
                                .generate_ray(f, Vec2::new(rng.random(), rng.random()), &[550.0; 4])
                                .unwrap();
                            let (o, d) = (r.origin_m.as_dvec3(), r.direction.as_dvec3());
                            let t = (-z - o.z) / d.z;
                            s += tex(o.x + t * d.x, o.y + t * d.y);
                        }
                        (s / spp as f64) as f32
                    })
                    .collect::<Vec<f32>>()
            })
            .collect()
    };
    let thin = image(&cam, 256, 1);
    let pinhole = image(&pin, 64, 2);
    let d = ThinLensDefocus {
        aperture_radius_m: 0.06,
        focus_distance_m: 2.5,
        yfov_rad: 40f64.to_radians(),
        height_px: h,
    };
    let c = d.coc_radius_px(z);
    let depth = vec![z as f32; w * h];
    let out = &defocus_layered(&[pinhole.clone()], &depth, w, h, 8, |iz| d.kernel(iz))[0];
    // modulation at 0.1 cycle/px along x (least squares on cos, sin; 4-px border skipped)
    let amp = |img: &[f32]| {
        let (mut sc, mut ss, mut n) = (0.0, 0.0, 0.0);
        let (mut cc, mut s2) = (0.0, 0.0);
        for j in 4..h - 4 {
            for i in 4..w - 4 {
                // film x of the pixel centre relative to the image centre, in px
                let ph = 2.0 * std::f64::consts::PI * (i as f64 + 0.5 - w as f64 / 2.0) / period_px;
                let v = img[j * w + i] as f64 - 0.5;
                sc += v * ph.cos();
                ss += v * ph.sin();
                cc += ph.cos() * ph.cos();
                s2 += ph.sin() * ph.sin();
                n += 1.0;
            }
        }
        let _ = n;
        (sc / cc).hypot(ss / s2)
    };
    let (a_thin, a_dp, a_pin) = (amp(&thin), amp(out), amp(&pinhole));
    let x = 2.0 * std::f64::consts::PI * c / period_px;
    let mtf = 2.0 * j1(x) / x;
    eprintln!("plane: c = {c:.3} px, MTF(0.1 cy/px) closed form {mtf:.4}, thin lens {:.4}, depth path {:.4}", a_thin / a_pin, a_dp / a_pin);
    assert!(
        (a_thin / a_pin - mtf).abs() < 0.03,
        "thin lens modulation {:.4} vs disc MTF {mtf:.4}",
        a_thin / a_pin
    );
    assert!(
        (a_dp / a_pin - mtf).abs() < 0.03,
        "depth path modulation {:.4} vs disc MTF {mtf:.4}",
        a_dp / a_pin
    );
    let r = c.ceil() as usize + 1;
    let (mut e_dp, mut e_pin, mut n) = (0.0, 0.0, 0.0);
    for j in r..h - r {
        for i in r..w - r {
            let k = j * w + i;
            e_dp += ((out[k] - thin[k]) as f64).powi(2);
            e_pin += ((pinhole[k] - thin[k]) as f64).powi(2);
            n += 1.0;
        }
    }
    assert!(
        e_dp < 0.1 * e_pin,
        "depth path RMS {:.4} vs pinhole RMS {:.4}",
        (e_dp / n).sqrt(),
        (e_pin / n).sqrt()
    );
}

/// Bessel J₁ (series; |x| < 8 here).
fn j1(x: f64) -> f64 {
    let mut term = x / 2.0;
    let mut s = term;
    for k in 1..40 {
        term *= -(x * x / 4.0) / (k as f64 * (k + 1) as f64);
        s += term;
    }
    s
}

/// The Mitsuba thin-lens scene (boxes at 1.2, 2.5 and 5 m; focus 2.5 m) with a 6 cm
/// aperture radius (CoC up to 3.4 px at 96 px): the depth path from camsim's pinhole render against
/// camsim's thin-lens render. Reported: the RMS error over the mean (Monte Carlo noise
/// removed), everywhere and away from depth edges, and that of the unblurred pinhole image.
#[test]
fn depth_path_on_the_thin_lens_scene() {
    let gltf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/mitsuba/thinlens.gltf");
    let scene = load_gltf(&gltf).unwrap();
    let sc = pick_camera(&scene, None).unwrap();
    let (w, h) = (96u32, 96u32);
    let (_, fd) = sc.thinlens.unwrap();
    let ar = 0.06f32;
    let settings = RenderSettings {
        spp: 256,
        seed: 3,
        bands: Bands::new(450.0, 650.0, 200.0).unwrap(),
        variance: true,
        depth_spp: 0,
        ..Default::default()
    };
    let pin = render(
        &scene,
        &Pinhole {
            perspective: sc.perspective(w, h),
        },
        sc.to_world,
        &settings,
        None,
    );
    let thin_cam = ThinLens {
        perspective: sc.perspective(w, h),
        aperture_radius_m: ar,
        focus_distance_m: fd,
    };
    let thin = render(&scene, &thin_cam, sc.to_world, &settings, None);
    let d = ThinLensDefocus {
        aperture_radius_m: ar as f64,
        focus_distance_m: fd as f64,
        yfov_rad: sc.yfov_rad as f64,
        height_px: h as usize,
    };
    let (w, h) = (w as usize, h as usize);
    let out = defocus_layered(&pin.band_planes, &pin.depth_z_m, w, h, 32, |iz| {
        d.kernel(iz)
    });
    // depth edges: pixels within the largest CoC (+1) of a 10 % jump in 1/z
    let inv: Vec<f64> = pin
        .depth_z_m
        .iter()
        .map(|z| if z.is_finite() { 1.0 / *z as f64 } else { 0.0 })
        .collect();
    let edge: Vec<bool> = {
        let mut jump = vec![0f32; w * h];
        for j in 0..h {
            for i in 0..w {
                let a = inv[j * w + i];
                for (di, dj) in [(1, 0), (0, 1)] {
                    if i + di < w
                        && j + dj < h
                        && (inv[(j + dj) * w + i + di] - a).abs()
                            > 0.1 * a.max(inv[(j + dj) * w + i + di])
                    {
                        jump[j * w + i] = 1.0;
                    }
                }
            }
        }
        let rmax = (0..=10)
            .map(|k| d.coc_radius_px(0.5 + k as f64))
            .fold(0.0, f64::max)
            .min(8.0);
        let near_jump = convolve(&jump, w, h, &Kernel::pillbox(rmax + 1.5));
        // the frame border too: the lens sees past it, the pinhole image does not
        let b = rmax.ceil() as usize + 2;
        (0..w * h)
            .map(|k| {
                near_jump[k] > 0.0 || k % w < b || k % w >= w - b || k / w < b || k / w >= h - b
            })
            .collect()
    };
    let tvar = thin.variance_planes.as_ref().unwrap();
    let pvar = pin.variance_planes.as_ref().unwrap();
    let mut rep = Vec::new();
    for b in 0..out.len() {
        let mean: f64 = thin.band_planes[b].iter().map(|v| *v as f64).sum::<f64>() / (w * h) as f64;
        let (mut e_all, mut e_in, mut n_in, mut e_pin) = (0.0, 0.0, 0.0, 0.0);
        let (mut nt, mut nt_in, mut np) = (0.0, 0.0, 0.0);
        for k in 0..w * h {
            let diff = (out[b][k] - thin.band_planes[b][k]) as f64;
            e_all += diff * diff;
            e_pin += ((pin.band_planes[b][k] - thin.band_planes[b][k]) as f64).powi(2);
            nt += tvar[b][k] as f64;
            np += pvar[b][k] as f64;
            if !edge[k] {
                e_in += diff * diff;
                nt_in += tvar[b][k] as f64;
                n_in += 1.0;
            }
        }
        let n = (w * h) as f64;
        // RMS over the mean with the expected Monte Carlo part removed (the depth path's own
        // noise is the pinhole noise averaged by the blur: neglected, which errs on the high
        // side)
        let ex = |e: f64, noise: f64, nn: f64| ((e - noise) / nn).max(0.0).sqrt() / mean;
        rep.push((
            ex(e_all, nt, n),
            ex(e_in, nt_in, n_in),
            ex(e_pin, nt + np, n),
            n_in / n,
        ));
    }
    if let Ok(dir) = std::env::var("CAMSIM_DEPTH_PATH_DUMP") {
        let dump = |name: &str, v: &[f32]| {
            let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            std::fs::write(Path::new(&dir).join(name), bytes).unwrap();
        };
        dump("thin.f32", &thin.band_planes[0]);
        dump("pin.f32", &pin.band_planes[0]);
        dump("dp.f32", &out[0]);
        dump("depth.f32", &pin.depth_z_m);
    }
    for (b, r) in rep.iter().enumerate() {
        eprintln!(
            "band {b}: depth path RMS error {:.4} of the mean (away from depth edges and the frame border {:.4}, {:.0} % of pixels); pinhole {:.4}",
            r.0, r.1, 100.0 * r.3, r.2
        );
        // near depth edges the lens sees what the pinhole image hides (partial occlusion):
        // the depth path removes most but not all of the pinhole image's error there
        assert!(
            r.0 < 0.75 * r.2,
            "band {b}: depth path {:.4} vs pinhole {:.4}",
            r.0,
            r.2
        );
        assert!(
            r.1 < 0.02,
            "band {b}: depth path error away from depth edges {:.4}",
            r.1
        );
    }
}
