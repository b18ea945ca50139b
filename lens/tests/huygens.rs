//! Huygens PSF: the Airy pattern of an aberration-free lens, and agreement with the FFT PSF
//! where both are well sampled.
use camsim_lens::huygens::HuygensWindow;
use camsim_lens::prescription::{ApertureFile, MaterialFile, PrescriptionFile, SurfaceFile};
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};

const WL: f64 = 587.5618;

/// J₁(x) from Bessel's integral J₁(x) = (1/π)∫₀^π cos(τ − x sin τ) dτ (trapezoid rule, which
/// converges geometrically for this periodic integrand).
fn bessel_j1(x: f64) -> f64 {
    let m = 400;
    let h = std::f64::consts::PI / m as f64;
    let mut s = 0.5 * ((0.0f64).cos() + (std::f64::consts::PI - 0.0).cos());
    for k in 1..m {
        let t = k as f64 * h;
        s += (t - x * t.sin()).cos();
    }
    s * h / std::f64::consts::PI
}

/// Airy intensity relative to its peak: [2 J₁(v)/v]², v = π r/(λ N_w).
fn airy(r_mm: f64, lambda_mm: f64, nw: f64) -> f64 {
    let v = std::f64::consts::PI * r_mm / (lambda_mm * nw);
    if v.abs() < 1e-12 {
        1.0
    } else {
        (2.0 * bessel_j1(v) / v).powi(2)
    }
}

/// Cartesian oval (ellipsoid k = −1/n²): stigmatic for an object at infinity, image in glass.
fn perfect_lens(epd_mm: f64) -> LensPrescription {
    let (n, r) = (1.5, 50.0);
    let f = PrescriptionFile {
        name: "oval".into(),
        units: "mm".into(),
        surfaces: vec![SurfaceFile {
            radius_mm: Some(r),
            thickness_mm: n * r / (n - 1.0),
            material: MaterialFile::Model { nd: n, vd: 0.0 },
            semi_diameter_mm: None,
            conic: -1.0 / (n * n),
            aspheric_coeffs: vec![],
            odd_aspheric_coeffs: vec![],
            stop: true,
        }],
        object_distance_mm: None,
        fields_deg: vec![0.0],
        wavelengths_nm: vec![WL],
        primary_nm: None,
        aperture: ApertureFile::Epd { epd_mm },
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    LensPrescription::from_file_form(&f, &GlassCatalog::bundled()).unwrap()
}

#[test]
fn bessel_j1_matches_tabulated_values() {
    // Abramowitz & Stegun table 9.1 and the first zero j₁,₁ = 3.831706.
    assert!((bessel_j1(1.0) - 0.440_050_585_7).abs() < 1e-9);
    assert!((bessel_j1(2.0) - 0.576_724_807_8).abs() < 1e-9);
    assert!((bessel_j1(5.0) - (-0.327_579_137_6)).abs() < 1e-9);
    assert!(bessel_j1(3.831_705_97).abs() < 1e-8);
}

#[test]
fn perfect_lens_huygens_psf_is_the_airy_pattern() {
    let l = perfect_lens(8.0);
    let fo = l.first_order(WL).unwrap();
    let nw = fo.working_f_number;
    let lam = WL * 1e-6;
    // Window ±1.6 Airy radii at λN_w/8 pitch; a 48-sample pupil repeats every 47 λN_w.
    let n = 31;
    let pitch = lam * nw / 8.0;
    let win = HuygensWindow {
        n,
        sample_mm: pitch,
        offset_mm: [0.0, 0.0],
    };
    let h = l.huygens_psf(0.0, WL, 48, &win, Clipping::None).unwrap();
    assert!(
        (h.strehl_ratio - 1.0).abs() < 1e-6,
        "Strehl {}",
        h.strehl_ratio
    );
    let c = n / 2;
    let peak = h.psf.values[c * n + c];
    assert!(h.psf.values.iter().all(|&v| v <= peak * (1.0 + 1e-12)));
    let mut worst: f64 = 0.0;
    for iy in 0..n {
        for ix in 0..n {
            let r = pitch * ((ix as f64 - c as f64).hypot(iy as f64 - c as f64));
            let want = airy(r, lam, nw);
            worst = worst.max((h.psf.values[iy * n + ix] / peak - want).abs());
        }
    }
    // Discrete 48² pupil (a polygonal disc: ~1/n relative rim error) and the obliquity factor.
    assert!(worst < 5e-3, "max |I/I0 − Airy| = {worst}");
    // The first dark ring at 1.2197 λN_w: a 3-sample cut along x has its minimum there.
    let r0 = 1.219_67 * lam * nw;
    let dark = HuygensWindow {
        n: 3,
        sample_mm: 0.01 * r0,
        offset_mm: [r0, 0.0],
    };
    let d = l.huygens_psf(0.0, WL, 48, &dark, Clipping::None).unwrap();
    let row = &d.psf.values[3..6];
    assert!(
        row[1] < row[0] && row[1] < row[2],
        "no minimum at the Airy zero: {row:?}"
    );
}

#[test]
fn off_axis_huygens_psf_of_a_concentric_lens_is_the_projected_airy_pattern() {
    // A refracting sphere (R = 20 mm, n = 1.5) with the stop at its centre of curvature C is
    // the same system for every field, rotated about C: the focus of field θ lies on the chief
    // ray at ρ = R/(n − 1) from C. Seen along the chief ray the flat stop is an ellipse
    // (tangential semi-axis × cos θ), so in the plane normal to the chief ray the PSF is the
    // Airy pattern stretched by 1/cos θ tangentially; on the image plane (normal to the axis,
    // placed through the focus) the projection stretches it by another 1/cos θ:
    // I(x, y)/I₀ = [2J₁(v)/v]², v = π √(x² + (y cos²θ)²)/(λ N_w), N_w the on-axis value.
    let (n, r) = (1.5, 20.0);
    let rho = r / (n - 1.0);
    let mk = |z_img: f64| {
        let f = PrescriptionFile {
            name: "concentric".into(),
            units: "mm".into(),
            surfaces: vec![
                SurfaceFile {
                    radius_mm: Some(r),
                    thickness_mm: r,
                    material: MaterialFile::Model { nd: n, vd: 0.0 },
                    semi_diameter_mm: None,
                    conic: 0.0,
                    aspheric_coeffs: vec![],
                    odd_aspheric_coeffs: vec![],
                    stop: false,
                },
                SurfaceFile {
                    radius_mm: None,
                    thickness_mm: z_img,
                    material: MaterialFile::Model { nd: n, vd: 0.0 },
                    semi_diameter_mm: None,
                    conic: 0.0,
                    aspheric_coeffs: vec![],
                    odd_aspheric_coeffs: vec![],
                    stop: true,
                },
            ],
            object_distance_mm: None,
            fields_deg: vec![0.0],
            wavelengths_nm: vec![WL],
            primary_nm: None,
            aperture: ApertureFile::Epd { epd_mm: 1.0 },
            provenance: None,
            coordinate_breaks: Vec::new(),
        };
        LensPrescription::from_file_form(&f, &GlassCatalog::bundled()).unwrap()
    };
    let lam = WL * 1e-6;
    let nw = mk(rho).first_order(WL).unwrap().working_f_number;
    for th in [0.0f64, 20.0, 35.0] {
        let ct = th.to_radians().cos();
        let l = mk(rho * ct);
        let nn = 31;
        let pitch = lam * nw / 5.0;
        let win = HuygensWindow {
            n: nn,
            sample_mm: pitch,
            offset_mm: [0.0, 0.0],
        };
        let h = l.huygens_psf(th, WL, 96, &win, Clipping::None).unwrap();
        // The chief ray meets the focus on the sphere about C.
        assert!((h.chief_mm[1] - rho * th.to_radians().sin()).abs() < 1e-9);
        assert!(h.strehl_ratio > 0.999, "{th}°: Strehl {}", h.strehl_ratio);
        let c = (nn / 2) as f64;
        let peak = h.psf.values[nn / 2 * nn + nn / 2];
        let mut worst: f64 = 0.0;
        for iy in 0..nn {
            for ix in 0..nn {
                let (x, y) = ((ix as f64 - c) * pitch, (iy as f64 - c) * pitch);
                let want = airy(x.hypot(y * ct * ct), lam, nw);
                worst = worst.max((h.psf.values[iy * nn + ix] / peak - want).abs());
            }
        }
        // Discretisation of the 96² pupil (polygonal rim) ≈ 7e-4.
        assert!(
            worst < 1.5e-3,
            "{th}°: max |I/I0 − projected Airy| = {worst}"
        );
    }
}

#[test]
fn huygens_and_fft_psfs_agree_on_axis_where_both_are_well_sampled() {
    // On the axis the FFT's paraxial pupil → image-angle scaling is exact for a lens obeying
    // the sine condition, so the two methods must agree on the same 64² pupil samples, with
    // strong aberration (f/2 at paraxial focus, Strehl 0.01) and near the diffraction limit
    // (f/8). (Off the axis the FFT PSF misses the foreshortening of the exit pupil seen from
    // the field point, which the concentric-lens test above checks for the Huygens PSF.)
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses/double_gauss_50mm_f2.json");
    let l = LensPrescription::from_json_file(p, &GlassCatalog::bundled()).unwrap();
    let mut l = l.focused(l.primary_nm).unwrap();
    let (pupil_n, pad) = (64, 4);
    for epd in [25.0, 6.25] {
        l.aperture = camsim_lens::prescription::Aperture::EntrancePupilDiameter(epd);
        let wo = l.wave_optics(0.0, WL, pupil_n, pad, &[]).unwrap();
        let m = wo.psf.n;
        let pitch = wo.psf.sample_mm;
        let n = 41;
        let win = HuygensWindow {
            n,
            sample_mm: pitch,
            offset_mm: [0.0, 0.0],
        };
        let h = l
            .huygens_psf(0.0, WL, pupil_n, &win, Clipping::None)
            .unwrap();
        // The FFT PSF is point-reflected about the chief-ray point (field_model docs): the
        // image-plane offset (x, y) is FFT sample (m/2 − x/pitch, m/2 − y/pitch).
        let c = (n / 2) as isize;
        let cm = (m / 2) as isize;
        let mut fft: Vec<f64> = (0..n * n)
            .map(|k| {
                let (ix, iy) = ((k % n) as isize - c, (k / n) as isize - c);
                wo.psf.values[((cm - iy) as usize) * m + (cm - ix) as usize]
            })
            .collect();
        let s: f64 = fft.iter().sum();
        fft.iter_mut().for_each(|v| *v /= s);
        let peak = fft.iter().cloned().fold(0.0, f64::max);
        let max_diff = h
            .psf
            .values
            .iter()
            .zip(&fft)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            max_diff < 2e-3 * peak,
            "EPD {epd}: max diff {max_diff} vs peak {peak}"
        );
    }
}
