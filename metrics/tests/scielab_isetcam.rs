//! Issue 17 §4: S-CIELAB with ISETCam's parameters ([`ScielabOptions::isetcam`]) against
//! ISETCam's documented procedure (metrics/scielab: `scParams`, `scPrepareFilters`,
//! `scGaussianParameters` 'distribution', `gauss`, `sumGauss`, `scApplyFilters`,
//! `ClipXYZImage`), written out here independently of the library's separable code: the
//! channel filter is `g(x, y) = Σ_i w_i G_i(x) G_i(y) / Σ_i w_i` on the odd support
//! `S = filterSize` (one degree), `G_i(x) = exp(−ln 2 · x² / h_i²)` normalised over
//! `x ∈ (1:S) − round(S/2)` with `h_i` the half-width at half maximum (degrees × samples per
//! degree); the image is filtered by circular convolution (images smaller than S are first
//! mirror-padded to S) after cutting an even side by one; XYZ is clipped to [0, white].
use camsim_core::colorimetry::{xyz_to_lab, Xyz};
use camsim_metrics::scielab::{filter_opponent_plane, ScielabBoundary};
use camsim_metrics::{delta_e_2000, scielab_with_options, ScielabOptions};

/// ISETCam 'distribution' parameters: (hwhm in degrees, weight) per channel.
const DISTRIBUTION: [&[(f64, f64)]; 3] = [
    &[(0.05, 1.00327), (0.225, 0.114416), (7.0, -0.117686)],
    &[(0.0685, 0.616725), (0.826, 0.383275)],
    &[(0.0920, 0.567885), (0.6451, 0.432115)],
];

/// The documented 2-D filter of channel `ch` at `spd` samples per degree, support `s` (odd):
/// row-major `s × s`, centre at (s/2, s/2).
fn documented_filter(ch: usize, spd: f64, s: usize) -> Vec<f64> {
    let xs: Vec<f64> = (1..=s)
        .map(|i| i as f64 - (s as f64 / 2.0).round())
        .collect();
    let mut g = vec![0.0; s * s];
    for &(hwhm_deg, w) in DISTRIBUTION[ch] {
        let h = hwhm_deg * spd;
        let one: Vec<f64> = xs
            .iter()
            .map(|x| (-(2f64.ln()) * x * x / (h * h)).exp())
            .collect();
        let sum1: f64 = one.iter().sum();
        for i in 0..s {
            for j in 0..s {
                g[i * s + j] += w * one[i] * one[j] / (sum1 * sum1);
            }
        }
    }
    let total: f64 = g.iter().sum();
    g.iter_mut().for_each(|v| *v /= total);
    g
}

/// ISETCam's `scApplyFilters` on one plane (odd sides), directly in 2-D: mirror-pad a side
/// shorter than S to S, circular convolution over the (padded) grid, cut back.
fn documented_apply(plane: &[f64], rows: usize, cols: usize, g: &[f64], s: usize) -> Vec<f64> {
    let mirror = |i: isize, n: usize| {
        let p = 2 * n as isize;
        let m = i.rem_euclid(p);
        if m < n as isize {
            m as usize
        } else {
            (p - 1 - m) as usize
        }
    };
    let (pr, pc) = (rows.max(s), cols.max(s));
    let (or, oc) = ((pr - rows) / 2, (pc - cols) / 2);
    let ext = |i: usize, j: usize| {
        plane
            [mirror(i as isize - or as isize, rows) * cols + mirror(j as isize - oc as isize, cols)]
    };
    let r = (s / 2) as isize;
    let mut out = vec![0.0; rows * cols];
    for i in 0..rows {
        for j in 0..cols {
            let mut acc = 0.0;
            for u in 0..s {
                for v in 0..s {
                    let y = (i as isize + or as isize - (u as isize - r)).rem_euclid(pr as isize);
                    let x = (j as isize + oc as isize - (v as isize - r)).rem_euclid(pc as isize);
                    acc += g[u * s + v] * ext(y as usize, x as usize);
                }
            }
            out[i * cols + j] = acc;
        }
    }
    out
}

/// The library's filtering (separable, per Gaussian) equals the documented 2-D procedure, for
/// an image larger than the filter (circular wrap of an impulse near the border) and one
/// smaller (mirror padding), in every channel; and differs from camsim's mirror filtering.
#[test]
fn isetcam_filters_follow_the_documented_procedure() {
    let spd = 23.0;
    let opts = ScielabOptions::isetcam(spd);
    let s = opts.fixed_support_samples.unwrap();
    assert_eq!(s, 23);
    for (rows, cols) in [(31usize, 33usize), (9, 15)] {
        let plane: Vec<f64> = (0..rows * cols)
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                if (r, c) == (1, 2) {
                    50.0
                } else {
                    ((r * 7 + c * 3) % 11) as f64
                }
            })
            .collect();
        for ch in 0..3 {
            let got = filter_opponent_plane(&plane, rows, cols, ch, &opts);
            let want = documented_apply(&plane, rows, cols, &documented_filter(ch, spd, s), s);
            let worst = got
                .iter()
                .zip(&want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-9, "{rows}×{cols} channel {ch}: {worst}");
            if rows > s {
                let mirror_opts = ScielabOptions {
                    boundary: ScielabBoundary::Mirror,
                    ..opts.clone()
                };
                let m = filter_opponent_plane(&plane, rows, cols, ch, &mirror_opts);
                let d = m
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(d > 1e-3, "channel {ch}: the circular wrap must show ({d})");
            }
        }
    }
}

const D65_10: Xyz = Xyz {
    x: 94.811,
    y: 100.0,
    z: 107.304,
};

/// Even sides are cut by one (ISETCam keeps the filter centred), a uniform difference gives the
/// plain CIEDE2000 (the filters sum to 1 and the 10° matrix inverts exactly), and values above
/// the white are clipped before filtering.
#[test]
fn isetcam_scielab_crops_keeps_uniform_and_clips() {
    let (rows, cols) = (32, 40);
    let opts = ScielabOptions::isetcam(24.0);
    assert_eq!(opts.fixed_support_samples, Some(23));
    let pa = Xyz {
        x: 30.0,
        y: 32.0,
        z: 25.0,
    };
    let pb = Xyz {
        x: 33.0,
        y: 31.0,
        z: 29.0,
    };
    let a = vec![pa; rows * cols];
    let b = vec![pb; rows * cols];
    let r = scielab_with_options(&a, &b, rows, cols, D65_10, &opts).unwrap();
    assert_eq!((r.rows, r.cols), (31, 39));
    assert_eq!(r.delta_e_map.len(), 31 * 39);
    let plain = delta_e_2000(xyz_to_lab(pa, D65_10), xyz_to_lab(pb, D65_10));
    for v in &r.delta_e_map {
        assert!((v - plain).abs() < 1e-9 * plain, "{v} vs {plain}");
    }
    // Above the white: ISETCam clips, camsim's default does not.
    let hi_a = vec![
        Xyz {
            x: 120.0,
            y: 130.0,
            z: 140.0
        };
        rows * cols
    ];
    let hi_b = vec![
        Xyz {
            x: 150.0,
            y: 110.0,
            z: 200.0
        };
        rows * cols
    ];
    let clipped = scielab_with_options(&hi_a, &hi_b, rows, cols, D65_10, &opts).unwrap();
    assert!(clipped.mean_delta_e < 1e-9, "{}", clipped.mean_delta_e);
    let plain_opts = ScielabOptions::new(24.0);
    let unclipped = scielab_with_options(&hi_a, &hi_b, rows, cols, D65_10, &plain_opts).unwrap();
    assert!(unclipped.mean_delta_e > 1.0);
    assert_eq!((unclipped.rows, unclipped.cols), (rows, cols));
}
