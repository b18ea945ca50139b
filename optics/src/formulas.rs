//! Closed-form optics formulas (Farrell, Catrysse & Wandell 2012, §2.B). Units are in the
//! argument names; wavelengths in nm.
use std::f64::consts::PI;

/// Thin-lens image distance (m) for an object at `object_distance_m` (None = infinity):
/// `1 / (1/f − 1/d)`. Requires `d > f` (checked by the caller).
pub fn thin_lens_image_distance_m(focal_length_m: f64, object_distance_m: Option<f64>) -> f64 {
    match object_distance_m {
        None => focal_length_m,
        Some(d) => 1.0 / (1.0 / focal_length_m - 1.0 / d),
    }
}

/// Lateral magnification `m = −image_distance / d` of a thin lens (0 for an object at
/// infinity).
pub fn magnification(focal_length_m: f64, object_distance_m: Option<f64>) -> f64 {
    match object_distance_m {
        None => 0.0,
        Some(d) => -thin_lens_image_distance_m(focal_length_m, Some(d)) / d,
    }
}

/// Camera equation factor (paper Eq. 1): `E = L · π / (4 N² (1 + |m|)²)` (times T(λ) and the
/// relative illumination). Exactly `π / (4N²)` for an object at infinity (m = 0).
pub fn camera_equation_factor(f_number: f64, magnification: f64) -> f64 {
    let k = 1.0 + magnification.abs();
    PI / (4.0 * f_number * f_number * k * k)
}

/// ISETCam's camera equation factor (`oiCalculateIrradiance`):
/// `π / (1 + 4 N² (1 + |m|)²)`. Offered only for compatibility with ISETCam.
pub fn camera_equation_factor_isetcam(f_number: f64, magnification: f64) -> f64 {
    let k = 1.0 + magnification.abs();
    PI / (1.0 + 4.0 * f_number * f_number * k * k)
}

/// Plain cos⁴ relative illumination at distance `r_m` from the optical axis: `cos⁴θ` with
/// `tan θ = r / f`, i.e. `(f² / (f² + r²))²`.
pub fn relative_illumination_cos4(r_m: f64, focal_length_m: f64) -> f64 {
    relative_illumination_cos4_r2(r_m * r_m, focal_length_m)
}

/// [`relative_illumination_cos4`] from the squared distance `r2_m2 = x² + y²` (no square root,
/// for per-pixel loops): `(f² / (f² + r²))²`.
#[inline]
pub fn relative_illumination_cos4_r2(r2_m2: f64, focal_length_m: f64) -> f64 {
    let f2 = focal_length_m * focal_length_m;
    cos4_from_f2(f2, f2 + r2_m2)
}

/// [`relative_illumination_cos4`] along one row of pixels at squared height `y2_m2`: the
/// returned function maps a pixel's squared column offset x² to `(f² / ((f² + y²) + x²))²`,
/// with `f² + y²` formed once per row (one addition per pixel in the caller's loop, which
/// then vectorises).
#[inline]
pub fn relative_illumination_cos4_row(y2_m2: f64, focal_length_m: f64) -> impl Fn(f64) -> f64 {
    let f2 = focal_length_m * focal_length_m;
    let f2_y2 = f2 + y2_m2;
    move |x2_m2: f64| cos4_from_f2(f2, f2_y2 + x2_m2)
}

/// cos⁴θ = (cos²θ)² with cos²θ = f² / (f² + r²).
#[inline(always)]
fn cos4_from_f2(f2: f64, f2_plus_r2: f64) -> f64 {
    let c2 = f2 / f2_plus_r2;
    c2 * c2
}

/// ISETCam's `'cos4th'` off-axis falloff (`cos4th.m`), which is *not* plain cos⁴: with
/// `d = image_distance_m` (ISETCam passes the focal length), `tan φ = r/d` for
/// `r² = x² + y²`, `sin θ = 1 / (1 + 4 (N (1 − m))²)` (sic, as in ISETCam),
/// factor `= (π/2)(1 − (1 − tan²θ + tan²φ) / √(tan⁴φ + 2 tan²φ (1 − tan²θ) + 1/cos⁴θ)) /
/// (π sin²θ)`. When `d > 10 × image_diagonal_m` ISETCam uses `(d / √(d² + r²))⁴` instead.
/// Equals 1 on the axis.
pub fn relative_illumination_isetcam(
    x_m: f64,
    y_m: f64,
    image_distance_m: f64,
    f_number: f64,
    magnification: f64,
    image_diagonal_m: f64,
) -> f64 {
    let d = image_distance_m;
    let r2 = x_m * x_m + y_m * y_m;
    if d > 10.0 * image_diagonal_m {
        let c2 = d * d / (d * d + r2);
        return c2 * c2;
    }
    let tan_phi2 = r2 / (d * d);
    let t = f_number * (1.0 - magnification);
    let sin_t = 1.0 / (1.0 + 4.0 * t * t);
    let sin2 = sin_t * sin_t;
    let cos2 = 1.0 - sin2;
    let tan_t2 = sin2 / cos2;
    let num = 1.0 - tan_t2 + tan_phi2;
    let den = (tan_phi2 * tan_phi2 + 2.0 * tan_phi2 * (1.0 - tan_t2) + 1.0 / (cos2 * cos2)).sqrt();
    (PI / 2.0) * (1.0 - num / den) / (PI * sin2)
}

/// Diffraction-limited OTF of an aberration-free circular pupil under incoherent light
/// (paper Eq. 3): `H(ρ) = (2/π)(acos u − u √(1 − u²))`, `u = ρ/ρc`, `ρc = 1/(λN)`; 0 for
/// `u ≥ 1`. `freq_cycles_per_m` is the radial spatial frequency in the image plane.
pub fn diffraction_otf(freq_cycles_per_m: f64, wavelength_nm: f64, f_number: f64) -> f64 {
    otf_of_u(freq_cycles_per_m.abs() * wavelength_nm * 1e-9 * f_number)
}

/// `H(u)` of [`diffraction_otf`] for the normalised frequency `u = ρ λ N ≥ 0`.
#[inline]
pub(crate) fn otf_of_u(u: f64) -> f64 {
    if u >= 1.0 {
        0.0
    } else {
        (2.0 / PI) * (u.acos() - u * (1.0 - u * u).sqrt())
    }
}

/// Radius of the first dark ring of the Airy pattern in the image plane: `1.22 λ N` (m).
pub fn airy_first_zero_m(wavelength_nm: f64, f_number: f64) -> f64 {
    1.22 * wavelength_nm * 1e-9 * f_number
}

/// Angular radius of the first dark ring for a pupil of diameter `pupil_diameter_m`:
/// `1.22 λ / D` (radians).
pub fn airy_first_zero_rad(wavelength_nm: f64, pupil_diameter_m: f64) -> f64 {
    1.22 * wavelength_nm * 1e-9 / pupil_diameter_m
}

/// Fraction of a diffraction-limited (Airy) PSF's energy beyond a straight line at distance
/// `distance_m` from its centre, i.e. the edge-spread tail `1 − ESF(x)`, by its large-`x`
/// asymptote `T(x) = 2 λN / (π³ x)`.
///
/// Source: Eq. 3 has the slope `dH/du = −4/π` at `u = 0`, so near zero frequency the line
/// spread function's spectrum is `1 − (4 λN / π) abs(ρ)`; the Fourier pair
/// `abs(ρ) ↔ −1 / (2π² x²)` (Bracewell, *The Fourier Transform and its Applications*, table of
/// generalised transforms) gives the LSF tail `2 λN / (π³ x²)`, whose integral beyond `x` is
/// `T(x)`; equivalently the half-plane integral of [`airy_psf_tail_envelope`]. The exact tail
/// `1/2 − (1/π) ∫₀^{1/λN} H(ρ) sin(2πρx)/ρ dρ` is within 0.6 % of `T` from `x = 5 λN` and
/// within 0.1 % beyond `20 λN` (test `airy_edge_tail_asymptote`).
pub fn airy_edge_tail_fraction(distance_m: f64, wavelength_nm: f64, f_number: f64) -> f64 {
    2.0 * wavelength_nm * 1e-9 * f_number / (PI.powi(3) * distance_m.abs())
}

/// Distance (m) beyond which the Airy PSF's edge-spread tail [`airy_edge_tail_fraction`] is
/// `tail_fraction`: `x = 2 λN / (π³ T)` (`≈ 64.5 λN` for `T = 10⁻³`).
pub fn airy_edge_tail_distance_m(tail_fraction: f64, wavelength_nm: f64, f_number: f64) -> f64 {
    2.0 * wavelength_nm * 1e-9 * f_number / (PI.powi(3) * tail_fraction)
}

/// The Airy PSF [`airy_psf`] averaged over its rings far from the centre (units 1/m²):
/// `⟨I(r)⟩ = λN / (π³ r³)`, valid for `r ≫ λN`.
///
/// Source: the Bessel asymptote `J₁(v) ≈ √(2/(πv)) cos(v − 3π/4)` (Abramowitz & Stegun 9.2.1)
/// in `I = π/(4λ²N²) [2J₁(v)/v]²`, `v = πr/(λN)`, with `⟨cos²⟩ = 1/2`. Its integral over a
/// half-plane at distance `x` is [`airy_edge_tail_fraction`] (test
/// `airy_tail_envelope_matches_ring_average`).
pub fn airy_psf_tail_envelope(r_m: f64, wavelength_nm: f64, f_number: f64) -> f64 {
    wavelength_nm * 1e-9 * f_number / (PI.powi(3) * r_m.abs().powi(3))
}

/// The Airy PSF (Fourier transform of Eq. 3) at distance `r_m` from its centre, normalised so
/// that its integral over the image plane is 1 (units 1/m²):
/// `I(r) = π / (4 λ² N²) · [2 J₁(v) / v]²`, `v = π r / (λ N)`. First zero at `v = 3.8317`,
/// i.e. `r = 1.2197 λN`.
pub fn airy_psf(r_m: f64, wavelength_nm: f64, f_number: f64) -> f64 {
    let ln = wavelength_nm * 1e-9 * f_number;
    let v = PI * r_m.abs() / ln;
    let a = if v < 1e-8 {
        1.0
    } else {
        2.0 * bessel_j1(v) / v
    };
    PI / (4.0 * ln * ln) * a * a
}

/// Bessel function J₁ (rational/asymptotic approximations, absolute error ≈ 1e-8).
pub fn bessel_j1(x: f64) -> f64 {
    let ax = x.abs();
    if ax < 8.0 {
        let y = x * x;
        let a1 = x
            * (72362614232.0
                + y * (-7895059235.0
                    + y * (242396853.1
                        + y * (-2972611.439 + y * (15704.48260 + y * (-30.16036606))))));
        let a2 = 144725228442.0
            + y * (2300535178.0
                + y * (18583304.74 + y * (99447.43394 + y * (376.9991397 + y * 1.0))));
        a1 / a2
    } else {
        let z = 8.0 / ax;
        let y = z * z;
        let xx = ax - 2.356194491;
        let a1 = 1.0
            + y * (0.183105e-2
                + y * (-0.3516396496e-4 + y * (0.2457520174e-5 + y * (-0.240337019e-6))));
        let a2 = 0.04687499995
            + y * (-0.2002690873e-3
                + y * (0.8449199096e-5 + y * (-0.88228987e-6 + y * 0.105787412e-6)));
        let ans = (std::f64::consts::FRAC_2_PI / ax).sqrt() * (xx.cos() * a1 - z * xx.sin() * a2);
        if x < 0.0 {
            -ans
        } else {
            ans
        }
    }
}

/// Gaussian σ from its full width at half maximum: `σ = FWHM / (2 √(2 ln 2))`.
pub fn sigma_from_fwhm(fwhm: f64) -> f64 {
    fwhm / (2.0 * (2.0 * std::f64::consts::LN_2).sqrt())
}
