//! Pixel optics (issue 21, "pixel vignetting against the etendue calculation"): the angular
//! response of [`camsim_sensor::pixel_optics`] against
//! * the étendue ratio on the axis (focal-plane pixel, the regimes where spot and photodiode
//!   nest; the ratio bounds it in between),
//! * the circular-segment closed form of the shifted spot off the axis (own photodiode and the
//!   neighbour's: optical crosstalk), for several f-numbers, CRAs and microlens shifts,
//! * full CRA compensation restoring the on-axis response (also defocused, `h ≠ f`),
//! * a Monte Carlo ray trace of the cone through the microlens and the stack (chi-square over
//!   the 9 photodiodes + lost, z-test on the own photodiode, fixed seeds),
//! * the gather that applies the map to a rate against a direct scatter of each pixel's light.
use camsim_sensor::pixel_optics::{
    apply_pixel_optics, disk_rect_overlap_area, etendue_ratio, ChiefRay, Cone, Microlens,
    MicrolensShift, PixelOptics,
};
use camsim_sensor::ElectronRate;
use rand::RngExt;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;

/// A focal-plane pixel (h = f).
fn focal_plane(w_um: f64) -> Microlens {
    Microlens {
        pitch_um: 1.4,
        diameter_um: 1.4,
        focal_length_um: 3.0,
        stack_height_um: 3.0,
        photodiode_width_um: w_um,
        refractive_index: 1.5,
    }
}

fn on_axis_cone(f_number: f64) -> Cone {
    Cone {
        chief_tangent: [0.0, 0.0],
        radius_tangent: 0.5 / f_number,
    }
}

#[test]
fn on_axis_acceptance_is_the_etendue_ratio() {
    let ml = focal_plane(0.7);
    let (mut inside, mut covering, mut between) = (0, 0, 0);
    for n in [1.2, 1.4, 2.0, 2.8, 3.5, 4.0, 5.6, 8.0, 16.0] {
        let cone = on_axis_cone(n);
        let got = ml.response(&cone, [0.0, 0.0]).accepted();
        let ratio = etendue_ratio(&ml, cone.radius_tangent);
        let spot_radius = ml.stack_height_um * cone.radius_tangent / ml.refractive_index;
        let hw = 0.5 * ml.photodiode_width_um;
        if spot_radius <= hw || spot_radius >= hw * 2f64.sqrt() {
            // The spot and the photodiode nest: acceptance = min(1, G_pd / G_cone).
            assert!(
                (got - ratio).abs() < 1e-12,
                "N = {n}: {got} vs étendue {ratio}"
            );
            if spot_radius <= hw {
                inside += 1;
                assert!((got - 1.0).abs() < 1e-12);
            } else {
                covering += 1;
                assert!(ratio < 1.0);
            }
        } else {
            // Partial overlap: étendue conservation bounds the acceptance.
            between += 1;
            assert!(
                got < ratio - 1e-3,
                "N = {n}: {got} not below étendue {ratio}"
            );
        }
    }
    assert!(
        inside >= 2 && covering >= 2 && between >= 1,
        "{inside} {covering} {between}"
    );
    // The microlens fill (D/p)² scales it.
    let small = Microlens {
        diameter_um: 1.1,
        ..focal_plane(0.7)
    };
    let cone = on_axis_cone(2.0);
    let got = small.response(&cone, [0.0, 0.0]).accepted();
    assert!((got - etendue_ratio(&small, cone.radius_tangent)).abs() < 1e-12);
    assert!(
        (got / ml.response(&cone, [0.0, 0.0]).accepted() - (1.1f64 / 1.4).powi(2)).abs() < 1e-12
    );
}

/// Area of the disk of radius r beyond the line x = d (from its centre): the circular segment
/// `r² acos(d/r) − d √(r² − d²)`, all of it for d ≤ −r, none for d ≥ r.
fn segment(r: f64, d: f64) -> f64 {
    let d = d.clamp(-r, r);
    r * r * (d / r).acos() - d * (r * r - d * d).sqrt()
}

/// Fraction of a disk of radius r centred at x = c within the band a ≤ x ≤ b.
fn band(r: f64, c: f64, a: f64, b: f64) -> f64 {
    (segment(r, a - c) - segment(r, b - c)) / (PI * r * r)
}

#[test]
fn off_axis_spot_follows_the_segment_closed_form() {
    // w = 1.0 µm, p = 1.4 µm: the spot (radius f ρ / n < w/2) moves along x only and crosses
    // the photodiode's right edge, then the gap, then the right neighbour's photodiode.
    let ml = focal_plane(1.0);
    let (p, hw, h, n_idx) = (1.4, 0.5, 3.0, 1.5);
    let mut checked = 0;
    let mut saw_crosstalk = false;
    for f_number in [2.2, 2.8, 4.0, 8.0] {
        for cra_deg in [0.0f64, 5.0, 10.0, 20.0, 30.0, 40.0] {
            for shift in [
                MicrolensShift::None,
                MicrolensShift::Cra { fraction: 0.5 },
                MicrolensShift::Linear { um_per_mm: 0.2 },
            ] {
                let field_mm = 2.0;
                let chief = ChiefRay::Table {
                    field_mm: vec![0.0, 4.0],
                    cra_deg: vec![0.0, 2.0 * cra_deg],
                    f_number,
                };
                let po = PixelOptics::new(ml, chief, shift).unwrap();
                let t = cra_deg.to_radians().tan();
                let m = match shift {
                    MicrolensShift::None => 0.0,
                    MicrolensShift::Cra { fraction } => -fraction * h * t / n_idx,
                    MicrolensShift::Linear { um_per_mm } => -um_per_mm * field_mm,
                };
                let c = m + h * t / n_idx;
                let r = h * (0.5 / f_number) / n_idx;
                assert!(r < hw);
                let got = po.response_at(field_mm, 0.0).to_pixel;
                let own = band(r, c, -hw, hw);
                let right = band(r, c, p - hw, p + hw);
                let left = band(r, c, -p - hw, -p + hw);
                let tag = format!("N {f_number}, CRA {cra_deg}°, {shift:?}");
                assert!(
                    (got[1][1] - own).abs() < 1e-12,
                    "{tag}: own {} vs {own}",
                    got[1][1]
                );
                assert!(
                    (got[1][2] - right).abs() < 1e-12,
                    "{tag}: right {} vs {right}",
                    got[1][2]
                );
                assert!((got[1][0] - left).abs() < 1e-12, "{tag}: left");
                for (i, row) in got.iter().enumerate() {
                    if i != 1 {
                        assert!(
                            row.iter().all(|v| *v == 0.0),
                            "{tag}: rows above/below get light"
                        );
                    }
                }
                saw_crosstalk |= right > 0.05;
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 72);
    assert!(saw_crosstalk);
}

#[test]
fn cra_compensating_shift_restores_the_on_axis_response() {
    for (h, w) in [(3.0, 0.7), (2.2, 0.9), (3.8, 1.1)] {
        let ml = Microlens {
            stack_height_um: h,
            ..focal_plane(w)
        };
        for f_number in [1.8, 2.8, 5.6] {
            let exit = ChiefRay::ExitPupil {
                distance_mm: 6.0,
                radius_mm: 6.0 / (2.0 * f_number),
            };
            let axis = PixelOptics::new(ml, exit.clone(), MicrolensShift::None)
                .unwrap()
                .response_at(0.0, 0.0)
                .to_pixel;
            let comp =
                PixelOptics::new(ml, exit.clone(), MicrolensShift::Cra { fraction: 1.0 }).unwrap();
            let bare = PixelOptics::new(ml, exit, MicrolensShift::None).unwrap();
            for (x, y) in [(1.5, 0.0), (-2.0, 1.0), (2.5, -2.5)] {
                let got = comp.response_at(x, y).to_pixel;
                for i in 0..3 {
                    for j in 0..3 {
                        assert!(
                            (got[i][j] - axis[i][j]).abs() < 1e-12,
                            "h {h}, N {f_number}, ({x}, {y}): [{i}][{j}] {} vs {}",
                            got[i][j],
                            axis[i][j]
                        );
                    }
                }
                // Without the shift the same pixel is vignetted.
                assert!(bare.response_at(x, y).accepted() < axis[1][1] - 1e-3);
            }
        }
    }
}

/// One Monte Carlo estimate: rays uniform over one pixel area and the cone's disk, traced
/// through the microlens and the stack step by step; bins 0..9 = photodiodes of the 3 × 3
/// neighbourhood (row-major), 9 = lost.
fn trace_rays(ml: &Microlens, cone: &Cone, shift: [f64; 2], n: usize, seed: u64) -> [u64; 10] {
    let mut rng = camsim_core::rng::stream(seed, &[21]);
    let mut bins = [0u64; 10];
    let (p, d) = (ml.pitch_um, ml.diameter_um);
    for _ in 0..n {
        // Entry point (relative to the pixel's centre) on the p × p cell of the microlens
        // array around this pixel's (shifted) microlens: the shifted array still tiles the
        // plane, so each microlens receives the light of one pixel area.
        let e = [
            shift[0] + (rng.random::<f64>() - 0.5) * p,
            shift[1] + (rng.random::<f64>() - 0.5) * p,
        ];
        // Direction: uniform in the cone's disk (rejection from its bounding square).
        let t = loop {
            let u = [
                2.0 * rng.random::<f64>() - 1.0,
                2.0 * rng.random::<f64>() - 1.0,
            ];
            if u[0] * u[0] + u[1] * u[1] <= 1.0 {
                break [
                    cone.chief_tangent[0] + cone.radius_tangent * u[0],
                    cone.chief_tangent[1] + cone.radius_tangent * u[1],
                ];
            }
        };
        // Outside the (shifted) microlens aperture: lost.
        let x = [e[0] - shift[0], e[1] - shift[1]];
        if x[0].abs() > 0.5 * d || x[1].abs() > 0.5 * d {
            bins[9] += 1;
            continue;
        }
        // Refraction into the stack, the thin microlens, propagation to the photodiodes.
        let mut s = [0.0; 2];
        for k in 0..2 {
            let t_stack = t[k] / ml.refractive_index;
            let t_lens = t_stack - x[k] / ml.focal_length_um;
            s[k] = e[k] + ml.stack_height_um * t_lens;
        }
        let hw = 0.5 * ml.photodiode_width_um;
        let mut bin = 9;
        for iy in 0..3 {
            for ix in 0..3 {
                let (cx, cy) = ((ix as f64 - 1.0) * p, (iy as f64 - 1.0) * p);
                if (s[0] - cx).abs() < hw && (s[1] - cy).abs() < hw {
                    bin = iy * 3 + ix;
                }
            }
        }
        bins[bin] += 1;
    }
    bins
}

#[test]
fn monte_carlo_ray_trace_agrees_with_the_response() {
    // Defocused stacks (h ≠ f: the aperture quadrature), a microlens smaller than the pixel,
    // off-axis cones in x and y, with and without shifts.
    let cases = [
        (2.4, 3.0, 1.2, 0.8, [0.50, 0.30], 0.20, [0.0, 0.0]),
        (3.6, 3.0, 1.4, 0.9, [0.45, -0.25], 0.12, [-0.3, 0.1]),
        (2.0, 2.6, 1.3, 0.7, [-0.60, 0.50], 0.25, [0.2, -0.2]),
        (3.0, 3.0, 1.4, 1.0, [0.40, 0.0], 0.20, [0.0, 0.0]),
    ];
    let n_rays = 400_000;
    for (case, (h, f, d, w, tc, rho, shift)) in cases.iter().enumerate() {
        let ml = Microlens {
            pitch_um: 1.4,
            diameter_um: *d,
            focal_length_um: *f,
            stack_height_um: *h,
            photodiode_width_um: *w,
            refractive_index: 1.5,
        };
        let cone = Cone {
            chief_tangent: *tc,
            radius_tangent: *rho,
        };
        let resp = ml.response(&cone, *shift).to_pixel;
        let mut prob: Vec<f64> = resp.iter().flatten().copied().collect();
        prob.push(1.0 - prob.iter().sum::<f64>());
        let bins = trace_rays(&ml, &cone, *shift, n_rays, 7 + case as u64);
        // z-test on the own photodiode.
        let p_own = prob[4];
        let z = (bins[4] as f64 - n_rays as f64 * p_own)
            / (n_rays as f64 * p_own * (1.0 - p_own)).sqrt();
        assert!(
            z.abs() < 4.0,
            "case {case}: own z = {z:.2} ({} of {n_rays}, p = {p_own})",
            bins[4]
        );
        // Chi-square over the bins with expected counts ≥ 5 (the rest pooled).
        let (mut chi2, mut df, mut pool_o, mut pool_e) = (0.0, 0usize, 0.0, 0.0);
        for (o, p) in bins.iter().zip(&prob) {
            let e = p * n_rays as f64;
            if e >= 5.0 {
                chi2 += (*o as f64 - e).powi(2) / e;
                df += 1;
            } else {
                pool_o += *o as f64;
                pool_e += e;
            }
        }
        if pool_e >= 5.0 {
            chi2 += (pool_o - pool_e).powi(2) / pool_e;
            df += 1;
        } else {
            assert!(
                pool_o <= 20.0,
                "case {case}: {pool_o} rays where the model expects {pool_e}"
            );
        }
        let crit = ChiSquared::new((df - 1) as f64)
            .unwrap()
            .inverse_cdf(1.0 - 1e-4);
        assert!(
            chi2 < crit,
            "case {case}: chi² {chi2:.1} ≥ {crit:.1} (df {}), bins {bins:?}, p {prob:?}",
            df - 1
        );
        assert!(df >= 3, "case {case}: too few populated bins ({df})");
    }
}

#[test]
fn response_map_interpolates_the_exact_response() {
    let ml = Microlens {
        stack_height_um: 2.6,
        ..focal_plane(0.9)
    };
    let po = PixelOptics::new(
        ml,
        ChiefRay::ExitPupil {
            distance_mm: 5.0,
            radius_mm: 1.2,
        },
        MicrolensShift::Linear { um_per_mm: 0.1 },
    )
    .unwrap();
    let (rows, cols) = (300, 401);
    let map = po.response_map(rows, cols);
    assert!(map.node_rows < rows && map.node_cols < cols);
    let p_mm = 1.4e-3;
    let mut worst = 0f64;
    for (r, c) in [
        (0, 0),
        (17, 333),
        (150, 200),
        (299, 400),
        (211, 5),
        (3, 398),
    ] {
        let (x, y) = (
            (c as f64 - (cols as f64 - 1.0) / 2.0) * p_mm,
            (r as f64 - (rows as f64 - 1.0) / 2.0) * p_mm,
        );
        let exact = po.response_at(x, y).to_pixel;
        let got = map.at(r, c);
        for i in 0..3 {
            for j in 0..3 {
                worst = worst.max((got[i][j] as f64 - exact[i][j]).abs());
            }
        }
    }
    assert!(worst < 2e-4, "bilinear map vs exact: {worst}");
}

#[test]
fn applying_the_map_equals_scattering_each_pixels_light() {
    let ml = focal_plane(0.8);
    let po = PixelOptics::new(
        ml,
        ChiefRay::Table {
            field_mm: vec![0.0, 0.02, 0.05],
            cra_deg: vec![0.0, 25.0, 35.0],
            f_number: 2.0,
        },
        MicrolensShift::None,
    )
    .unwrap();
    let (rows, cols) = (23, 31);
    let map = po.response_map(rows, cols);
    let mut rng = camsim_core::rng::stream(5, &[]);
    let src: Vec<f32> = (0..rows * cols)
        .map(|_| 100.0 + 900.0 * rng.random::<f32>())
        .collect();
    let mut rate = ElectronRate {
        rows,
        cols,
        electrons_per_s: src.clone(),
    };
    apply_pixel_optics(&map, &mut rate);
    // Scatter: each pixel sends its light to its 3 × 3 neighbourhood.
    let mut want = vec![0f64; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let k = map.at(r, c);
            for (iy, row) in k.iter().enumerate() {
                for (ix, v) in row.iter().enumerate() {
                    let (tr, tc) = (r as isize + iy as isize - 1, c as isize + ix as isize - 1);
                    if tr >= 0 && tc >= 0 && (tr as usize) < rows && (tc as usize) < cols {
                        want[tr as usize * cols + tc as usize] +=
                            src[r * cols + c] as f64 * *v as f64;
                    }
                }
            }
        }
    }
    let mut moved = 0.0;
    for (g, w) in rate.electrons_per_s.iter().zip(&want) {
        assert!(
            (*g as f64 - w).abs() <= 1e-5 * w.abs().max(1.0),
            "{g} vs {w}"
        );
        moved += w;
    }
    assert!(moved > 0.0);
    // Neighbour crosstalk is present at this CRA (the test exercises the off-centre terms).
    assert!(map.at(0, 0).iter().flatten().sum::<f32>() - map.at(0, 0)[1][1] > 0.01);
}

#[test]
fn overlap_area_matches_a_chord_length_integral() {
    // The closed-form disk ∩ rectangle area against the midpoint rule (10⁶ points) of the
    // chord length |[y0, y1] ∩ [−√(r² − x²), √(r² − x²)]| over [x0, x1] (error ~1e-9).
    let mut rng = camsim_core::rng::stream(3, &[]);
    for _ in 0..8 {
        let r = 0.3 + rng.random::<f64>();
        let x0 = -1.5 + 2.0 * rng.random::<f64>();
        let y0 = -1.5 + 2.0 * rng.random::<f64>();
        let (x1, y1) = (
            x0 + 0.2 + rng.random::<f64>(),
            y0 + 0.2 + rng.random::<f64>(),
        );
        let n = 1_000_000;
        let dx = (x1 - x0) / n as f64;
        let numeric: f64 = (0..n)
            .map(|i| {
                let x = x0 + (i as f64 + 0.5) * dx;
                let s = (r * r - x * x).max(0.0).sqrt();
                (s.min(y1) - (-s).max(y0)).max(0.0)
            })
            .sum::<f64>()
            * dx;
        let exact = disk_rect_overlap_area(r, x0, x1, y0, y1);
        assert!(
            (numeric - exact).abs() < 1e-7,
            "r {r}, [{x0}, {x1}] × [{y0}, {y1}]: {numeric} vs {exact}"
        );
    }
}
