//! The real-lens camera against closed forms, an independent brute-force estimator and the lens
//! crate's own analyses (field-model PSF, relative illumination, distortion, lateral colour).
//!
//! Lens: the Double Gauss 50 mm f/2 of `lenses/` (stopped to f/4 where the PSF must stay
//! small). Monte Carlo results are checked with z-scores from their own variance estimates,
//! fixed seeds.
use camsim_core::rng::stream;
use camsim_lens::prescription::Aperture;
use camsim_lens::{FieldModel, FieldModelOptions, LensPrescription, PsfKind};
use camsim_render::camera::real_lens::LensExit;
use camsim_render::camera::real_lens::{FilmSize, RealLensCamera, RealLensOptions};
use camsim_render::camera::{Camera, OutputQuantity};
use glam::{Vec2, Vec3};
use rand::RngExt;
use rayon::prelude::*;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::sync::OnceLock;

fn dgauss() -> LensPrescription {
    super::test_lenses::double_gauss()
}

/// 64×64 film whose paraxial field is ±15° vertically (half-diagonal ≈ 19 mm, past 20°).
fn build(f_number: Option<f64>) -> RealLensCamera {
    // Paraxial focus: these tests compare the camera's tracer with the lens crate's own
    // analyses (distortion, field-model PSF, pupil bounds) on the paraxial image plane those use.
    let opts = RealLensOptions {
        f_number,
        film: FilmSize::VerticalFovRad(30f64.to_radians()),
        focus_method: camsim_lens::FocusMethod::paraxial(),
        ..Default::default()
    };
    RealLensCamera::new(&dgauss(), 64, 64, &opts).unwrap()
}

/// The cameras the tests share (built once): full aperture f/2, f/4 and f/8.
fn camera(f_number: Option<f64>) -> &'static RealLensCamera {
    static F2: OnceLock<RealLensCamera> = OnceLock::new();
    static F4: OnceLock<RealLensCamera> = OnceLock::new();
    static F8: OnceLock<RealLensCamera> = OnceLock::new();
    match f_number {
        None => F2.get_or_init(|| build(None)),
        Some(n) if n == 4.0 => F4.get_or_init(|| build(Some(4.0))),
        Some(n) if n == 8.0 => F8.get_or_init(|| build(Some(8.0))),
        Some(n) => panic!("no shared camera at f/{n}"),
    }
}

/// Mean and variance of the mean of `n` samples of `f(rng)`.
fn mean_var(
    n: usize,
    seed: u64,
    f: impl Fn(&mut camsim_core::rng::CamRng) -> f64 + Sync,
) -> (f64, f64) {
    let chunks = 16;
    let per = n / chunks;
    let parts: Vec<(f64, f64)> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = stream(seed, &[c as u64]);
            let (mut s, mut s2) = (0.0, 0.0);
            for _ in 0..per {
                let v = f(&mut rng);
                s += v;
                s2 += v * v;
            }
            (s, s2)
        })
        .collect();
    let m = (chunks * per) as f64;
    let s: f64 = parts.iter().map(|p| p.0).sum();
    let s2: f64 = parts.iter().map(|p| p.1).sum();
    let mean = s / m;
    (mean, (s2 / m - mean * mean).max(0.0) / m)
}

/// Irradiance per unit radiance at a sensor point (mm) from the camera's own sampler.
fn irradiance_sampler(
    cam: &RealLensCamera,
    p_mm: [f64; 2],
    wl: f64,
    n: usize,
    seed: u64,
) -> (f64, f64) {
    mean_var(n, seed, |rng| {
        let u = [rng.random::<f64>(), rng.random::<f64>()];
        cam.sample_ray_mm(p_mm, u, wl).map_or(0.0, |(w, _)| w)
    })
}

#[test]
fn real_lens_camera_reports_irradiance_and_film_geometry() {
    let cam = camera(None);
    assert!(matches!(
        cam.output_quantity(),
        OutputQuantity::SensorIrradiance
    ));
    assert_eq!(cam.film_size_px(), (64, 64));
    // The film centre maps to the axis; the image is upright: a pixel right of / below the
    // centre sees a direction to the right (+X) / below (−Y).
    let c = cam.center_ray(Vec2::new(32.0, 32.0)).unwrap();
    assert!((c.direction - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
    let r = cam.center_ray(Vec2::new(50.0, 32.0)).unwrap();
    assert!(r.direction.x > 0.05 && r.direction.y.abs() < 1e-6);
    let b = cam.center_ray(Vec2::new(32.0, 50.0)).unwrap();
    assert!(b.direction.y < -0.05 && b.direction.x.abs() < 1e-6);
    // The camera origin is the entrance pupil: the on-axis ray starts at the front vertex,
    // z_ep in front of it.
    assert!((c.origin_m.z as f64 + cam.info().entrance_pupil_z_mm * 1e-3).abs() < 1e-6);
    // Dispersion: the hero wavelength alone is valid.
    let g = cam
        .generate_ray(
            Vec2::new(40.0, 20.0),
            Vec2::new(0.5, 0.5),
            &[550.0, 600.0, 650.0, 700.0],
        )
        .unwrap();
    assert!(g.wavelength_dependent && g.weight[0] > 0.0 && g.weight[1..] == [0.0; 3]);
}

/// Closed form: on axis a well-corrected lens at f/8 gives E/L = π sin²θ' = π/(4N²) (Smith
/// §9.2; sin θ' = 1/(2N) for an aplanatic lens at infinity).
#[test]
fn on_axis_irradiance_matches_the_camera_equation() {
    for n in [8.0, 4.0] {
        let cam = camera(Some(n));
        let (e, v) = irradiance_sampler(cam, [0.0, 0.0], 587.6, 200_000, 1);
        let expect = std::f64::consts::PI / (4.0 * n * n);
        let rel = e / expect - 1.0;
        // f/8: aberrations are negligible (< 0.3 %); f/4: spherical aberration of the
        // marginal zone changes sin θ' by about 1 %.
        let tol = if n == 8.0 { 0.004 } else { 0.015 };
        assert!(
            rel.abs() < tol + 4.0 * v.sqrt() / expect,
            "f/{n}: E/L = {e:.6} vs π/4N² = {expect:.6} (rel {rel:+.4})"
        );
    }
}

/// The exit-pupil sampler draws uniformly from its box (chi-square on 8×8 cells of the box,
/// after undoing the rotation to the film point's azimuth) and reports the box area.
#[test]
fn exit_pupil_sampler_is_uniform_on_its_bounds_chi_square() {
    let cam = camera(None);
    let (dr, bins) = cam.pupil_table();
    let mut rng = stream(2, &[]);
    let cells = 8usize;
    let n = 64_000;
    for trial in 0..6 {
        let r = rng.random::<f64>() * dr * bins.len() as f64 * 0.95;
        let phi = rng.random::<f64>() * std::f64::consts::TAU;
        let p = [r * phi.cos(), r * phi.sin()];
        let b = bins[(r / dr) as usize].unwrap();
        let mut hist = vec![0usize; cells * cells];
        for _ in 0..n {
            let (q, area) = cam.sample_pupil(p, [rng.random(), rng.random()]).unwrap();
            assert!((area - b.area_mm2()).abs() < 1e-9 * area);
            // rotate back by −φ into the box frame
            let (c, s) = (phi.cos(), phi.sin());
            let (x, y) = (c * q[0] + s * q[1], -s * q[0] + c * q[1]);
            let fx = (x - b.x0_mm) / (b.x1_mm - b.x0_mm);
            let fy = (y - b.y0_mm) / (b.y1_mm - b.y0_mm);
            assert!((-1e-9..=1.0 + 1e-9).contains(&fx) && (-1e-9..=1.0 + 1e-9).contains(&fy));
            let i = ((fx * cells as f64) as usize).min(cells - 1);
            let j = ((fy * cells as f64) as usize).min(cells - 1);
            hist[j * cells + i] += 1;
        }
        let e = n as f64 / (cells * cells) as f64;
        let chi2: f64 = hist.iter().map(|&o| (o as f64 - e).powi(2) / e).sum();
        let p_value = 1.0
            - ChiSquared::new((cells * cells - 1) as f64)
                .unwrap()
                .cdf(chi2);
        assert!(
            p_value > 1e-3,
            "trial {trial}: chi² {chi2:.1}, p = {p_value:.2e}"
        );
    }
}

/// No ray that gets through the lens starts outside the pupil box of its film radius: rear-
/// plane points drawn from a square 4× the box area, random film points and wavelengths.
#[test]
fn exit_pupil_bounds_contain_every_transmitted_ray() {
    let cam = camera(None);
    let (dr, bins) = cam.pupil_table();
    let r_max = dr * bins.len() as f64;
    let e = bins
        .iter()
        .flatten()
        .map(|b| b.x0_mm.abs().max(b.x1_mm.abs()).max(b.y1_mm.abs()))
        .fold(0.0, f64::max)
        * 2.0;
    let outside: usize = (0..8u64)
        .into_par_iter()
        .map(|c| {
            let mut rng = stream(3, &[c]);
            let mut bad = 0;
            for _ in 0..25_000 {
                let r = rng.random::<f64>() * r_max * 0.999;
                let q = [
                    (2.0 * rng.random::<f64>() - 1.0) * e,
                    (2.0 * rng.random::<f64>() - 1.0) * e,
                ];
                let wl = 380.0 + 400.0 * rng.random::<f64>();
                if cam.trace_through([r, 0.0], q, wl).is_some() {
                    match bins[(r / dr) as usize] {
                        Some(b)
                            if (b.x0_mm..=b.x1_mm).contains(&q[0])
                                && (b.y0_mm..=b.y1_mm).contains(&q[1]) => {}
                        _ => bad += 1,
                    }
                }
            }
            bad
        })
        .sum();
    assert_eq!(
        outside, 0,
        "{outside} transmitted rays started outside their pupil box"
    );
}

/// The camera's irradiance estimate (pupil-box sampling) equals a brute-force estimate that
/// samples the rear plane uniformly over a large square (same integrand, independent pdf).
#[test]
fn irradiance_estimator_agrees_with_brute_force_rear_plane_sampling() {
    let cam = camera(None);
    let d = cam.info().rear_plane_mm;
    let half = 25.0; // mm, larger than every pupil box
    for (i, p) in [[0.0, 0.0], [0.0, 7.0], [-9.0, 9.0], [15.0, 3.0]]
        .iter()
        .enumerate()
    {
        let (e1, v1) = irradiance_sampler(cam, *p, 550.0, 160_000, 10 + i as u64);
        let (e2, v2) = mean_var(320_000, 20 + i as u64, |rng| {
            let q = [
                (2.0 * rng.random::<f64>() - 1.0) * half,
                (2.0 * rng.random::<f64>() - 1.0) * half,
            ];
            let v = [q[0] - p[0], q[1] - p[1], d];
            let cos = d / (v[0] * v[0] + v[1] * v[1] + d * d).sqrt();
            match cam.trace_through(*p, q, 550.0) {
                Some(_) => cos.powi(4) * (2.0 * half).powi(2) / (d * d),
                None => 0.0,
            }
        });
        let z = (e1 - e2) / (v1 + v2).sqrt();
        assert!(
            z.abs() < 4.0,
            "film point {p:?}: pupil-box {e1:.5} vs brute force {e2:.5} (z = {z:.2})"
        );
    }
}

/// Relative illumination (irradiance of a uniform radiance field at the real image height of
/// field θ over the on-axis value) matches the lens report (vignetting fraction of the
/// entrance pupil × cos⁴ of the image-space chief ray). The two differ by definition (the
/// report's cos⁴ is that of the chief ray, not the pupil average; pupil aberrations): about
/// 0.7 % at f/4, 14°. Tolerance 1.5 % relative + 4σ.
#[test]
fn relative_illumination_matches_the_lens_report() {
    for f_number in [None, Some(4.0)] {
        let cam = camera(f_number);
        let mut lens = dgauss();
        if let Some(n) = f_number {
            lens.aperture = Aperture::FNumber(n);
        }
        let (e0, v0) = irradiance_sampler(cam, [0.0, 0.0], 587.6, 200_000, 30);
        for (i, th) in [7.0, 14.0, 18.0].into_iter().enumerate() {
            let h = lens.distortion(th).unwrap().real_height_mm;
            let report = lens
                .relative_illumination(th, 587.6, 128)
                .unwrap()
                .relative_illumination;
            // a point at azimuth 135° (the camera is rotationally symmetric)
            let p = [-h / 2f64.sqrt(), h / 2f64.sqrt()];
            let (e, v) = irradiance_sampler(cam, p, 587.6, 200_000, 31 + i as u64);
            let ri = e / e0;
            let sd = ri * (v / (e * e) + v0 / (e0 * e0)).sqrt();
            assert!(
                (ri - report).abs() < 0.015 * report + 4.0 * sd,
                "f/{f_number:?} {th}°: camera RI {ri:.4} ± {sd:.4} vs lens report {report:.4}"
            );
        }
    }
}

/// Distortion: the camera's centre ray (the chief ray, through the stop centre) from the film
/// point at the report's real image height of field θ leaves at θ, so the camera reproduces
/// the report's distortion (100 (y_real − y_parax)/y_parax).
#[test]
fn distortion_matches_the_lens_report() {
    let cam = camera(None);
    let lens = dgauss();
    for th in [3.0, 8.0, 12.0, 16.0, 19.0] {
        let d = lens.distortion(th).unwrap();
        for az in [90f64, 200.0] {
            let a = az.to_radians();
            let px = cam.film_px([d.real_height_mm * a.cos(), d.real_height_mm * a.sin()]);
            let r = cam.center_ray(px).unwrap();
            let angle = (r.direction.truncate().length() as f64)
                .atan2(-r.direction.z as f64)
                .to_degrees();
            assert!(
                (angle - th).abs() < 2e-3,
                "{th}° at azimuth {az}°: centre ray at {angle:.5}°"
            );
            // the centre ray points at the object side opposite to the image point
            let dir_az = (r.direction.y as f64)
                .atan2(r.direction.x as f64)
                .to_degrees();
            let opposite = (az + 180.0).rem_euclid(360.0);
            let daz = (dir_az.rem_euclid(360.0) - opposite + 540.0).rem_euclid(360.0) - 180.0;
            assert!(daz.abs() < 1e-3, "azimuth {dir_az} vs {opposite}");
            // the camera's distortion from this angle equals the report's
            let parax = lens
                .paraxial_chief_height_mm(angle, lens.primary_nm)
                .unwrap()
                .abs();
            let dist_cam = 100.0 * (d.real_height_mm - parax) / parax;
            assert!(
                (dist_cam - d.distortion_pct).abs() < 0.01,
                "{th}°: {dist_cam:.4} % vs {:.4} %",
                d.distortion_pct
            );
        }
    }
}

/// Irradiance image of a small distant disc source (angular radius δ) estimated on a grid of
/// `n`×`n` cells of `pitch_mm` centred on sensor point (0, y0): per cell the mean over `k`
/// samples (film position uniform in the cell, pupil sample uniform) of w·[ray hits the disc].
/// Returns (mean, variance of the mean) per cell.
fn disc_source_image(
    cam: &RealLensCamera,
    field_deg: f64,
    delta_rad: f64,
    wl: f64,
    y0_mm: f64,
    n: usize,
    pitch_mm: f64,
    k: usize,
    seed: u64,
) -> Vec<(f64, f64)> {
    let th = field_deg.to_radians();
    // towards the object (camera space): below the axis, so the image lies on sensor +y
    let omega = [0.0, -th.sin(), -th.cos()];
    let cos_d = delta_rad.cos();
    (0..n * n)
        .into_par_iter()
        .map(|c| {
            let (ix, iy) = (c % n, c / n);
            let mut rng = stream(seed, &[c as u64]);
            let (mut s, mut s2) = (0.0, 0.0);
            for _ in 0..k {
                let x = (ix as f64 - (n / 2) as f64 + rng.random::<f64>() - 0.5) * pitch_mm;
                let y = y0_mm + (iy as f64 - (n / 2) as f64 + rng.random::<f64>() - 0.5) * pitch_mm;
                let u = [rng.random::<f64>(), rng.random::<f64>()];
                let v = match cam.sample_ray_mm([x, y], u, wl) {
                    Some((w, LensExit { direction: d, .. })) => {
                        // mirrored frame → camera frame: z flips
                        let dot = d[0] * omega[0] + d[1] * omega[1] - d[2] * omega[2];
                        if dot > cos_d {
                            w
                        } else {
                            0.0
                        }
                    }
                    None => 0.0,
                };
                s += v;
                s2 += v * v;
            }
            let m = s / k as f64;
            (m, (s2 / k as f64 - m * m).max(0.0) / k as f64)
        })
        .collect()
}

/// Centroid (x, y) in cells, its standard error (cells) and RMS radius (cells) of an n×n
/// image.
struct PsfStats {
    cx: f64,
    cy: f64,
    c_se: f64,
    rms: f64,
}

/// Fraction of the energy of an n×n image within `r` cells of (cx, cy) (cell centres).
fn encircled(img: &[(f64, f64)], n: usize, cx: f64, cy: f64, r: f64) -> f64 {
    let tot: f64 = img.iter().map(|v| v.0).sum();
    let inside: f64 = img
        .iter()
        .enumerate()
        .filter(|(i, _)| ((i % n) as f64 - cx).hypot((i / n) as f64 - cy) <= r)
        .map(|(_, v)| v.0)
        .sum();
    inside / tot
}

fn psf_stats(img: &[(f64, f64)], n: usize) -> PsfStats {
    let tot: f64 = img.iter().map(|v| v.0).sum();
    let pos = |i: usize| ((i % n) as f64, (i / n) as f64);
    let (mut cx, mut cy) = (0.0, 0.0);
    for (i, v) in img.iter().enumerate() {
        let (x, y) = pos(i);
        cx += x * v.0 / tot;
        cy += y * v.0 / tot;
    }
    let (mut m2, mut var_c) = (0.0, 0.0);
    for (i, v) in img.iter().enumerate() {
        let (x, y) = pos(i);
        let r2 = (x - cx).powi(2) + (y - cy).powi(2);
        m2 += r2 * v.0 / tot;
        var_c += r2 * v.1 / (tot * tot);
    }
    PsfStats {
        cx,
        cy,
        c_se: (var_c / 2.0).sqrt(),
        rms: m2.sqrt(),
    }
}

/// Field-model PSF (n×n, sum 1) convolved with the image of the disc source: an ellipse of
/// semi-axes `a_x`, `a_y` (cells), rasterised with 8×8 sub-samples per cell.
fn convolve_ellipse(psf: &[f64], n: usize, a_x: f64, a_y: f64) -> Vec<(f64, f64)> {
    let r = a_x.max(a_y).ceil() as isize + 1;
    let mut ker = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            let mut w = 0.0;
            for sy in 0..8 {
                for sx in 0..8 {
                    let x = dx as f64 + (sx as f64 + 0.5) / 8.0 - 0.5;
                    let y = dy as f64 + (sy as f64 + 0.5) / 8.0 - 0.5;
                    if (x / a_x).powi(2) + (y / a_y).powi(2) <= 1.0 {
                        w += 1.0;
                    }
                }
            }
            if w > 0.0 {
                ker.push((dx, dy, w));
            }
        }
    }
    let kt: f64 = ker.iter().map(|k| k.2).sum();
    let mut out = vec![(0.0, 0.0); n * n];
    for iy in 0..n as isize {
        for ix in 0..n as isize {
            let v = psf[(iy as usize) * n + ix as usize];
            if v == 0.0 {
                continue;
            }
            for &(dx, dy, w) in &ker {
                let (x, y) = (ix + dx, iy + dy);
                if x >= 0 && y >= 0 && x < n as isize && y < n as isize {
                    out[(y as usize) * n + x as usize].0 += v * w / kt;
                }
            }
        }
    }
    out
}

/// A distant point source imaged by the camera matches the lens crate's field-model
/// (geometric) PSF: centroid (chief ray + coma), RMS radius and 50 % / 80 % encircled-energy
/// radii, on axis and at 14°, f/4, 587.6 nm; and lateral colour (the 486.1 − 656.3 nm
/// centroid shift at 14°). The source is a disc of angular radius δ = 10⁻⁴ rad (an image
/// ellipse of about 5 µm, convolved into the field-model PSF).
#[test]
fn distant_point_source_matches_the_field_model_psf() {
    let cam = camera(Some(4.0));
    let mut lens = dgauss();
    lens.aperture = Aperture::FNumber(4.0);
    let wls = vec![486.1, 587.6, 656.3];
    let n = 65;
    let pitch_um = 2.0;
    let fm = FieldModel::compute(
        &lens,
        &FieldModelOptions {
            n_fields: 2,
            max_field_deg: Some(14.0),
            wavelengths_nm: Some(wls.clone()),
            kind: PsfKind::Geometric,
            psf_n: n,
            psf_pitch_um: pitch_um,
            pupil_n: 256,
            ..Default::default()
        },
    )
    .unwrap();
    // the object-at-infinity table (the only one requested)
    let fm = fm.at_distance(None);
    let delta = 1e-4;
    let pitch_mm = pitch_um * 1e-3;
    let mut centroids = Vec::new();
    for (f, wi, k) in [
        (0usize, 1usize, 256usize),
        (1, 1, 256),
        (1, 0, 96),
        (1, 2, 96),
    ] {
        let th = fm.field_angles_deg[f];
        let wl = wls[wi];
        let y0 = fm.real_height_mm[f][wi];
        let img = disc_source_image(
            cam,
            th,
            delta,
            wl,
            y0,
            n,
            pitch_mm,
            k,
            40 + (f * 3 + wi) as u64,
        );
        // image ellipse of the disc: tangential δ·h/sin θ, radial δ·dh/dθ (cells)
        let dh = {
            let e: f64 = 0.05;
            let hp = lens.distortion(th + e).unwrap().real_height_mm;
            let hm = if th > e {
                lens.distortion(th - e).unwrap().real_height_mm
            } else {
                -hp
            };
            (hp - hm) / (2.0 * e.to_radians())
        };
        let a_t = if th > 0.0 {
            y0 / th.to_radians().sin()
        } else {
            dh
        } * delta
            / pitch_mm;
        let a_r = dh * delta / pitch_mm;
        let conv = convolve_ellipse(&fm.psf[f][wi], n, a_t, a_r);
        let expect = psf_stats(&conv, n);
        let got = psf_stats(&img, n);
        let ctx = format!("{th:.1}° {wl} nm");
        // centroids (cells) agree within 4 standard errors + 0.1 cell
        for (g, e) in [(got.cx, expect.cx), (got.cy, expect.cy)] {
            assert!(
                (g - e).abs() < 0.1 + 4.0 * got.c_se,
                "{ctx}: centroid {g:.3} vs field model {e:.3} (se {:.3})",
                got.c_se
            );
        }
        centroids.push((
            y0 + (got.cy - (n / 2) as f64) * pitch_mm,
            got.c_se * pitch_mm,
            y0 + (expect.cy - (n / 2) as f64) * pitch_mm,
        ));
        if wi == 1 {
            assert!(
                (got.rms / expect.rms - 1.0).abs() < 0.04,
                "{ctx}: RMS radius {:.2} µm vs field model {:.2} µm",
                got.rms * pitch_um,
                expect.rms * pitch_um
            );
            // encircled energy about each centroid at 0.5, 1, 1.5 and 2 RMS radii
            for m in [0.5, 1.0, 1.5, 2.0] {
                let r = m * expect.rms;
                let (g, e) = (
                    encircled(&img, n, got.cx, got.cy, r),
                    encircled(&conv, n, expect.cx, expect.cy, r),
                );
                assert!(
                    (g - e).abs() < 0.03,
                    "{ctx}: EE({:.1} µm) {g:.3} vs field model {e:.3}",
                    r * pitch_um
                );
            }
        }
    }
    // lateral colour at 14°: blue − red centroid shift
    let (b, r) = (centroids[2], centroids[3]);
    let got = b.0 - r.0;
    let expect = b.2 - r.2;
    let se = (b.1 * b.1 + r.1 * r.1).sqrt();
    assert!(
        (got - expect).abs() < 0.2e-3 + 4.0 * se,
        "lateral colour {:.2} µm vs field model {:.2} µm",
        got * 1e3,
        expect * 1e3
    );
}
