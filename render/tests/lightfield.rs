//! The light-field camera against closed forms: flux through a microlens, sub-aperture
//! disparity versus depth, and shift-and-add refocusing. The scene is a textured plane at a
//! chosen depth, intersected analytically (camera-only tests, no BVH), radiance = texture.
use camsim_core::rng::stream;
use camsim_render::camera::lightfield::{refocus, LightFieldCamera, MainLens};
use camsim_render::camera::real_lens::{FilmSize, RealLensCamera, RealLensOptions};
use camsim_render::camera::{Camera, OutputQuantity};
use glam::Vec2;
use rand::RngExt;
use rayon::prelude::*;
use std::f64::consts::PI;

const N: u32 = 9; // pixels per microlens
const M: u32 = 33; // microlenses per side (odd: one sits on the axis)

/// Thin 50 mm f/4 main lens focused at 2 m; 100 µm microlenses of f/4.1 (f_μ = 410 µm, the
/// image-side F-number b/2A ≈ 4.1), sensor at f_μ.
fn thin_camera() -> LightFieldCamera {
    LightFieldCamera::new(
        MainLens::Thin {
            focal_length_mm: 50.0,
            f_number: 4.0,
        },
        2.0,
        100.0,
        410.0,
        None,
        N,
        N * M,
        N * M,
    )
    .unwrap()
}

/// Raw irradiance image of the plane z = −z_m with radiance `tex(X, Y)` (m): per pixel the
/// mean of `spp` samples (jittered film position, random microlens point).
fn render_plane(
    cam: &LightFieldCamera,
    z_m: f64,
    tex: impl Fn(f64, f64) -> f64 + Sync,
    spp: usize,
    seed: u64,
) -> Vec<f32> {
    let (w, h) = cam.film_size_px();
    (0..h as usize)
        .into_par_iter()
        .flat_map_iter(|j| {
            let mut rng = stream(seed, &[j as u64]);
            let tex = &tex;
            (0..w as usize)
                .map(|i| {
                    let mut s = 0.0;
                    for _ in 0..spp {
                        let f = Vec2::new(
                            i as f32 + rng.random::<f32>(),
                            j as f32 + rng.random::<f32>(),
                        );
                        let u = Vec2::new(rng.random::<f32>(), rng.random::<f32>());
                        if let Some(r) = cam.generate_ray(f, u, &[550.0; 4]) {
                            let (o, d) = (r.origin_m.as_dvec3(), r.direction.as_dvec3());
                            let t = (-z_m - o.z) / d.z;
                            s += r.weight[0] as f64 * tex(o.x + t * d.x, o.y + t * d.y);
                        }
                    }
                    (s / spp as f64) as f32
                })
                .collect::<Vec<f32>>()
        })
        .collect()
}

/// Least-squares fit of a + Σ (b sin ωx + c cos ωx) over an image (border of 2 px skipped):
/// returns the (phase, amplitude) of each frequency (radians per pixel along x or y).
fn fit_sinusoids(img: &[f32], vw: usize, vh: usize, wx: f64, wy: f64) -> [(f64, f64); 2] {
    // normal equations of the 5 basis functions
    let mut ata = [[0.0f64; 5]; 5];
    let mut atb = [0.0f64; 5];
    for j in 2..vh - 2 {
        for i in 2..vw - 2 {
            let (x, y) = (i as f64, j as f64);
            let b = [
                1.0,
                (wx * x).sin(),
                (wx * x).cos(),
                (wy * y).sin(),
                (wy * y).cos(),
            ];
            for r in 0..5 {
                for c in 0..5 {
                    ata[r][c] += b[r] * b[c];
                }
                atb[r] += b[r] * img[j * vw + i] as f64;
            }
        }
    }
    // Gaussian elimination
    let mut a = ata;
    let mut y = atb;
    for k in 0..5 {
        let p = a[k][k];
        for r in k + 1..5 {
            let f = a[r][k] / p;
            for c in k..5 {
                a[r][c] -= f * a[k][c];
            }
            y[r] -= f * y[k];
        }
    }
    let mut x = [0.0; 5];
    for k in (0..5).rev() {
        let s: f64 = (k + 1..5).map(|c| a[k][c] * x[c]).sum();
        x[k] = (y[k] - s) / a[k][k];
    }
    [
        (x[2].atan2(x[1]), x[1].hypot(x[2])),
        (x[4].atan2(x[3]), x[3].hypot(x[4])),
    ]
}

#[test]
fn light_field_camera_basics_and_bad_configs() {
    let cam = thin_camera();
    assert!(matches!(
        cam.output_quantity(),
        OutputQuantity::SensorIrradiance
    ));
    assert_eq!(cam.film_size_px(), (N * M, N * M));
    let i = cam.info();
    // 1/b = 1/F − 1/D and the pixel pitch that centres the cells on the chief rays
    assert!((i.mla_distance_mm - 1.0 / (1.0 / 50.0 - 1.0 / 2000.0)).abs() < 1e-9);
    let p = 0.1 * (i.mla_distance_mm + 0.41) / (9.0 * i.mla_distance_mm);
    assert!((i.pixel_pitch_mm - p).abs() < 1e-12);
    // the centre ray of the central pixel of the central cell is the optical axis
    let c = cam
        .center_ray(Vec2::new((N * M) as f32 / 2.0, (N * M) as f32 / 2.0))
        .unwrap();
    assert!(c.direction.z < -0.999_999);
    // bad configurations → errors, not panics
    let make = |pitch: f64, n: u32, w: u32| {
        LightFieldCamera::new(
            MainLens::Thin {
                focal_length_mm: 50.0,
                f_number: 4.0,
            },
            2.0,
            pitch,
            410.0,
            None,
            n,
            w,
            w,
        )
    };
    assert!(make(-1.0, 9, 297).is_err());
    assert!(make(100.0, 0, 297).is_err());
    assert!(make(100.0, 9, 300).is_err());
    let e = LightFieldCamera::new(
        MainLens::Thin {
            focal_length_mm: 50.0,
            f_number: 4.0,
        },
        0.04,
        100.0,
        410.0,
        None,
        9,
        297,
        297,
    );
    assert!(e.unwrap_err().to_string().contains("focus_distance_m"));
}

/// Flux through the on-axis microlens in a uniform radiance field equals
/// L·p_μ²·π sin²θ with sin θ = A/√(A² + b²) (the projected solid angle of the main-lens
/// aperture seen from the MLA).
#[test]
fn microlens_flux_of_a_uniform_scene_matches_closed_form() {
    let cam = thin_camera();
    let i = cam.info().clone();
    let (k0, spp) = ((M / 2 * N) as usize, 4000usize);
    let per_pixel: Vec<(f64, f64)> = (0..(N * N) as usize)
        .into_par_iter()
        .map(|p| {
            let (px, py) = (k0 + p % N as usize, k0 + p / N as usize);
            let mut rng = stream(5, &[p as u64]);
            let (mut s, mut s2) = (0.0, 0.0);
            for _ in 0..spp {
                let f = Vec2::new(
                    px as f32 + rng.random::<f32>(),
                    py as f32 + rng.random::<f32>(),
                );
                let w = cam
                    .sample(f, [rng.random(), rng.random()], 550.0)
                    .map_or(0.0, |x| x.0);
                s += w;
                s2 += w * w;
            }
            let m = s / spp as f64;
            (m, (s2 / spp as f64 - m * m) / spp as f64)
        })
        .collect();
    let a2 = i.pixel_pitch_mm * i.pixel_pitch_mm;
    let flux: f64 = per_pixel.iter().map(|v| v.0 * a2).sum();
    let sd = per_pixel.iter().map(|v| v.1 * a2 * a2).sum::<f64>().sqrt();
    let aperture = 50.0 / 8.0;
    let b = i.mla_distance_mm;
    let expect =
        i.microlens_pitch_mm.powi(2) * PI * aperture * aperture / (aperture * aperture + b * b);
    assert!(
        (flux - expect).abs() < 4.0 * sd + 2e-3 * expect,
        "flux {flux:.6e} vs {expect:.6e} (sd {sd:.1e})"
    );
}

/// Sub-aperture views of a textured plane shift with depth by the closed form
/// D(z) = −b (1/z − 1/D)(b + s)/(n f_μ) view pixels per view step, along x and y.
#[test]
fn sub_aperture_disparity_matches_closed_form() {
    let cam = thin_camera();
    let i = cam.info().clone();
    let b_m = i.mla_distance_mm * 1e-3;
    let p_mu = i.microlens_pitch_mm * 1e-3;
    let (vw, vh) = (M as usize, M as usize);
    for (k, z) in [1.0, 1.4, 2.0, 3.5, 6.0].into_iter().enumerate() {
        // periods of 11 and 13 view pixels, whatever the depth (scene period P·p_μ·z/b)
        let (px, py) = (11.0, 13.0);
        let tex = |x: f64, y: f64| {
            0.5 + 0.2 * (2.0 * PI * x / (px * p_mu * z / b_m)).sin()
                + 0.2 * (2.0 * PI * y / (py * p_mu * z / b_m)).sin()
        };
        let raw = render_plane(&cam, z, tex, 24, 100 + k as u64);
        let views = cam.sub_aperture_views(&raw);
        let c = (N / 2) as usize;
        let (wx, wy) = (2.0 * PI / px, 2.0 * PI / py);
        // shift δ = −Δφ/ω relative to the central view, regressed on the view offset
        let phase = |u: usize, v: usize| fit_sinusoids(&views[v * N as usize + u], vw, vh, wx, wy);
        let centre = phase(c, c);
        let slope = |pts: &[(f64, f64)]| {
            let n = pts.len() as f64;
            let (mx, my) = (
                pts.iter().map(|p| p.0).sum::<f64>() / n,
                pts.iter().map(|p| p.1).sum::<f64>() / n,
            );
            pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
                / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>()
        };
        let wrap = |a: f64| (a + PI).rem_euclid(2.0 * PI) - PI;
        let dx: Vec<(f64, f64)> = (1..N as usize - 1)
            .map(|u| {
                (
                    u as f64 - c as f64,
                    -wrap(phase(u, c)[0].0 - centre[0].0) / wx,
                )
            })
            .collect();
        let dy: Vec<(f64, f64)> = (1..N as usize - 1)
            .map(|v| {
                (
                    v as f64 - c as f64,
                    -wrap(phase(c, v)[1].0 - centre[1].0) / wy,
                )
            })
            .collect();
        let expect = cam.disparity_per_view(z);
        for (axis, got) in [("x", slope(&dx)), ("y", slope(&dy))] {
            assert!(
                (got - expect).abs() < 0.03 * expect.abs() + 0.004,
                "z = {z} m, {axis}: disparity {got:.4} vs closed form {expect:.4} view px per view"
            );
        }
    }
}

/// Shift-and-add refocusing: a plane off the focus distance is blurred in the plain sum of
/// the views and sharp (as sharp as one view) when refocused at its depth; a plane at the
/// focus distance is sharp with no shift.
#[test]
fn refocusing_brings_a_plane_into_focus() {
    let cam = thin_camera();
    let i = cam.info().clone();
    let b_m = i.mla_distance_mm * 1e-3;
    let p_mu = i.microlens_pitch_mm * 1e-3;
    let (vw, vh) = (M as usize, M as usize);
    let n = N as usize;
    let period = 6.0; // view pixels
    let w = 2.0 * PI / period;
    for (k, z) in [0.8, 2.0].into_iter().enumerate() {
        let tex = |x: f64, _y: f64| 0.5 + 0.4 * (2.0 * PI * x / (period * p_mu * z / b_m)).sin();
        let raw = render_plane(&cam, z, tex, 24, 200 + k as u64);
        let views = cam.sub_aperture_views(&raw);
        let amp = |img: &[f32]| fit_sinusoids(img, vw, vh, w, 2.0 * PI / 7.0)[0].1;
        let central = amp(&views[(n / 2) * n + n / 2]);
        let d = cam.disparity_per_view(z);
        let sharp = amp(&refocus(&views, n, vw, vh, d));
        let plain = amp(&refocus(&views, n, vw, vh, 0.0));
        // the sum over views averages vignetted (darker) corner views: compare with the
        // central view relative to the mean level
        let level = |img: &[f32]| img.iter().map(|v| *v as f64).sum::<f64>() / img.len() as f64;
        let rel = |a: f64, img: &[f32]| a / level(img);
        let central_rel = rel(central, &views[(n / 2) * n + n / 2]);
        let sharp_rel = rel(sharp, &refocus(&views, n, vw, vh, d));
        let plain_rel = rel(plain, &refocus(&views, n, vw, vh, 0.0));
        assert!(
            sharp_rel > 0.85 * central_rel,
            "z = {z}: refocused modulation {sharp_rel:.3} vs one view {central_rel:.3}"
        );
        if z != 2.0 {
            assert!(
                plain_rel < 0.5 * sharp_rel,
                "z = {z}: unshifted {plain_rel:.3} vs refocused {sharp_rel:.3}"
            );
        } else {
            assert!(d.abs() < 1e-12 && (plain_rel - sharp_rel).abs() < 1e-6);
        }
    }
}

/// With a traced prescription as main lens the flux through the on-axis microlens equals
/// the real-lens camera's own on-axis irradiance × microlens area (two independent paths
/// through the same lens: exit-pupil sampling from the sensor vs microlens sampling).
#[test]
fn prescription_main_lens_flux_matches_the_real_lens_camera() {
    let lens = super::test_lenses::double_gauss();
    let main = LightFieldCamera::prescription_main_lens(&lens, 2.0, Some(4.0), 100.0).unwrap();
    let cam = LightFieldCamera::new(
        MainLens::Prescription(Box::new(main)),
        2.0,
        100.0,
        410.0,
        None,
        N,
        N * M,
        N * M,
    )
    .unwrap();
    let rl = RealLensCamera::new(
        &lens,
        64,
        64,
        &RealLensOptions {
            focus_distance_m: Some(2.0),
            f_number: Some(4.0),
            film: FilmSize::PixelPitchUm(10.0),
            ..Default::default()
        },
    )
    .unwrap();
    let i = cam.info().clone();
    let k0 = (M / 2 * N) as usize;
    let mut rng = stream(9, &[]);
    let (mut s, mut s2, n) = (0.0, 0.0, 400_000);
    for _ in 0..n {
        let f = Vec2::new(
            k0 as f32 + rng.random::<f32>() * N as f32,
            k0 as f32 + rng.random::<f32>() * N as f32,
        );
        let w = cam
            .sample(f, [rng.random(), rng.random()], 587.6)
            .map_or(0.0, |x| x.0);
        s += w;
        s2 += w * w;
    }
    let cell_area = (N as f64 * i.pixel_pitch_mm).powi(2);
    let flux = s / n as f64 * cell_area;
    let sd = ((s2 / n as f64 - (s / n as f64).powi(2)) / n as f64).sqrt() * cell_area;
    let (mut e, mut e2) = (0.0, 0.0);
    for _ in 0..n {
        let w = rl
            .sample_ray_mm([0.0, 0.0], [rng.random(), rng.random()], 587.6)
            .map_or(0.0, |x| x.0);
        e += w;
        e2 += w * w;
    }
    let e_mean = e / n as f64;
    let e_sd = ((e2 / n as f64 - e_mean * e_mean) / n as f64).sqrt();
    let expect = e_mean * i.microlens_pitch_mm.powi(2);
    let tot_sd = (sd * sd + (e_sd * i.microlens_pitch_mm.powi(2)).powi(2)).sqrt();
    assert!(
        (flux - expect).abs() < 4.0 * tot_sd + 3e-3 * expect,
        "flux {flux:.5e} vs {expect:.5e} (sd {tot_sd:.1e})"
    );
}
