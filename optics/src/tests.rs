//! Tests of the optics stage (closed forms, FFT blur, ISETCam oracles).
use super::*;
use approx::assert_relative_eq;
use camsim_core::npy::read_npy;
use camsim_core::{SpectralBasis, SpectralImage};
use std::f64::consts::PI;
use std::path::PathBuf;

const ORACLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/oracles/isetcam");

fn oracle_case(name: &str) -> serde_json::Value {
    let p = PathBuf::from(ORACLES).join("cases").join(name);
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).unwrap()
}

/// Read an oracle `.npy` (C or Fortran order, `<f8`) as C-ordered data. `camsim_core::npy`
/// is used for C order; the oracle cubes are stored in Fortran order, converted here.
fn read_oracle_npy(rel: &str) -> (Vec<usize>, Vec<f64>) {
    let path = PathBuf::from(ORACLES).join(rel);
    if let Ok(a) = read_npy(&path) {
        return (a.shape, a.data);
    }
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let (hlen, hstart) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        )
    };
    let header = String::from_utf8_lossy(&bytes[hstart..hstart + hlen]).to_string();
    assert!(
        header.contains("'<f8'") && header.contains("'fortran_order': True"),
        "{header}"
    );
    let shape: Vec<usize> = header
        .split("'shape':")
        .nth(1)
        .unwrap()
        .split('(')
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap()
        .split(',')
        .filter_map(|t| t.trim().parse().ok())
        .collect();
    let f: Vec<f64> = bytes[hstart + hlen..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let n: usize = shape.iter().product();
    assert_eq!(f.len(), n);
    // Fortran: first index fastest. Convert to C order.
    let mut c = vec![0.0; n];
    let mut idx = vec![0usize; shape.len()];
    for (fi, &v) in f.iter().enumerate() {
        let mut r = fi;
        for (k, &s) in shape.iter().enumerate() {
            idx[k] = r % s;
            r /= s;
        }
        let ci = idx.iter().zip(&shape).fold(0, |acc, (&i, &s)| acc * s + i);
        c[ci] = v;
    }
    (shape, c)
}

fn f64s(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn band_scene(
    rows: usize,
    cols: usize,
    grid: &WavelengthGrid,
    pitch_m: f64,
    planes: Vec<Vec<f32>>,
) -> SceneRadiance {
    SceneRadiance {
        radiance: SpectralImage::new(rows, cols, SpectralBasis::Bands(grid.clone()), planes)
            .unwrap(),
        sample_pitch_m: pitch_m,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    }
}

fn plain(blur: Blur) -> OpticsModel {
    OpticsModel {
        relative_illumination: RelativeIllumination::None,
        blur,
        ..OpticsModel::diffraction_limited(4.0, 4e-3)
    }
}

#[test]
fn isetcam_diffraction_limited_default_oracle() {
    let case = oracle_case("oi_diffraction_limited_default.json");
    let (sshape, scene) = read_oracle_npy("data/scene_macbeth_default__photons.npy");
    let (eshape, expected) = read_oracle_npy("data/oi_diffraction_limited_default__photons.npy");
    assert_eq!(sshape, vec![64, 96, 31]);
    assert_eq!(eshape, vec![64, 96, 31]);
    let (rows, cols, nb) = (64, 96, 31);
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let planes: Vec<Vec<f32>> = (0..nb)
        .map(|b| (0..rows * cols).map(|p| scene[p * nb + b] as f32).collect())
        .collect();
    let optics_in = &case["inputs"]["optics"];
    let n = optics_in["f_number"].as_f64().unwrap();
    let f = optics_in["focal_length_m"].as_f64().unwrap();
    let d = case["inputs"]["scene_distance_m"].as_f64().unwrap();
    let hfov = case["inputs"]["scene_hfov_deg"]
        .as_f64()
        .unwrap()
        .to_radians();
    let img_dist = thin_lens_image_distance_m(f, Some(d));
    let dx = 2.0 * img_dist * (hfov / 2.0).tan() / cols as f64;
    let mut sc = band_scene(rows, cols, &grid, dx, planes);
    sc.object_distance_m = Some(d);
    let optics = OpticsModel {
        f_number: n,
        focal_length_m: f,
        transmittance: Spectrum::constant(1.0),
        relative_illumination: RelativeIllumination::IsetCam,
        camera_equation: CameraEquation::IsetCam,
        blur: Blur::Diffraction,
        diffuser: None,
        padding: Padding::Zero,
        effects: Default::default(),
    };
    let out = form_image(&optics, &sc, &grid).unwrap();
    let e = &out.irradiance;
    let max = expected.iter().cloned().fold(0.0, f64::max);
    let mut worst = 0.0f64;
    for b in 0..nb {
        for p in 0..rows * cols {
            let diff = (e.planes[b][p] as f64 - expected[p * nb + b]).abs() / max;
            worst = worst.max(diff);
        }
    }
    eprintln!("oi_diffraction_limited_default: max |diff| / max = {worst:.3e}");
    assert!(worst < 5e-4, "max abs diff relative to max {worst}");
}

#[test]
fn isetcam_otf_wavelength_oracle() {
    let case = oracle_case("oi_otfwavelength_diffraction_small.json");
    let n = case["inputs"]["optics"]["f_number"].as_f64().unwrap();
    let wl = f64s(&case["inputs"]["wavelength_nm"]["values"]);
    let fx = f64s(&case["inputs"]["fx_cycles_per_um"]["values"]);
    let otf = f64s(&case["expected"]["otf"]["values"]);
    assert_eq!(otf.len(), fx.len() * wl.len());
    for (i, &f) in fx.iter().enumerate() {
        for (k, &w) in wl.iter().enumerate() {
            let got = diffraction_otf(f * 1e6, w, n);
            let exp = otf[i * wl.len() + k];
            assert!((got - exp).abs() <= 1e-9, "fx {f} λ {w}: {got} vs {exp}");
        }
    }
}

#[test]
fn isetcam_airy_disk_oracle() {
    let case = oracle_case("optics_airy_disk_small.json");
    let q = &case["inputs"]["radius_um_query"];
    let r = airy_first_zero_m(
        q["wavelength_nm"].as_f64().unwrap(),
        q["f_number"].as_f64().unwrap(),
    );
    let e = &case["expected"];
    assert_relative_eq!(
        r * 1e6,
        e["radius_um"].as_f64().unwrap(),
        max_relative = 2e-3
    );
    assert_relative_eq!(
        2.0 * r * 1e6,
        e["diameter_um"].as_f64().unwrap(),
        max_relative = 2e-3
    );
    let q = &case["inputs"]["radius_angle_query"];
    let a = airy_first_zero_rad(
        q["wavelength_nm"].as_f64().unwrap(),
        q["pupil_diameter_m"].as_f64().unwrap(),
    );
    assert_relative_eq!(a, e["radius_rad"].as_f64().unwrap(), max_relative = 2e-3);
    assert_relative_eq!(
        a.to_degrees(),
        e["radius_deg"].as_f64().unwrap(),
        max_relative = 2e-3
    );
}

#[test]
fn camera_equation_closed_form() {
    // Object at infinity: exactly π/(4N²).
    assert_eq!(camera_equation_factor(4.0, 0.0), PI / 64.0);
    assert_eq!(camera_equation_factor(2.8, 0.0), PI / (4.0 * 2.8 * 2.8));
    // Finite distance: thin lens, m = −i/d.
    let (f, d) = (0.05, 1.0);
    let i = thin_lens_image_distance_m(f, Some(d));
    assert_relative_eq!(i, 0.05 / 0.95, max_relative = 1e-12);
    let m = magnification(f, Some(d));
    assert_relative_eq!(m, -i / d, max_relative = 1e-12);
    assert_relative_eq!(
        camera_equation_factor(2.0, m),
        PI / (16.0 * (1.0 + i / d).powi(2)),
        max_relative = 1e-12
    );
    assert_relative_eq!(
        camera_equation_factor_isetcam(4.0, 0.0),
        PI / 65.0,
        max_relative = 1e-15
    );
    // Through the pipeline: uniform scene, no blur, no falloff, T = 0.9.
    let g = WavelengthGrid::regular(500.0, 600.0, 50.0).unwrap();
    let sc = band_scene(3, 4, &g, 1e-6, vec![vec![1e15; 12]; 3]);
    let mut o = plain(Blur::None);
    o.transmittance = Spectrum::constant(0.9);
    let e = form_image(&o, &sc, &g).unwrap().irradiance;
    for p in &e.planes {
        for v in p {
            assert_relative_eq!(*v as f64, 1e15 * 0.9 * PI / 64.0, max_relative = 1e-6);
        }
    }
    // Spectral transmittance scales per band.
    o.transmittance = Spectrum::sampled(vec![500.0, 600.0], vec![1.0, 0.5]).unwrap();
    let e = form_image(&o, &sc, &g).unwrap().irradiance;
    assert_relative_eq!(
        e.planes[1][0] as f64,
        1e15 * 0.75 * PI / 64.0,
        max_relative = 1e-6
    );
    // Finite object distance in the pipeline.
    let mut sc2 = sc.clone();
    sc2.object_distance_m = Some(0.2);
    o.transmittance = Spectrum::constant(1.0);
    let e = form_image(&o, &sc2, &g).unwrap().irradiance;
    let m = magnification(4e-3, Some(0.2));
    assert_relative_eq!(
        e.planes[0][5] as f64,
        1e15 * PI / (64.0 * (1.0 + m.abs()).powi(2)),
        max_relative = 1e-6
    );
}

#[test]
fn cos4_by_row_is_cos4_of_the_pixel_angle() {
    // The row form (f² + y² formed once) against cos⁴ of the angle tan θ = √(x² + y²)/f.
    let f = 0.004;
    for y_m in [0.0, 1e-4, 1.7e-3, 4e-3] {
        let row = relative_illumination_cos4_row(y_m * y_m, f);
        for x_m in [0.0, 3e-5, 2.2e-3, 6e-3] {
            let t = (x_m as f64).hypot(y_m).atan2(f);
            assert_relative_eq!(row(x_m * x_m), t.cos().powi(4), max_relative = 1e-13);
            assert_relative_eq!(
                row(x_m * x_m),
                relative_illumination_cos4_r2(x_m * x_m + y_m * y_m, f),
                max_relative = 1e-15
            );
        }
    }
}

#[test]
fn cos4_values() {
    let f = 0.01;
    assert_eq!(relative_illumination_cos4(0.0, f), 1.0);
    assert_relative_eq!(relative_illumination_cos4(f, f), 0.25, max_relative = 1e-15);
    let t = 30f64.to_radians();
    assert_relative_eq!(
        relative_illumination_cos4(f * t.tan(), f),
        t.cos().powi(4),
        max_relative = 1e-12
    );
    // In the pipeline: the corner of a 5×5 image at pitch p lies at r = 2√2 p.
    let g = WavelengthGrid::new(vec![550.0]).unwrap();
    let p = 1e-3;
    let sc = band_scene(5, 5, &g, p, vec![vec![1.0; 25]]);
    let mut o = plain(Blur::None);
    o.relative_illumination = RelativeIllumination::Cos4;
    o.focal_length_m = f;
    let e = form_image(&o, &sc, &g).unwrap().irradiance;
    let k = PI / 64.0;
    assert_relative_eq!(e.planes[0][12] as f64, k, max_relative = 1e-6);
    let r = (8.0f64).sqrt() * p;
    let c2 = f * f / (f * f + r * r);
    assert_relative_eq!(e.planes[0][0] as f64, k * c2 * c2, max_relative = 1e-6);
    // The ISETCam formula is 1 on the axis and falls off monotonically.
    assert_relative_eq!(
        relative_illumination_isetcam(0.0, 0.0, f, 4.0, 0.0, 1e-3),
        1.0,
        epsilon = 1e-12
    );
    let a = relative_illumination_isetcam(1e-3, 0.0, f, 4.0, 0.0, 1e-3);
    let b = relative_illumination_isetcam(2e-3, 0.0, f, 4.0, 0.0, 1e-3);
    assert!(1.0 > a && a > b && b > 0.0, "{a} {b}");
}

#[test]
fn otf_closed_form() {
    let (w, n) = (550.0, 4.0);
    let rc = 1.0 / (w * 1e-9 * n);
    assert_eq!(diffraction_otf(0.0, w, n), 1.0);
    for u in [0.1f64, 0.25, 0.5, 0.75, 0.9] {
        let h = (2.0 / PI) * (u.acos() - u * (1.0 - u * u).sqrt());
        assert_relative_eq!(diffraction_otf(u * rc, w, n), h, max_relative = 1e-12);
        assert_relative_eq!(diffraction_otf(-u * rc, w, n), h, max_relative = 1e-12);
    }
    assert_relative_eq!(
        diffraction_otf(0.5 * rc, w, n),
        0.391_002_218,
        max_relative = 1e-8
    );
    assert_eq!(diffraction_otf(rc, w, n), 0.0);
    assert_eq!(diffraction_otf(1.5 * rc, w, n), 0.0);
}

#[test]
fn airy_psf_closed_form() {
    let (w, n) = (550.0, 4.0);
    let ln = w * 1e-9 * n;
    // Peak π/(4 (λN)²); zero at 1.2197 λN; integral 1 (radial quadrature).
    assert_relative_eq!(
        airy_psf(0.0, w, n),
        PI / (4.0 * ln * ln),
        max_relative = 1e-9
    );
    assert!(airy_psf(3.8317 / PI * ln, w, n) < 1e-8 * airy_psf(0.0, w, n));
    let dr = ln / 200.0;
    let total: f64 = (0..200 * 400)
        .map(|i| {
            let r = (i as f64 + 0.5) * dr;
            airy_psf(r, w, n) * 2.0 * PI * r * dr
        })
        .sum();
    // Encircled energy within 400 λN is 1 − ~2/(π² · 400)·…; > 0.998.
    assert!(total > 0.998 && total < 1.0 + 1e-6, "{total}");
    assert_relative_eq!(bessel_j1(1.0), 0.440_050_585_744_933_5, epsilon = 1e-8);
    assert_relative_eq!(bessel_j1(10.0), 0.043_472_746_168_861_44, epsilon = 1e-8);
}

/// A single bright sample on a finely sampled grid, blurred by the FFT diffraction OTF: the
/// first minimum of the radial profile lies at 1.22 λN and the profile follows the Airy PSF.
#[test]
fn airy_first_zero_in_fft_psf_of_point_source() {
    let (w, n) = (550.0, 4.0);
    let g = WavelengthGrid::new(vec![w]).unwrap();
    let dx = 0.05e-6;
    let size = 201;
    let c = size / 2;
    let mut plane = vec![0f32; size * size];
    plane[c * size + c] = 1.0;
    for padding in [Padding::Replicate, Padding::Zero] {
        let sc = band_scene(size, size, &g, dx, vec![plane.clone()]);
        let mut o = plain(Blur::Diffraction);
        o.padding = padding;
        let e = form_image(&o, &sc, &g).unwrap().irradiance;
        let p = &e.planes[0];
        let prof: Vec<f64> = (0..=c).map(|k| p[c * size + c + k] as f64).collect();
        let first_min = (1..c)
            .find(|&k| prof[k] < prof[k - 1] && prof[k] <= prof[k + 1])
            .unwrap();
        let r_min = first_min as f64 * dx;
        let expect = airy_first_zero_m(w, n);
        assert!(
            (r_min - expect).abs() <= dx,
            "{padding:?}: first minimum {r_min} vs {expect}"
        );
        // Radial profile vs the closed-form Airy PSF times the sample area.
        let k0 = PI / 64.0; // camera equation factor π/(4N²), N = 4
        for k in [0usize, 10, 20, 40, 70] {
            let airy = airy_psf(k as f64 * dx, w, n) * dx * dx * k0;
            assert!(
                (prof[k] - airy).abs() < 0.01 * airy_psf(0.0, w, n) * dx * dx * k0,
                "r={k}: {} vs {airy}",
                prof[k]
            );
        }
        // Symmetric in x and y.
        assert_relative_eq!(
            p[(c + 20) * size + c],
            p[c * size + c + 20],
            max_relative = 1e-4
        );
    }
}

fn uniform_blur_check(blur: Blur, diffuser: Option<Diffuser>) {
    let g = WavelengthGrid::regular(400.0, 700.0, 50.0).unwrap();
    let (rows, cols) = (37, 52);
    let planes: Vec<Vec<f32>> = (0..g.len())
        .map(|b| vec![1.0 + b as f32; rows * cols])
        .collect();
    let sc = band_scene(rows, cols, &g, 1.0e-6, planes);
    let mut o = plain(blur.clone());
    o.diffuser = diffuser;
    let e = form_image(&o, &sc, &g).unwrap().irradiance;
    let k = PI / 64.0;
    for (b, p) in e.planes.iter().enumerate() {
        for v in p {
            let want = (1.0 + b as f64) * k;
            assert!(
                ((*v as f64) - want).abs() < 1e-5 * want,
                "{blur:?}: band {b} {v} vs {want}"
            );
        }
    }
}

#[test]
fn uniform_scene_stays_uniform_with_replicate_padding() {
    uniform_blur_check(Blur::Diffraction, None);
    uniform_blur_check(Blur::Gaussian { sigma_um: 3.0 }, None);
    uniform_blur_check(Blur::Pillbox { width_um: 7.0 }, None);
    uniform_blur_check(
        Blur::Wavefront {
            defocus_um: 0.1,
            pupil_samples: 64,
        },
        None,
    );
    uniform_blur_check(Blur::None, Some(Diffuser { fwhm_um: 2.0 }));
    uniform_blur_check(Blur::Psf(test_psf_set()), None);
}

/// A compact object far from the borders: every blur preserves the total irradiance; with
/// diffraction and replicated edges (the far-tail correction, issue 17 §5), the image keeps
/// the total minus the Airy tail beyond its four sides — per sample `Σ_sides T(d)` minus the
/// four quadrants `(a + b − √(a²+b²)) λN/(π³ab)` counted twice (the envelope's integrals;
/// 0.55–0.8 % here) — within 1e-3 of the total.
#[test]
fn blur_conserves_energy() {
    let g = WavelengthGrid::regular(450.0, 650.0, 100.0).unwrap();
    let (rows, cols) = (170, 160);
    let mut plane = vec![0f32; rows * cols];
    for i in 77..93 {
        for j in 70..90 {
            plane[i * cols + j] = ((i * 7 + j * 3) % 5) as f32 + 1.0;
        }
    }
    let sc = band_scene(rows, cols, &g, 1e-6, vec![plane.clone(); 3]);
    let total_in: f64 = plane.iter().map(|v| *v as f64).sum::<f64>() * PI / 64.0;
    for blur in [
        Blur::Gaussian { sigma_um: 2.0 },
        Blur::Pillbox { width_um: 5.0 },
        Blur::Wavefront {
            defocus_um: 0.1,
            pupil_samples: 64,
        },
        Blur::Psf(test_psf_set()),
        Blur::Diffraction,
    ] {
        for padding in [Padding::Replicate, Padding::Zero] {
            let mut o = plain(blur.clone());
            o.padding = padding;
            let e = form_image(&o, &sc, &g).unwrap().irradiance;
            let tol = if blur == Blur::Diffraction {
                5e-3
            } else {
                1e-5
            };
            for (p, &w) in e.planes.iter().zip(&g.wavelength_nm) {
                let s: f64 = p.iter().map(|v| *v as f64).sum();
                if blur == Blur::Diffraction && padding == Padding::Replicate {
                    let ln = w * 1e-9 * 4.0;
                    let quad = |a: f64, b: f64| {
                        (a + b - (a * a + b * b).sqrt()) * ln / (PI.powi(3) * a * b)
                    };
                    let kept: f64 = (0..rows * cols)
                        .map(|q| {
                            let (i, j) = ((q / cols) as f64 + 0.5, (q % cols) as f64 + 0.5);
                            let (t, b) = (i * 1e-6, (rows as f64 - i) * 1e-6);
                            let (l, r) = (j * 1e-6, (cols as f64 - j) * 1e-6);
                            let out = [t, b, l, r]
                                .iter()
                                .map(|&d| airy_edge_tail_fraction(d, w, 4.0))
                                .sum::<f64>()
                                - quad(t, l)
                                - quad(t, r)
                                - quad(b, l)
                                - quad(b, r);
                            plane[q] as f64 * (1.0 - out)
                        })
                        .sum::<f64>()
                        * PI
                        / 64.0;
                    eprintln!("{w} nm: kept {s:.6}, expected {kept:.6} (total {total_in:.6})");
                    assert!(
                        (s - kept).abs() < 1e-3 * total_in,
                        "{blur:?} {padding:?} {w} nm: {s} vs {kept} (total {total_in})"
                    );
                    continue;
                }
                assert!(
                    (s - total_in).abs() < tol * total_in,
                    "{blur:?} {padding:?}: {s} vs {total_in}"
                );
            }
            // and it actually blurs: the peak drops
            let max_in = plane.iter().cloned().fold(0.0, f32::max) as f64 * PI / 64.0;
            let max_out = e.planes[0].iter().cloned().fold(0.0, f32::max) as f64;
            assert!(max_out < 0.99 * max_in, "{blur:?}: no blur");
        }
    }
}

#[test]
fn psfs_sum_to_one() {
    for (s, p) in [(0.5, 1.0), (2.0, 1.0), (3.3, 0.7)] {
        let k = gaussian_kernel_1d(s * 1e-6, p * 1e-6);
        assert_relative_eq!(k.iter().sum::<f64>(), 1.0, epsilon = 1e-12);
        assert_eq!(k.len() % 2, 1);
    }
    // discrete variance of the Gaussian kernel ≈ σ²
    let k = gaussian_kernel_1d(2e-6, 1e-6);
    let h = (k.len() / 2) as f64;
    let var: f64 = k
        .iter()
        .enumerate()
        .map(|(i, v)| v * (i as f64 - h).powi(2))
        .sum();
    assert_relative_eq!(var, 4.0, max_relative = 1e-3);
    assert_relative_eq!(sigma_from_fwhm(2.354_820_045), 1.0, max_relative = 1e-9);
    let pb = pillbox_psf(5e-6, 1e-6);
    assert_relative_eq!(pb.sum(), 1.0, epsilon = 1e-12);
    assert_eq!(pb.half_rows, 2);
    assert_eq!(pillbox_psf(0.1e-6, 1e-6).data, vec![1.0]);
    let wf = wavefront_psf(550.0, 4.0, 0.1, 64, 0.5e-6).unwrap();
    assert_relative_eq!(wf.sum(), 1.0, epsilon = 1e-12);
    let set = test_psf_set();
    for w in [400.0, 480.0, 520.0, 700.0] {
        assert_relative_eq!(
            set.at_wavelength(w).iter().sum::<f64>(),
            1.0,
            epsilon = 1e-12
        );
        for pitch in [0.3e-6, 1e-6, 2.5e-6] {
            let r = set.resampled(w, pitch);
            assert_relative_eq!(r.sum(), 1.0, epsilon = 1e-12);
        }
    }
}

/// Zero defocus reproduces the Airy pattern; small defocus lowers the peak by the Strehl ratio
/// (sin β / β)², β = 2π√3 c / λ, of Zernike defocus.
#[test]
fn wavefront_psf_is_airy_at_zero_defocus_and_follows_strehl() {
    let (w, n, dx) = (550.0, 4.0, 0.2e-6);
    let p0 = wavefront_psf(w, n, 0.0, 128, dx).unwrap();
    let airy = |dy: isize, dxs: isize| {
        let r = ((dy * dy + dxs * dxs) as f64).sqrt() * dx;
        airy_psf(r, w, n) * dx * dx
    };
    // Normalise the Airy samples over the same (truncated) support as the wavefront PSF.
    let (hr, hc) = (p0.half_rows as isize, p0.half_cols as isize);
    let total: f64 = (-hr..=hr)
        .flat_map(|y| (-hc..=hc).map(move |x| (y, x)))
        .map(|(y, x)| airy(y, x))
        .sum();
    let peak = airy(0, 0) / total;
    let mut worst = 0.0f64;
    for dy in -hr..=hr {
        for dxs in -hc..=hc {
            worst = worst.max((p0.at(dy, dxs) - airy(dy, dxs) / total).abs() / peak);
        }
    }
    assert!(worst < 2e-3, "wavefront PSF vs Airy: {worst}");
    // first zero at 1.22 λN
    let prof: Vec<f64> = (0..40).map(|k| p0.at(0, k)).collect();
    let kmin = (1..39)
        .find(|&k| prof[k] < prof[k - 1] && prof[k] <= prof[k + 1])
        .unwrap();
    assert!((kmin as f64 * dx - airy_first_zero_m(w, n)).abs() <= dx);
    let c = 0.05;
    let p1 = wavefront_psf(w, n, c, 128, dx).unwrap();
    let beta = 2.0 * PI * 3f64.sqrt() * c / (w * 1e-3);
    let strehl = (beta.sin() / beta).powi(2);
    let ratio = p1.at(0, 0) / p0.at(0, 0);
    assert!((ratio - strehl).abs() < 0.02, "Strehl {ratio} vs {strehl}");
    // ± defocus give the same in-focus-plane intensity
    let pm = wavefront_psf(w, n, -c, 128, dx).unwrap();
    assert_relative_eq!(pm.at(0, 3), p1.at(0, 3), max_relative = 1e-6);
}

fn test_psf_set() -> PsfSet {
    // 5×5 PSFs: a narrow one at 400 nm, a wide one at 700 nm (unnormalised on purpose).
    let narrow: Vec<Vec<f64>> = (0..5)
        .map(|i| {
            (0..5)
                .map(|j| {
                    if i == 2 && j == 2 {
                        4.0
                    } else if (i - 2i32).abs() + (j - 2i32).abs() == 1 {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let wide = vec![vec![1.0; 5]; 5];
    PsfSet::new(vec![400.0, 700.0], 1.0, vec![narrow, wide]).unwrap()
}

#[test]
fn psf_set_json_interpolation_and_errors() {
    let text = r#"{"wavelength_nm":[500,600],"sample_spacing_um":0.5,
        "psf":[[[0,0,0],[0,2,0],[0,0,0]], [[1,1,1],[1,1,1],[1,1,1]]]}"#;
    let s = PsfSet::from_json_str(text).unwrap();
    assert_eq!((s.rows, s.cols), (3, 3));
    assert_relative_eq!(s.sample_spacing_m, 0.5e-6);
    let m = s.at_wavelength(550.0);
    assert_relative_eq!(m[4], 0.5 + 0.5 / 9.0, epsilon = 1e-12);
    assert_relative_eq!(m[0], 0.5 / 9.0, epsilon = 1e-12);
    assert_eq!(s.at_wavelength(450.0), s.psf[0]);
    assert_eq!(s.at_wavelength(650.0), s.psf[1]);
    // Same pitch: the resampled PSF is the PSF itself (with a zero border).
    let r = s.resampled(600.0, 0.5e-6);
    assert_relative_eq!(r.at(0, 0), 1.0 / 9.0, epsilon = 1e-12);
    assert_relative_eq!(r.at(1, -1), 1.0 / 9.0, epsilon = 1e-12);
    assert_eq!(r.at(2, 0), 0.0);
    // Coarser pitch keeps the centroid at the centre.
    let r = s.resampled(600.0, 1.3e-6);
    let cx: f64 = (-(r.half_cols as isize)..=r.half_cols as isize)
        .flat_map(|x| (-(r.half_rows as isize)..=r.half_rows as isize).map(move |y| (y, x)))
        .map(|(y, x)| r.at(y, x) * x as f64)
        .sum();
    assert!(cx.abs() < 1e-12);
    let bad = [
        (
            r#"{"wavelength_nm":[600,500],"sample_spacing_um":1,"psf":[[[1]],[[1]]]}"#,
            "600",
        ),
        (
            r#"{"wavelength_nm":[500],"sample_spacing_um":0,"psf":[[[1]]]}"#,
            "sample_spacing_um = 0",
        ),
        (
            r#"{"wavelength_nm":[500],"sample_spacing_um":1,"psf":[[[1,-2]]]}"#,
            "-2",
        ),
        (
            r#"{"wavelength_nm":[500],"sample_spacing_um":1,"psf":[[[1,2],[3]]]}"#,
            "row 1",
        ),
        (
            r#"{"wavelength_nm":[500,510],"sample_spacing_um":1,"psf":[[[1]]]}"#,
            "1 PSFs for 2",
        ),
        (
            r#"{"wavelength_nm":[500],"sample_spacing_um":1,"psf":[[[0]]]}"#,
            "sums to 0",
        ),
        (r#"{"wavelength_nm":[500]}"#, "missing field"),
    ];
    for (t, needle) in bad {
        let e = PsfSet::from_json_str(t).unwrap_err().to_string();
        assert!(e.contains(needle), "{e:?} should mention {needle:?}");
    }
    let e = PsfSet::from_json_file(std::path::Path::new("/nonexistent/psf.json")).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/psf.json"), "{e}");
}

#[test]
fn errors_name_the_offending_value() {
    let g = WavelengthGrid::new(vec![550.0]).unwrap();
    let sc = band_scene(4, 4, &g, 1e-6, vec![vec![1.0; 16]]);
    let mut o = plain(Blur::None);
    o.f_number = -2.0;
    let e = form_image(&o, &sc, &g).unwrap_err().to_string();
    assert!(e.contains("f_number") && e.contains("-2"), "{e}");
    let o = plain(Blur::Gaussian { sigma_um: f64::NAN });
    let e = form_image(&o, &sc, &g).unwrap_err().to_string();
    assert!(e.contains("sigma_um") && e.contains("NaN"), "{e}");
    let o = plain(Blur::Wavefront {
        defocus_um: 0.0,
        pupil_samples: 4,
    });
    assert!(form_image(&o, &sc, &g)
        .unwrap_err()
        .to_string()
        .contains("pupil_samples = 4"));
    let mut sc2 = sc.clone();
    sc2.object_distance_m = Some(0.001);
    let e = form_image(&plain(Blur::None), &sc2, &g)
        .unwrap_err()
        .to_string();
    assert!(e.contains("object_distance_m = 0.001"), "{e}");
    let mut sc3 = sc.clone();
    sc3.sample_pitch_m = 0.0;
    let e = form_image(&plain(Blur::None), &sc3, &g)
        .unwrap_err()
        .to_string();
    assert!(e.contains("sample_pitch_m = 0"), "{e}");
}

/// Wavelength-independent blurs act on the linear-model planes: same result as blurring the
/// band cube, and the output keeps the linear model.
#[test]
fn linear_model_planes_blur_like_bands() {
    let g = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let (rows, cols) = (24, 30);
    let s = Spectrum::sampled(vec![400.0, 700.0], vec![1.0, 3.0]).unwrap();
    let plane: Vec<f32> = (0..rows * cols).map(|i| ((i * 13) % 17) as f32).collect();
    let lm = SceneRadiance {
        radiance: SpectralImage::from_single_spectrum(rows, cols, s, plane),
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let mut bands = lm.clone();
    bands.radiance = lm.radiance.to_bands(&g);
    for blur in [
        Blur::Gaussian { sigma_um: 1.5 },
        Blur::Pillbox { width_um: 4.0 },
    ] {
        let mut o = plain(blur);
        o.relative_illumination = RelativeIllumination::Cos4;
        o.focal_length_m = 50e-6;
        o.diffuser = Some(Diffuser { fwhm_um: 1.0 });
        let a = form_image(&o, &lm, &g).unwrap().irradiance;
        assert!(matches!(a.basis, SpectralBasis::Spectra(_)));
        let a = a.to_bands(&g);
        let b = form_image(&o, &bands, &g).unwrap().irradiance;
        for (pa, pb) in a.planes.iter().zip(&b.planes) {
            for (x, y) in pa.iter().zip(pb) {
                assert!((x - y).abs() <= 1e-4 * y.abs().max(1e-3), "{x} vs {y}");
            }
        }
    }
}

/// Diffraction blur of a linear-model scene is computed per band of the requested grid
/// (one plane per cell of the grid); sampled back at the band wavelengths it is the scene's
/// spectrum times the camera-equation factor.
#[test]
fn diffraction_expands_linear_model_to_bands() {
    let g = WavelengthGrid::regular(400.0, 700.0, 100.0).unwrap();
    let s = Spectrum::constant(2.0);
    let sc = SceneRadiance {
        radiance: SpectralImage::from_single_spectrum(8, 8, s, vec![1.0; 64]),
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let e = form_image(&plain(Blur::Diffraction), &sc, &g)
        .unwrap()
        .irradiance;
    assert_eq!(e.planes.len(), g.len());
    let e = e.to_bands(&g);
    assert_relative_eq!(e.planes[3][27] as f64, 2.0 * PI / 64.0, max_relative = 1e-5);
}

/// Performance check (run with `cargo test -p camsim-optics --release -- --ignored`):
/// 1024×1024×31 diffraction should take ≤ 1.5 s on 2 cores.
#[test]
#[ignore]
fn perf_diffraction_1024() {
    let g = WavelengthGrid::default_visible();
    let (rows, cols) = (1024, 1024);
    let planes: Vec<Vec<f32>> = (0..g.len())
        .map(|b| {
            (0..rows * cols)
                .map(|i| ((i * 31 + b) % 97) as f32)
                .collect()
        })
        .collect();
    let sc = band_scene(rows, cols, &g, 1.4e-6, planes);
    let o = OpticsModel::diffraction_limited(4.0, 4e-3);
    let t = std::time::Instant::now();
    let e = form_image(&o, &sc, &g).unwrap();
    let dt = t.elapsed().as_secs_f64();
    eprintln!(
        "1024x1024x31 diffraction: {dt:.3} s ({} threads)",
        rayon::current_num_threads()
    );
    assert_eq!(e.irradiance.planes.len(), 31);
}

/// Issue 17 §4, the uncropped optical image (ISETCam `oiCompute` with `crop = false`): on
/// the ISETCam macbeth case the image grows by ISETCam's `oiPad` ring of `round(n/8)` each
/// side (64×96 → 80×120), its centre is the cropped image (which still matches the oracle),
/// the ring carries the blurred light, and the total power equals the unblurred power
/// (OTF(0) = 1), which the cropped image loses.
#[test]
fn uncropped_optical_image_keeps_isetcams_padded_ring() {
    let case = oracle_case("oi_diffraction_limited_default.json");
    let (_, scene) = read_oracle_npy("data/scene_macbeth_default__photons.npy");
    let (_, expected) = read_oracle_npy("data/oi_diffraction_limited_default__photons.npy");
    let (rows, cols, nb) = (64, 96, 31);
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let planes: Vec<Vec<f32>> = (0..nb)
        .map(|b| (0..rows * cols).map(|p| scene[p * nb + b] as f32).collect())
        .collect();
    let o = &case["inputs"]["optics"];
    let (n, f) = (
        o["f_number"].as_f64().unwrap(),
        o["focal_length_m"].as_f64().unwrap(),
    );
    let d = case["inputs"]["scene_distance_m"].as_f64().unwrap();
    let hfov = case["inputs"]["scene_hfov_deg"]
        .as_f64()
        .unwrap()
        .to_radians();
    let dx = 2.0 * thin_lens_image_distance_m(f, Some(d)) * (hfov / 2.0).tan() / cols as f64;
    let mut sc = band_scene(rows, cols, &grid, dx, planes);
    sc.object_distance_m = Some(d);
    let optics = OpticsModel {
        f_number: n,
        focal_length_m: f,
        transmittance: Spectrum::constant(1.0),
        relative_illumination: RelativeIllumination::IsetCam,
        camera_equation: CameraEquation::IsetCam,
        blur: Blur::Diffraction,
        diffuser: None,
        padding: Padding::Zero,
        effects: Default::default(),
    };
    let un = form_image_uncropped(&optics, &sc, &grid).unwrap();
    let cropped = form_image(&optics, &sc, &grid).unwrap();
    assert_eq!((un.pad_rows, un.pad_cols), (8, 12));
    let e = &un.irradiance.irradiance;
    assert_eq!((e.rows, e.cols), (80, 120));
    let max = expected.iter().cloned().fold(0.0, f64::max);
    let (mut centre, mut oracle) = (0.0f64, 0.0f64);
    for b in 0..nb {
        for i in 0..rows {
            for j in 0..cols {
                let u = e.planes[b][(i + 8) * 120 + j + 12] as f64;
                let c = cropped.irradiance.planes[b][i * cols + j] as f64;
                centre = centre.max((u - c).abs() / max);
                oracle = oracle.max((u - expected[(i * cols + j) * nb + b]).abs() / max);
            }
        }
    }
    assert!(centre < 1e-6, "centre vs cropped: {centre}");
    assert!(oracle < 5e-4, "centre vs ISETCam oracle: {oracle}");
    // Light in the ring next to the scene (middle of the top edge).
    let ring = e.planes[15][7 * 120 + 60] as f64;
    assert!(ring > 1e-3 * max, "ring {ring}");
    // Power: uncropped ≡ unblurred, per band; the cropped image loses the ring's share.
    let none = form_image_uncropped(
        &OpticsModel {
            blur: Blur::None,
            ..optics.clone()
        },
        &sc,
        &grid,
    )
    .unwrap();
    for b in [0, 15, 30] {
        let sum = |p: &Vec<f32>| p.iter().map(|v| *v as f64).sum::<f64>();
        let (s_un, s_none) = (
            sum(&e.planes[b]),
            sum(&none.irradiance.irradiance.planes[b]),
        );
        let s_crop = sum(&cropped.irradiance.planes[b]);
        assert!(
            (s_un / s_none - 1.0).abs() < 1e-4,
            "band {b}: {s_un} vs {s_none}"
        );
        assert!(
            s_crop < s_none * (1.0 - 1e-3),
            "band {b}: cropped loses power"
        );
    }
    // Refused without the ISETCam padding.
    let err = form_image_uncropped(
        &OpticsModel {
            padding: Padding::Replicate,
            ..optics
        },
        &sc,
        &grid,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("Padding::Zero"), "{err}");
}

/// The ring of a uniform scene falls as the blur's edge-spread: along the middle row, the
/// FFT blur on ISETCam's padded grid (even sizes: the plain DFT grid) is the discrete
/// convolution with the periodised Airy PSF sampled at the pitch (Poisson summation; the OTF
/// vanishes beyond the grid's Nyquist frequency), so
/// `E(r, c) = k Σ_{(i, j) ∈ scene} Σ_wraps airy_psf(|(r − i, c − j)| Δ) Δ²`
/// (wraps ±3 periods each way); the rest of the lattice, whose sum converges only as 1/R, is
/// added as its continuum: fill fraction × the Airy energy outside the equal-area circle of
/// the included copies, `2 / (π v)` at `v = π R / (λN)` (the mean of `J₀² + J₁²`).
#[test]
fn uncropped_uniform_scene_edge_follows_the_edge_spread() {
    let (rows, cols, dx, n, w) = (40, 48, 1e-6, 4.0, 550.0);
    let grid = WavelengthGrid::regular(w, w, 10.0).unwrap();
    let sc = band_scene(rows, cols, &grid, dx, vec![vec![1.0; rows * cols]]);
    let optics = OpticsModel {
        padding: Padding::Zero,
        ..plain(Blur::Diffraction)
    };
    let un = form_image_uncropped(&optics, &sc, &grid).unwrap();
    let (pr, pc) = (un.pad_rows, un.pad_cols);
    assert_eq!((pr, pc), (5, 6));
    let e = &un.irradiance.irradiance;
    assert!(e.rows % 2 == 0 && e.cols % 2 == 0);
    let k = camera_equation_factor(n, 0.0);
    let (per_r, per_c) = (e.rows as isize, e.cols as isize);
    let row = (pr + rows / 2) as isize;
    let mut worst = 0.0f64;
    for c in 0..(pc + 4) as isize {
        let mut expect = 0.0;
        for i in pr as isize..(pr + rows) as isize {
            for j in pc as isize..(pc + cols) as isize {
                for wr in -3..=3 {
                    for wc in -3..=3 {
                        let dy = (row - i + wr * per_r) as f64 * dx;
                        let dxx = (c - j + wc * per_c) as f64 * dx;
                        expect += airy_psf(dy.hypot(dxx), w, n) * dx * dx;
                    }
                }
            }
        }
        let fill = (rows * cols) as f64 / (per_r * per_c) as f64;
        let r_eq = ((7 * per_r) as f64 * (7 * per_c) as f64 / PI).sqrt() * dx;
        expect += fill * 2.0 / (PI * PI * r_eq / (w * 1e-9 * n));
        let got = e.planes[0][row as usize * e.cols + c as usize] as f64 / k;
        worst = worst.max((got - expect).abs());
        if c as usize + 1 == pc {
            assert!(got > 0.05, "the ring next to the edge holds light: {got}");
        }
    }
    eprintln!("uniform edge vs Airy sum: max |diff| = {worst:.2e} of the plateau");
    assert!(worst < 1e-4, "{worst}");
}

/// The edge-spread tail of the Airy PSF beyond a line at distance x, computed from Eq. 3 by
/// the edge-spread integral `1/2 − (1/π) ∫₀^{ρc} H(ρ) sin(2πρx)/ρ dρ` (composite Simpson on
/// 2²⁰ intervals), against the asymptote `2 λN / (π³ x)` of `airy_edge_tail_fraction`; and the
/// distance for a given tail inverts it (64.5 λN for 10⁻³).
#[test]
fn airy_edge_tail_asymptote() {
    let (w, n) = (700.0, 4.0);
    let ln = w * 1e-9 * n;
    let exact = |x_ln: f64| -> f64 {
        let m = 1usize << 20;
        let h = 1.0 / m as f64;
        let f = |u: f64| -> f64 {
            let k = 2.0 * PI * x_ln;
            if u == 0.0 {
                k
            } else {
                diffraction_otf(u / ln, w, n) * (k * u).sin() / u
            }
        };
        let mut sum = f(0.0) + f(1.0);
        for i in 1..m {
            sum += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        0.5 - sum * h / 3.0 / PI
    };
    for (x_ln, tol) in [(5.0, 6e-3), (20.0, 1e-3), (64.5, 1e-3), (100.0, 1e-3)] {
        let t = airy_edge_tail_fraction(x_ln * ln, w, n);
        let e = exact(x_ln);
        eprintln!("x = {x_ln} λN: exact tail {e:.6e}, asymptote {t:.6e}");
        assert_relative_eq!(e, t, max_relative = tol);
    }
    // Far from the asymptote near the core (the tail there is not 1/x): x = λN/2.
    assert!((exact(0.5) - airy_edge_tail_fraction(0.5 * ln, w, n)).abs() > 0.01);
    let d = airy_edge_tail_distance_m(1e-3, w, n);
    assert_relative_eq!(d / ln, 2.0 / (PI.powi(3) * 1e-3), max_relative = 1e-12);
    assert!((d / ln - 64.5).abs() < 0.01);
    assert_relative_eq!(airy_edge_tail_fraction(d, w, n), 1e-3, max_relative = 1e-12);
}

/// The ring-averaged envelope `λN/(π³r³)`: (1) the Airy PSF's energy in annuli of 4 λN at
/// 20–100 λN (midpoint rule, 400 steps per λN) against the envelope's closed-form annulus
/// integral `2λN/π² (1/r₀ − 1/r₁)`, within 2 % at 20 λN (measured 1.5 %), the next order of
/// the Bessel asymptote falling as 1/r; (2) its half-plane integral at distance x
/// (numerical, over y and then x' out to 10⁴ x with the analytic remainder) is the edge-spread
/// tail `airy_edge_tail_fraction`.
#[test]
fn airy_tail_envelope_matches_ring_average() {
    let (w, n) = (650.0, 2.8);
    let ln = w * 1e-9 * n;
    for (r0_ln, tol) in [(20.0, 2e-2), (50.0, 8e-3), (100.0, 4e-3)] {
        let (r0, r1) = (r0_ln * ln, (r0_ln + 4.0) * ln);
        let steps = 1600;
        let dr = (r1 - r0) / steps as f64;
        let airy: f64 = (0..steps)
            .map(|k| {
                let r = r0 + (k as f64 + 0.5) * dr;
                airy_psf(r, w, n) * 2.0 * PI * r * dr
            })
            .sum();
        let env = 2.0 * ln / (PI * PI) * (1.0 / r0 - 1.0 / r1);
        // The envelope function itself integrates to the same closed form.
        let env_num: f64 = (0..steps)
            .map(|k| {
                let r = r0 + (k as f64 + 0.5) * dr;
                airy_psf_tail_envelope(r, w, n) * 2.0 * PI * r * dr
            })
            .sum();
        assert_relative_eq!(env_num, env, max_relative = 1e-6);
        eprintln!("annulus at {r0_ln} λN: Airy {airy:.6e}, envelope {env:.6e}");
        assert_relative_eq!(airy, env, max_relative = tol);
    }
    // Half-plane x' > x: ∫ dy env = 2λN/(π³ x'²) exactly (substitution y = x' tan t); check
    // it numerically at one x', then integrate over x'.
    let x = 30.0 * ln;
    let line: f64 = {
        let (m, ymax) = (200_000, 2000.0 * x);
        let dy = ymax / m as f64;
        2.0 * (0..m)
            .map(|k| airy_psf_tail_envelope((x * x + ((k as f64 + 0.5) * dy).powi(2)).sqrt(), w, n))
            .sum::<f64>()
            * dy
    };
    assert_relative_eq!(line, 2.0 * ln / (PI.powi(3) * x * x), max_relative = 2e-3);
    let tail: f64 = {
        let (m, xmax) = (100_000, 1e4 * x);
        // log-spaced x' for the 1/x'² integrand, plus the remainder beyond xmax
        let (a, b) = (x.ln(), xmax.ln());
        let du = (b - a) / m as f64;
        (0..m)
            .map(|k| {
                let xp = (a + (k as f64 + 0.5) * du).exp();
                2.0 * ln / (PI.powi(3) * xp * xp) * xp * du
            })
            .sum::<f64>()
            + 2.0 * ln / (PI.powi(3) * xmax)
    };
    assert_relative_eq!(tail, airy_edge_tail_fraction(x, w, n), max_relative = 1e-6);
}

/// Issue 17 §5: the FFT diffraction blur with replicated edges takes the scene's edges as
/// replicated to infinity, not the FFT's wrap. A slanted dark/light step (one band, 700 nm,
/// f/4, 0.7 µm samples, 60 × 80) against the same scene with its edges replicated 300 samples
/// (75 λN) further by hand and blurred, inner window: every sample within
/// `FAR_TAIL_FRACTION · E_max` per side (two in a corner) plus 2 % of the correction's size
/// (`T(pad) · E_max`), and the border samples well inside that (the wrap of before left
/// `T(20 λN) ≈ 3·10⁻³ · E_max`).
#[test]
fn far_tail_correction_replicates_edges_instead_of_wrapping() {
    let (w, n) = (700.0, 4.0);
    let g = WavelengthGrid::new(vec![w]).unwrap();
    let dx = 0.7e-6;
    let (rows, cols) = (60, 80);
    let (dark, light) = (0.1f32, 1.0f32);
    let step = |i: f64, j: f64| -> f32 {
        let (y, x) = (i - rows as f64 / 2.0, j - cols as f64 / 2.0);
        if x + 0.09 * y > 0.0 {
            light
        } else {
            dark
        }
    };
    let plane: Vec<f32> = (0..rows * cols)
        .map(|k| step((k / cols) as f64 + 0.5, (k % cols) as f64 + 0.5))
        .collect();
    let o = plain(Blur::Diffraction);
    assert_eq!(o.padding, Padding::Replicate);
    let e = form_image(&o, &band_scene(rows, cols, &g, dx, vec![plane.clone()]), &g)
        .unwrap()
        .irradiance;
    let k = 300;
    let (br, bc) = (rows + 2 * k, cols + 2 * k);
    let big: Vec<f32> = (0..br * bc)
        .map(|q| {
            let i = (q / bc).saturating_sub(k).min(rows - 1);
            let j = (q % bc).saturating_sub(k).min(cols - 1);
            plane[i * cols + j]
        })
        .collect();
    let eb = form_image(&o, &band_scene(br, bc, &g, dx, vec![big]), &g)
        .unwrap()
        .irradiance;
    let k0 = (PI / 64.0) as f32; // camera equation factor π/(4N²)
    let e_max = (light * k0) as f64;
    let (mut worst, mut worst_border) = (0f64, 0f64);
    for i in 0..rows {
        for j in 0..cols {
            let d = (e.planes[0][i * cols + j] - eb.planes[0][(i + k) * bc + j + k]).abs() as f64;
            worst = worst.max(d);
            if i == 0 || j == 0 || i == rows - 1 || j == cols - 1 {
                worst_border = worst_border.max(d);
            }
        }
    }
    let pad_m = 20.0 * w * 1e-9 * n;
    let bound = (2.0 * FAR_TAIL_FRACTION + 0.02 * airy_edge_tail_fraction(pad_m, w, n)) * e_max;
    eprintln!(
        "far tail: worst {:.2e}, border {:.2e} of E_max (bound {:.2e})",
        worst / e_max,
        worst_border / e_max,
        bound / e_max
    );
    assert!(worst <= bound, "{worst} > {bound}");
    assert!(worst_border < 0.1 * airy_edge_tail_fraction(pad_m, w, n) * e_max);
}

/// A row window through [`form_image_rows_projected`] (the lateral-colour warp accumulated
/// straight into three channel-like projections, then the Gaussian blur, the diffuser, the
/// defocus block and the veiling glare on those three planes) equals [`form_image_rows`]
/// (every wavelength band's plane through every step) projected afterwards with the same
/// weights of its basis, within f32 rounding (1e-6 of the largest value), with cos⁴
/// relative illumination, a fall-off block, a non-flat transmittance and the whole field's
/// glare sums; on a 25-term scene split into the 33 bands of 380–700 nm.
#[test]
fn projected_rows_equal_the_rows_projected() {
    use crate::effects::{Defocus, Falloff, LateralColor, LateralColorKind};
    let grid = WavelengthGrid::regular(380.0, 700.0, 10.0).unwrap();
    let (full_rows, cols, dx) = (90usize, 70usize, 1.1e-6);
    let terms: Vec<Spectrum> = (0..25)
        .map(|k| {
            let w: Vec<f64> = (0..65).map(|i| 380.0 + 5.0 * i as f64).collect();
            let v = w
                .iter()
                .map(|l| 1.0 + 0.6 * (l / (30.0 + k as f64) + k as f64).sin())
                .collect();
            Spectrum::sampled(w, v).unwrap()
        })
        .collect();
    let planes: Vec<Vec<f32>> = (0..25)
        .map(|k| {
            (0..full_rows * cols)
                .map(|i| {
                    let (r, c) = (i / cols, i % cols);
                    ((((r / 7) * 3 + c / 9 + k) % 5) as f32) * 0.2 + 0.05
                })
                .collect()
        })
        .collect();
    let whole = SceneRadiance {
        radiance: SpectralImage::new(full_rows, cols, SpectralBasis::Spectra(terms), planes)
            .unwrap(),
        sample_pitch_m: dx,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let mut o = OpticsModel {
        blur: Blur::Gaussian { sigma_um: 1.2 },
        diffuser: Some(Diffuser { fwhm_um: 1.5 }),
        transmittance: Spectrum::sampled(vec![380.0, 700.0], vec![0.8, 0.95]).unwrap(),
        ..OpticsModel::diffraction_limited(2.8, 1e-3)
    };
    o.effects.sensor_width_m = cols as f64 * dx;
    o.effects.sensor_height_m = full_rows as f64 * dx;
    o.effects.lateral_color = Some(LateralColor {
        kind: LateralColorKind::Linear,
        displacement_um: 6.0,
    });
    o.effects.falloff = Some(Falloff::Polynomial {
        coefficients: vec![-0.2],
    });
    o.effects.defocus = Some(Defocus::Gaussian { sigma_um: 0.9 });
    o.effects.veiling_glare = Some(0.04);
    let qe: Vec<Spectrum> = [450.0, 540.0, 610.0]
        .iter()
        .map(|&c| {
            let w: Vec<f64> = (0..33).map(|i| 380.0 + 10.0 * i as f64).collect();
            let v = w
                .iter()
                .map(|l: &f64| (-(l - c).powi(2) / (2.0 * 40.0f64.powi(2))).exp())
                .collect();
            Spectrum::sampled(w, v).unwrap()
        })
        .collect();
    let project =
        |b: &SpectralBasis| -> Vec<Vec<f64>> { qe.iter().map(|q| b.term_integrals(q)).collect() };
    let glare = glare_sums(&o, &whole, &grid).unwrap().unwrap();
    let (r0, r1) = (20usize, 58usize);
    let band = SceneRadiance {
        radiance: SpectralImage::new(
            r1 - r0,
            cols,
            whole.radiance.basis.clone(),
            whole
                .radiance
                .planes
                .iter()
                .map(|p| p[r0 * cols..r1 * cols].to_vec())
                .collect(),
        )
        .unwrap(),
        ..whole.clone()
    };
    let window = RowWindow {
        row0: r0,
        full_rows,
    };
    let bands = form_image_rows(&o, &band, &grid, window, Some(&glare)).unwrap();
    assert_eq!(bands.irradiance.planes.len(), 33);
    let w = project(&bands.irradiance.basis);
    let want: Vec<Vec<f32>> = w.iter().map(|wc| bands.irradiance.combine(wc)).collect();
    let got = form_image_rows_projected(&o, &band, &grid, window, Some(&glare), &project).unwrap();
    assert_eq!(got.irradiance.planes.len(), 3);
    assert_eq!(got.sample_pitch_m, dx);
    let scale = want.iter().flatten().fold(0f32, |m, v| m.max(v.abs()));
    let mut moved = 0f32;
    for (c, (g, e)) in got.irradiance.planes.iter().zip(&want).enumerate() {
        for (i, (a, b)) in g.iter().zip(e).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6 * scale,
                "plane {c} sample {i}: {a} vs {b} (largest {scale})"
            );
        }
        let unwarped = {
            let mut q = o.clone();
            q.effects.lateral_color = None;
            let g = glare_sums(&q, &whole, &grid).unwrap().unwrap();
            form_image_rows_projected(&q, &band, &grid, window, Some(&g), &project).unwrap()
        };
        moved = g
            .iter()
            .zip(&unwarped.irradiance.planes[c])
            .fold(moved, |m, (a, b)| m.max((a - b).abs()));
    }
    // (the lateral colour moves the light by far more than the tolerance)
    assert!(
        moved > 1e-3 * scale,
        "lateral colour moved {moved} of {scale}"
    );
}
