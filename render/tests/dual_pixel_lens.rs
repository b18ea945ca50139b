//! Real-lens dual-pixel PSFs ([`camsim_render::depth_path::LensDualPixelDefocus`]) against the
//! thin-lens dual-pixel geometry (`camsim_optics::dual_pixel`).
use camsim_render::depth_path::{Kernel, LensDualPixelDefocus};

/// (centroid x, centroid y, RMS radius about the centroid), in samples from the kernel centre.
fn moments(k: &Kernel) -> (f64, f64, f64) {
    let n = 2 * k.radius + 1;
    let c = k.radius as f64;
    let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (i, v) in k.values.iter().enumerate() {
        let v = *v as f64;
        s += v;
        sx += v * ((i % n) as f64 - c);
        sy += v * ((i / n) as f64 - c);
    }
    let (mx, my) = (sx / s, sy / s);
    let m2: f64 = k
        .values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let (x, y) = ((i % n) as f64 - c - mx, (i / n) as f64 - c - my);
            *v as f64 * (x * x + y * y)
        })
        .sum();
    (mx, my, (m2 / s).sqrt())
}

/// The full PSF (mean of the two halves, which partition its rays) as a kernel.
fn full(l: &Kernel, r: &Kernel) -> Kernel {
    let rad = l.radius.max(r.radius);
    let n = 2 * rad + 1;
    let mut values = vec![0f32; n * n];
    for k in [l, r] {
        let m = 2 * k.radius + 1;
        let off = rad - k.radius;
        for (i, v) in k.values.iter().enumerate() {
            values[(i / m + off) * n + i % m + off] += 0.5 * v;
        }
    }
    Kernel {
        radius: rad,
        values,
    }
}

/// The double Gauss 50 mm stopped to f/8 (spherical aberration small against the defocus),
/// paraxially focused at 2 m: for objects at 1 m (nearer) and 5 m (farther), the centroid
/// separation of the right and left half-pupil PSFs is the thin-lens closed form
/// `d = 2·4R/(3π)` (as `camsim_optics::dual_pixel_disparity_m`) with R the blur radius of the
/// traced full PSF (R = √2 × its RMS radius, a uniform disc's), positive for the nearer object
/// and negative for the farther one (the halves swap through focus). Tolerance 4 % + 0.15
/// samples: the residual spherical aberration and pupil distortion of the stopped lens make
/// the blur not quite a uniform disc (a few %). In focus the disparity is bounded by the spot
/// (|d| ≤ R; a nearest-bin histogram used to round it to 0), the centroids lie on the axis in
/// y, and the halves are mirror images.
#[test]
fn lens_half_pupil_disparity_matches_thin_lens_geometry() {
    let mut lens = super::test_lenses::double_gauss();
    lens.aperture = camsim_lens::prescription::Aperture::FNumber(8.0);
    let fo = lens.first_order(lens.primary_nm).unwrap();
    let z_ep_mm = fo.entrance_pupil_z_mm;
    let focus = lens
        .focus(&camsim_lens::FocusSpec {
            focus_distance_mm: Some(2000.0 - z_ep_mm),
            method: camsim_lens::FocusMethod {
                criterion: camsim_lens::FocusCriterion::Paraxial,
                ..Default::default()
            },
        })
        .unwrap();
    let pitch_mm = 0.008;
    let invs = [1.0, 0.5, 0.2];
    let dp = LensDualPixelDefocus::new(&focus, pitch_mm, &[lens.primary_nm], 64, &invs).unwrap();
    for inv in invs {
        let (l, r) = dp.kernels(0, inv);
        let (lx, ly, _) = moments(&l);
        let (rx, ry, _) = moments(&r);
        let (_, _, rms) = moments(&full(&l, &r));
        let radius = std::f64::consts::SQRT_2 * rms;
        let d = rx - lx;
        let sign = if inv > 0.5 {
            1.0
        } else if inv < 0.5 {
            -1.0
        } else {
            0.0
        };
        // the half-disc centroids lie 4R/(3π) either side of the centre (Pappus), restated
        // here independently of camsim_optics::dual_pixel_disparity_m
        let expected = sign * 8.0 * radius / (3.0 * std::f64::consts::PI);
        eprintln!("1/z {inv}: R {radius:.3} px, disparity {d:.3} px, thin lens {expected:.3} px, y {ly:.3} {ry:.3}");
        assert!(ly.abs() < 0.1 && ry.abs() < 0.1);
        if sign == 0.0 {
            // At the paraxial focus the residual spherical aberration leaves the halves a
            // disparity of the order of the spot (−0.16 px for R 0.22 px): the split of a
            // distribution into two halves moves their means apart by at most twice its x
            // standard deviation (between-group ≤ total variance), R for a round spot.
            assert!(radius < 1.0, "in focus R {radius}");
            assert!(
                d.abs() <= radius,
                "1/z {inv}: in-focus disparity {d} beyond R {radius}"
            );
        } else {
            assert!(
                (d - expected).abs() < 0.04 * expected.abs() + 0.15,
                "1/z {inv}: disparity {d} vs {expected}"
            );
            assert!(radius > 4.0, "defocused R {radius}");
            assert_eq!(d.signum(), sign);
        }
    }
}
