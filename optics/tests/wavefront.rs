//! Issue 17 §4, wavefront optics beyond defocus ([`camsim_optics::WavefrontPupil`]): OSA/ANSI
//! Zernike terms (Thibos et al. 2002), the measurement pupil, longitudinal chromatic aberration
//! and polygonal apertures, each against a closed form.
use camsim_core::{SceneRadiance, SpectralBasis, SpectralImage, Spectrum, WavelengthGrid};
use camsim_optics::{
    defocus_um_from_diopters, form_image, human_lca_diopters, polygon_area, zernike_osa,
    zernike_osa_nm, Blur, ChromaticDefocus, OpticsModel, RelativeIllumination, WavefrontPupil,
    ZernikeTerm,
};
use std::f64::consts::PI;

fn pupil(terms: &[(usize, f64)]) -> WavefrontPupil {
    WavefrontPupil {
        zernike: terms
            .iter()
            .map(|&(j, c)| ZernikeTerm { j, rms_um: c })
            .collect(),
        zernike_pupil_diameter_m: None,
        chromatic_defocus: ChromaticDefocus::None,
        blades: None,
        pupil_samples: 128,
    }
}

/// Aperture diameter used by the tests (f = 4 mm at f/4).
const D_M: f64 = 1e-3;

/// Index mapping and explicit polynomials of Thibos et al. 2002 (Table 2).
#[test]
fn osa_index_and_closed_forms() {
    let nm: Vec<(usize, i64)> = (0..15).map(zernike_osa_nm).collect();
    let expect = [
        (0, 0),
        (1, -1),
        (1, 1),
        (2, -2),
        (2, 0),
        (2, 2),
        (3, -3),
        (3, -1),
        (3, 1),
        (3, 3),
        (4, -4),
        (4, -2),
        (4, 0),
        (4, 2),
        (4, 4),
    ];
    assert_eq!(nm, expect);
    for &(r, t) in &[(0.3, 0.4), (0.77, 2.1), (1.0, -1.3)] {
        let close = |a: f64, b: f64| assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        close(zernike_osa(2, r, t), 2.0 * r * t.cos());
        close(zernike_osa(3, r, t), 6f64.sqrt() * r * r * (2.0 * t).sin());
        close(zernike_osa(4, r, t), 3f64.sqrt() * (2.0 * r * r - 1.0));
        close(
            zernike_osa(7, r, t),
            8f64.sqrt() * (3.0 * r.powi(3) - 2.0 * r) * t.sin(),
        );
        close(
            zernike_osa(9, r, t),
            8f64.sqrt() * r.powi(3) * (3.0 * t).cos(),
        );
        close(
            zernike_osa(12, r, t),
            5f64.sqrt() * (6.0 * r.powi(4) - 6.0 * r * r + 1.0),
        );
    }
}

/// The polynomials as sampled on the pupil grid are orthonormal over the aperture:
/// `⟨Z_j Z_k⟩ = δ_jk` (unit RMS), j, k ≤ 14.
#[test]
fn sampled_zernikes_are_orthonormal() {
    let field = pupil(&[]).pupil_field(550.0, D_M, 256).unwrap();
    let np = field.samples;
    let mut pts = Vec::new();
    for a in 0..np {
        for b in 0..np {
            let t = field.data[a * np + b].re;
            if t > 0.0 {
                let (x, y) = (field.coord[b], -field.coord[a]);
                pts.push((t, x.hypot(y), y.atan2(x)));
            }
        }
    }
    let wsum: f64 = pts.iter().map(|p| p.0).sum();
    let mut worst = 0.0f64;
    for j in 0..15 {
        for k in 0..=j {
            let g: f64 = pts
                .iter()
                .map(|&(t, r, th)| t * zernike_osa(j, r, th) * zernike_osa(k, r, th))
                .sum::<f64>()
                / wsum;
            let e = if j == k { 1.0 } else { 0.0 };
            worst = worst.max((g - e).abs());
        }
    }
    eprintln!("max |<Z_j Z_k> - δ_jk| = {worst:.2e}");
    assert!(worst < 3e-3, "{worst}");
}

/// Maréchal: a small RMS wavefront error σ of any single term lowers the on-axis intensity to
/// `exp(−(2πσ/λ)²)`; the drop `1 − S` scales as σ² (tests the unit-RMS normalisation).
#[test]
fn strehl_follows_marechal_for_each_term() {
    let (w, n, dx) = (550.0, 4.0, 0.25e-6);
    let p0 = pupil(&[]).psf(w, n, D_M, dx).unwrap();
    for j in [3, 4, 5, 6, 7, 8, 9, 11, 12, 13] {
        let sigma = 0.02;
        let p = pupil(&[(j, sigma)]).psf(w, n, D_M, dx).unwrap();
        let s = p.at(0, 0) / p0.at(0, 0);
        let m = (-(2.0 * PI * sigma / (w * 1e-3)).powi(2)).exp();
        eprintln!("j={j}: Strehl {s:.4}, Maréchal {m:.4}");
        assert!((s - m).abs() < 0.006, "j={j}: Strehl {s} vs Maréchal {m}");
    }
}

/// Centroid shifts: the PSF centroid is `2N ⟨∇W⟩` over the pupil (the mean transverse ray
/// aberration). Tilt `c Z₂` is a pure shift by `4 N c`: the PSF is the Airy pattern moved by
/// that much (checked point by point). Coma `c Z₈` moves the centroid by `4√2 N c` along +x
/// (`c Z₇`: along +y); its first moment converges only as 1/R with the window radius R (the
/// edge-diffraction tail carries the edge rays, which land 7× farther out than the mean), so
/// the moment over ±12 λN and ±24 λN (Nyquist pitch λN/2, exact for the band-limited intensity
/// up to the window) must approach the closed form from below, within 9 % at 24 λN.
#[test]
fn tilt_and_coma_move_the_centroid_by_the_closed_form() {
    let (w, n) = (550.0, 4.0);
    let ln = w * 1e-9 * n;
    // Tilt: I(x) = Airy(x − 4Nc) · I0(0).
    let c = 0.2;
    let shift_m = 4.0 * n * c * 1e-6;
    let tilt = pupil(&[(2, c)]).pupil_field(w, D_M, 128).unwrap();
    let flat = pupil(&[]).pupil_field(w, D_M, 128).unwrap();
    let i0 = flat.intensity_at(0.0, 0.0, ln);
    let mut worst = 0.0f64;
    for k in 0..40 {
        let (x, y) = (-3e-6 + k as f64 * 0.37e-6, 0.4e-6 * (k % 3) as f64);
        let airy = camsim_optics::airy_psf((x - shift_m).hypot(y), w, n)
            / camsim_optics::airy_psf(0.0, w, n);
        worst = worst.max((tilt.intensity_at(x, y, ln) / i0 - airy).abs());
    }
    assert!(worst < 2e-3, "tilted PSF vs shifted Airy: {worst}");
    // Moments over ±12 λN and ±24 λN in one pass (a 96-sample pupil: its discrete PSF
    // repeats every 96 λN, beyond the window).
    let moments = |j: usize, c: f64| {
        let f = pupil(&[(j, c)]).pupil_field(w, D_M, 96).unwrap();
        let pitch = 0.5 * ln;
        let mut s = [[0.0f64; 3]; 2];
        for r in -48isize..=48 {
            for q in -48isize..=48 {
                let (x, y) = (q as f64 * pitch, r as f64 * pitch);
                let v = f.intensity_at(x, y, ln);
                for (k, sk) in s.iter_mut().enumerate() {
                    if k == 1 || (r.abs() <= 24 && q.abs() <= 24) {
                        sk[0] += v;
                        sk[1] += v * x;
                        sk[2] += v * y;
                    }
                }
            }
        }
        s.map(|m| (m[1] / m[0] * 1e6, m[2] / m[0] * 1e6))
    };
    let k = 4.0 * 2f64.sqrt() * n;
    for (j, c) in [(8, -0.15)] {
        let expect = k * c;
        let [m15, m30] = moments(j, c);
        eprintln!(
            "j={j} c={c}: centroid {:.4} (±12 λN), {:.4} (±24 λN) µm, closed form {expect:.4}",
            m15.0, m30.0
        );
        let (e15, e30) = (expect - m15.0, expect - m30.0);
        assert!(
            e30.abs() < e15.abs(),
            "j={j}: the moment must converge: {e15} {e30}"
        );
        assert!(
            e30 * expect.signum() >= 0.0 && e30.abs() < 0.09 * expect.abs(),
            "j={j}: {} vs {expect}",
            m30.0
        );
        assert!(m30.1.abs() < 1e-6, "j={j}: no shift across");
    }
    // The sampled PSF (window ±(10 λN + ray fan)): Z₇ > 0 moves the centroid up (towards
    // row 0), Z₈ > 0 to the right, by most of the closed form.
    let dx = 0.25e-6;
    for (j, c) in [(7, 0.1), (8, 0.1)] {
        let p = pupil(&[(j, c)]).psf(w, n, D_M, dx).unwrap();
        let (hr, hc) = (p.half_rows as isize, p.half_cols as isize);
        let (mut sx, mut sy) = (0.0, 0.0);
        for r in -hr..=hr {
            for q in -hc..=hc {
                sx += p.at(r, q) * q as f64 * dx * 1e6;
                sy -= p.at(r, q) * r as f64 * dx * 1e6;
            }
        }
        let (along, across) = if j == 7 { (sy, sx) } else { (sx, sy) };
        eprintln!("sampled PSF j={j}: centroid {along:.4} µm");
        assert!(
            along > 0.85 * k * c && along < k * c && across.abs() < 1e-6,
            "j={j}: {along}"
        );
    }
}

/// Symmetry of each term's PSF: `|m|`-fold rotation (any rotation for m = 0), mirror
/// `y → −y` for cos terms (m > 0) and `x → −x` for sin terms (m < 0); coma is not
/// centro-symmetric and trefoil not 6-fold (the checks can fail).
#[test]
fn psf_symmetry_per_term() {
    let ln = 550e-9 * 4.0;
    for j in [3, 4, 5, 6, 7, 8, 9, 12] {
        let (_, m) = zernike_osa_nm(j);
        let f = pupil(&[(j, 0.15)]).pupil_field(550.0, D_M, 128).unwrap();
        let i_at = |r: f64, t: f64| f.intensity_at(r * t.cos(), r * t.sin(), ln);
        let mut worst = 0.0f64;
        for r in [1.5 * ln, 3.0 * ln] {
            let angles: Vec<f64> = (0..16).map(|k| 0.1 + k as f64 * PI / 8.0).collect();
            let ring: Vec<f64> = angles.iter().map(|&t| i_at(r, t)).collect();
            let max = ring.iter().cloned().fold(0.0, f64::max);
            let rot = if m == 0 {
                0.7
            } else {
                2.0 * PI / m.unsigned_abs() as f64
            };
            for (&t, &v) in angles.iter().zip(&ring) {
                worst = worst.max((i_at(r, t + rot) - v).abs() / max);
                // mirror: cos terms about the x axis (θ → −θ), sin terms about the y axis
                // (θ → π − θ)
                let mirrored = if m >= 0 { -t } else { PI - t };
                worst = worst.max((i_at(r, mirrored) - v).abs() / max);
            }
        }
        eprintln!("j={j} (m={m}): worst symmetry residual {worst:.2e}");
        assert!(worst < 1e-2, "j={j}: {worst}");
    }
    // Negative controls.
    let coma = pupil(&[(8, 0.15)]).pupil_field(550.0, D_M, 128).unwrap();
    let (a, b) = (
        coma.intensity_at(2.0 * ln, 0.0, ln),
        coma.intensity_at(-2.0 * ln, 0.0, ln),
    );
    assert!(
        (a - b).abs() / a.max(b) > 0.1,
        "coma is not centro-symmetric: {a} {b}"
    );
    let tre = pupil(&[(9, 0.15)]).pupil_field(550.0, D_M, 128).unwrap();
    let (a, b) = (
        tre.intensity_at(2.0 * ln, 0.0, ln),
        tre.intensity_at(2.0 * ln * (PI / 3.0).cos(), 2.0 * ln * (PI / 3.0).sin(), ln),
    );
    assert!(
        (a - b).abs() / a.max(b) > 0.1,
        "trefoil is 3-fold, not 6-fold: {a} {b}"
    );
}

/// Stopping a pure defocus down: coefficients measured over `D_z = D / s` act on the
/// aperture as the defocus `c s²` over `D` (`Z₄(sρ)` = `s² Z₄(ρ)` + piston).
#[test]
fn measurement_pupil_scales_defocus_by_s_squared() {
    let (w, n, dx, c, s) = (550.0, 4.0, 0.25e-6, 0.3, 0.6);
    let mut wide = pupil(&[(4, c)]);
    wide.zernike_pupil_diameter_m = Some(D_M / s);
    let a = wide.psf(w, n, D_M, dx).unwrap();
    let b = pupil(&[(4, c * s * s)]).psf(w, n, D_M, dx).unwrap();
    assert_eq!((a.half_rows, a.half_cols), (b.half_rows, b.half_cols));
    let peak = b.data.iter().cloned().fold(0.0, f64::max);
    let worst = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs() / peak)
        .fold(0.0, f64::max);
    assert!(worst < 1e-6, "{worst}");
    // A measurement pupil smaller than the aperture is refused, naming the key.
    let mut small = pupil(&[(4, c)]);
    small.zernike_pupil_diameter_m = Some(0.5 * D_M);
    let e = small.psf(w, n, D_M, dx).unwrap_err().to_string();
    assert!(e.contains("zernike_pupil_diameter_mm"), "{e}");
}

/// Longitudinal chromatic aberration. The dioptre → µm conversion against a projection of
/// the paraxial sag `D r² ρ² / 2` onto the sampled Z₄; the human eye's 400–700 nm LCA is
/// ≈ 2.1 D (Thibos et al. 1992, Fig. 4; Bedford & Wyszecki 1957); zero at the reference; a table
/// gives the same PSF as the equal fixed defocus.
#[test]
fn longitudinal_chromatic_aberration() {
    let (diopters, d_mm) = (1.5, 3.0);
    let f = pupil(&[]).pupil_field(550.0, D_M, 256).unwrap();
    let np = f.samples;
    let (mut num, mut den) = (0.0, 0.0);
    for a in 0..np {
        for b in 0..np {
            let t = f.data[a * np + b].re;
            if t > 0.0 {
                let (x, y) = (f.coord[b], -f.coord[a]);
                let (rho, th) = (x.hypot(y), y.atan2(x));
                // sag in µm: D [1/m] · r² [mm²] / 2 = µm
                let w_um = diopters * (0.5 * d_mm * rho).powi(2) / 2.0;
                num += t * w_um * zernike_osa(4, rho, th);
                den += t;
            }
        }
    }
    let projected = num / den;
    let closed = defocus_um_from_diopters(diopters, d_mm);
    assert!(
        (projected - closed).abs() < 2e-3 * closed,
        "{projected} vs {closed}"
    );
    let lca = human_lca_diopters(580.0, 400.0) - human_lca_diopters(580.0, 700.0);
    assert!(lca.abs() > 1.9 && lca.abs() < 2.3, "400–700 nm LCA {lca} D");
    assert_eq!(human_lca_diopters(580.0, 580.0), 0.0);
    // Human LCA: in focus at the reference, defocused elsewhere by the converted amount.
    let (n, dx) = (4.0, 0.25e-6);
    let mut eye = pupil(&[]);
    eye.chromatic_defocus = ChromaticDefocus::HumanEye {
        reference_nm: 580.0,
    };
    eye.zernike_pupil_diameter_m = Some(D_M);
    let same = |a: &camsim_optics::SampledPsf, b: &camsim_optics::SampledPsf| {
        a.data.len() == b.data.len()
            && a.data
                .iter()
                .zip(&b.data)
                .all(|(x, y)| (x - y).abs() < 1e-9)
    };
    let at_ref = eye.psf(580.0, n, D_M, dx).unwrap();
    assert!(same(&at_ref, &pupil(&[]).psf(580.0, n, D_M, dx).unwrap()));
    let c450 = defocus_um_from_diopters(-human_lca_diopters(580.0, 450.0), 1.0);
    let blue = eye.psf(450.0, n, D_M, dx).unwrap();
    assert!(same(
        &blue,
        &pupil(&[(4, c450)]).psf(450.0, n, D_M, dx).unwrap()
    ));
    // Table: linear between entries.
    let mut tab = pupil(&[]);
    tab.chromatic_defocus = ChromaticDefocus::Table {
        wavelength_nm: vec![450.0, 650.0],
        defocus_um: vec![0.2, -0.2],
    };
    let p = tab.psf(500.0, n, D_M, dx).unwrap();
    assert!(same(
        &p,
        &pupil(&[(4, 0.1)]).psf(500.0, n, D_M, dx).unwrap()
    ));
}

/// Polygonal apertures: open area `(N/2) R² sin(2π/N)`; PSF symmetry 2N-fold for odd N and
/// N-fold for even N (and not finer: the diffraction spikes); the area-normalised OTF(0), the
/// Nyquist-sampled PSF integral over `(2λN)² / Δξ⁴ · ∫|P|²` (Parseval), is 1 up to the energy
/// outside the 24 λN window.
#[test]
fn polygonal_apertures() {
    let ln = 550e-9 * 4.0;
    for blades in [5u32, 6, 7, 9] {
        let mut p = pupil(&[]);
        p.blades = Some(blades);
        let f = p.pupil_field(550.0, D_M, 256).unwrap();
        let (area, closed) = (f.area(), polygon_area(blades, 1.0));
        assert!(
            (area - closed).abs() < 1e-3 * closed,
            "N={blades}: {area} vs {closed}"
        );
    }
    assert!((pupil(&[]).pupil_field(550.0, D_M, 256).unwrap().area() - PI).abs() < 1e-3 * PI);
    for blades in [5u32, 6] {
        let mut p = pupil(&[]);
        p.blades = Some(blades);
        let f = p.pupil_field(550.0, D_M, 128).unwrap();
        let fold = if blades % 2 == 1 { 2 * blades } else { blades } as f64;
        let i_at = |r: f64, t: f64| f.intensity_at(r * t.cos(), r * t.sin(), ln);
        let (mut worst, mut finer) = (0.0f64, 0.0f64);
        for r in [3.0 * ln, 5.0 * ln] {
            let angles: Vec<f64> = (0..24).map(|k| 0.05 + k as f64 * 2.0 * PI / 24.0).collect();
            let ring: Vec<f64> = angles.iter().map(|&t| i_at(r, t)).collect();
            let max = ring.iter().cloned().fold(0.0, f64::max);
            for (&t, &v) in angles.iter().zip(&ring) {
                worst = worst.max((i_at(r, t + 2.0 * PI / fold) - v).abs() / max);
                finer = finer.max((i_at(r, t + PI / fold) - v).abs() / max);
            }
        }
        eprintln!("N={blades}: {fold}-fold residual {worst:.2e}, half-step {finer:.2e}");
        assert!(worst < 3e-2, "N={blades}: {worst}");
        assert!(
            finer > 0.2,
            "N={blades}: spikes must break the finer symmetry, {finer}"
        );
        // Parseval: ∫ PSF = (2λN)² / Δξ⁴ · Σ|P|² Δξ².
        let pitch = 0.5 * ln;
        let h = 48isize;
        let mut total = 0.0;
        for r in -h..=h {
            for q in -h..=h {
                total += f.intensity_at(q as f64 * pitch, r as f64 * pitch, ln);
            }
        }
        let dxi = 2.0 / f.samples as f64;
        let otf0 = total * pitch * pitch * dxi.powi(4) / ((2.0 * ln).powi(2) * f.power());
        eprintln!("N={blades}: area-normalised OTF(0) = {otf0:.4}");
        assert!(otf0 > 0.98 && otf0 <= 1.0 + 1e-6, "N={blades}: {otf0}");
    }
}

/// Through `form_image`: a uniform scene stays uniform with the general pupil (coma,
/// spherical, human LCA, hexagonal aperture) and keeps its mean (PSFs sum to 1).
#[test]
fn uniform_scene_through_an_aberrated_hexagonal_pupil() {
    let grid = WavelengthGrid::regular(450.0, 650.0, 50.0).unwrap();
    let (rows, cols) = (24, 28);
    let planes: Vec<Vec<f32>> = (0..grid.len()).map(|_| vec![1.0; rows * cols]).collect();
    let scene = SceneRadiance {
        radiance: SpectralImage::new(rows, cols, SpectralBasis::Bands(grid.clone()), planes)
            .unwrap(),
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let mut wp = pupil(&[(8, 0.1), (12, 0.05)]);
    wp.blades = Some(6);
    wp.chromatic_defocus = ChromaticDefocus::HumanEye {
        reference_nm: 550.0,
    };
    let optics = OpticsModel {
        relative_illumination: RelativeIllumination::None,
        blur: Blur::Pupil(wp),
        transmittance: Spectrum::constant(1.0),
        ..OpticsModel::diffraction_limited(4.0, 4e-3)
    };
    let out = form_image(&optics, &scene, &grid).unwrap();
    let k = std::f64::consts::PI / (4.0 * 16.0);
    for p in &out.irradiance.planes {
        for v in p {
            assert!((*v as f64 / k - 1.0).abs() < 1e-4, "{v} vs {k}");
        }
    }
}
