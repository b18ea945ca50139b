//! What one sample of a rendered scene stands for: the target filtered by an aperture of the
//! cell pitch `d`, read at the cell centre.
//!
//! * [`SampleAperture::Cell`]: the area average over the cell (a box of width `d`).
//! * [`SampleAperture::CubicBSpline`]: the target filtered by the cubic B-spline of knot spacing
//!   `d` (four boxes of width `d` convolved, per axis; transfer `sinc⁴(d f)`).
//!
//! Why: the optics' blur (diffraction, a wavefront pupil) is band-limited to `f_c = 1/(λN)`,
//! and the grid is chosen with `f_c ≤ 1/(2d)`. The pixel mean of the blurred irradiance then
//! depends only on the target's spectrum below `f_c`, and any aperture `Φ` gives that part
//! exactly once the optics divide by `Φ` ([`SampleAperture::order`]). What remains is
//! aliasing: target content at `f + k/d` (k ≠ 0) folded into the band, weighted by
//! `Φ(f + k/d)`. The cell average leaves ~0.6 % of an edge's contrast at 3 cells per pixel
//! (Airy, λN = 2.2 µm, 2.2 µm pixels: 1-D study of issue 17 §5); the cubic B-spline, whose
//! transfer falls as `1/f⁴`, leaves ~3e-5 (Unser, "Splines: a perfect fit for signal and image
//! processing", IEEE SPM 1999, for B-splines as sums of boxes).
//!
//! The B-spline density is that of the sum of `n` independent uniform variables on
//! `[−1/2, 1/2]` (Irwin–Hall, centred): a filtered value is a probability, computed exactly.

/// The aperture of the samples of a rendered scene (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SampleAperture {
    /// Area average over the sample's cell.
    #[default]
    Cell,
    /// The target filtered by the cubic B-spline of knot spacing = cell pitch, per axis.
    CubicBSpline,
}

impl SampleAperture {
    /// Number of cell-wide boxes convolved per axis: the transfer is `sincⁿ(d f)` per axis.
    pub fn order(self) -> u32 {
        match self {
            SampleAperture::Cell => 1,
            SampleAperture::CubicBSpline => 4,
        }
    }
}

/// `C(n, k)` for small n.
fn binomial(n: u32, k: u32) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

fn factorial(n: u32) -> f64 {
    (1..=n).fold(1.0, |acc, i| acc * i as f64)
}

/// CDF at `t` of the centred sum of `n` uniforms on [−1/2, 1/2] (Irwin–Hall shifted by n/2):
/// `F(s) = (1/n!) Σ_{k ≤ s} (−1)^k C(n,k) (s − k)^n`, `s = t + n/2`.
pub fn bspline_cdf(n: u32, t: f64) -> f64 {
    let s = t + n as f64 / 2.0;
    if s <= 0.0 {
        return 0.0;
    }
    if s >= n as f64 {
        return 1.0;
    }
    let mut acc = 0.0;
    for k in 0..=(s.floor() as u32).min(n) {
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        acc += sign * binomial(n, k) * (s - k as f64).powi(n as i32);
    }
    (acc / factorial(n)).clamp(0.0, 1.0)
}

/// Density at `t` of the same distribution (the B-spline of order n, unit knot spacing).
pub fn bspline_pdf(n: u32, t: f64) -> f64 {
    let s = t + n as f64 / 2.0;
    if s <= 0.0 || s >= n as f64 {
        return 0.0;
    }
    let mut acc = 0.0;
    for k in 0..=(s.floor() as u32).min(n) {
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        acc += sign * binomial(n, k) * (s - k as f64).powi(n as i32 - 1);
    }
    (acc / factorial(n - 1)).max(0.0)
}

/// The aperture-filtered indicator of the interval `[a, b]` (in cell units, relative to the
/// sample centre): `∫ φ(u) 1[a ≤ u ≤ b] du`.
pub fn interval_weight(aperture: SampleAperture, a: f64, b: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let n = aperture.order();
    bspline_cdf(n, b) - bspline_cdf(n, a)
}

/// 4-point Gauss–Legendre nodes and weights on [−1, 1] (exact for polynomials of degree 7).
const GL4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
];

/// The aperture-filtered indicator of the half-plane `nx·u + ny·v > c` (cell units, relative
/// to the sample centre): `P(nx X + ny Y > c)` for independent X, Y with the aperture's
/// density. Exact: between the breakpoints (the knots of X and the x where the argument of
/// Y's CDF crosses a knot) the integrand `φ(x)·P(ny Y > c − nx x)` is a polynomial of degree
/// `2n − 1 ≤ 7`, integrated by 4-point Gauss–Legendre.
pub fn half_plane_weight(aperture: SampleAperture, nx: f64, ny: f64, c: f64) -> f64 {
    let n = aperture.order();
    let h = n as f64 / 2.0;
    // Outside the joint support the answer is 0 or 1.
    let reach = h * (nx.abs() + ny.abs());
    if c >= reach {
        return 0.0;
    }
    if c <= -reach {
        return 1.0;
    }
    if ny.abs() < 1e-12 {
        // P(nx X > c)
        return if nx > 0.0 {
            1.0 - bspline_cdf(n, c / nx)
        } else {
            bspline_cdf(n, c / nx)
        };
    }
    // P(ny Y > c − nx x) as a function of x.
    let tail = |x: f64| -> f64 {
        let t = (c - nx * x) / ny;
        if ny > 0.0 {
            1.0 - bspline_cdf(n, t)
        } else {
            bspline_cdf(n, t)
        }
    };
    let mut pts: Vec<f64> = (0..=n).map(|k| k as f64 - h).collect();
    if nx.abs() > 1e-12 {
        for k in 0..=n {
            let x = (c - ny * (k as f64 - h)) / nx;
            if x > -h && x < h {
                pts.push(x);
            }
        }
    }
    pts.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    let mut acc = 0.0;
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b - a <= 0.0 {
            continue;
        }
        let (m, r) = (0.5 * (a + b), 0.5 * (b - a));
        for (x, wt) in GL4 {
            let u = m + r * x;
            acc += wt * r * bspline_pdf(n, u) * tail(u);
        }
    }
    acc.clamp(0.0, 1.0)
}

/// The aperture-filtered indicator of the union of intervals `k·spacing + [lo, hi]` (all
/// integers k), in cell units relative to the sample centre.
pub fn periodic_weight(aperture: SampleAperture, spacing: f64, lo: f64, hi: f64) -> f64 {
    let h = aperture.order() as f64 / 2.0;
    let k0 = ((-h - hi) / spacing).floor() as i64;
    let k1 = ((h - lo) / spacing).ceil() as i64;
    let mut s = 0.0;
    for k in k0..=k1 {
        let o = k as f64 * spacing;
        s += interval_weight(aperture, o + lo, o + hi);
    }
    s.min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The density integrates to its CDF (midpoint rule), the CDF is symmetric, and the
    /// cubic B-spline's values at the knots are the textbook 1/6, 2/3, 1/6.
    #[test]
    fn bspline_density_and_cdf_agree() {
        for n in 1..=4 {
            let m = 20000;
            let (lo, hi) = (-(n as f64) / 2.0, n as f64 / 2.0);
            let mut acc = 0.0;
            for i in 0..m {
                let t = lo + (hi - lo) * (i as f64 + 0.5) / m as f64;
                acc += bspline_pdf(n, t) * (hi - lo) / m as f64;
                let t1 = lo + (hi - lo) * (i + 1) as f64 / m as f64;
                assert!((acc - bspline_cdf(n, t1)).abs() < 1e-6, "n {n} t {t1}");
            }
            for t in [0.1, 0.37, 1.2] {
                assert!((bspline_cdf(n, t) + bspline_cdf(n, -t) - 1.0).abs() < 1e-12);
            }
        }
        assert!((bspline_pdf(4, 0.0) - 2.0 / 3.0).abs() < 1e-12);
        assert!((bspline_pdf(4, 1.0) - 1.0 / 6.0).abs() < 1e-12);
        // order 1 is the cell: the weight of [a, b] is its overlap with [−1/2, 1/2]
        assert!((interval_weight(SampleAperture::Cell, -0.2, 3.0) - 0.7).abs() < 1e-12);
    }

    /// The half-plane weight against a brute-force 2-D midpoint sum of the density, for
    /// slanted, axis-aligned and far-away edges.
    #[test]
    fn half_plane_weight_matches_brute_force() {
        let ap = SampleAperture::CubicBSpline;
        let m = 400;
        let step = 4.0 / m as f64;
        let grid: Vec<(f64, f64)> = (0..m)
            .map(|i| {
                let u = -2.0 + (i as f64 + 0.5) * step;
                (u, bspline_pdf(4, u) * step)
            })
            .collect();
        for (deg, c) in [
            (5.0f64, 0.3),
            (37.0, -0.8),
            (0.0, 0.45),
            (90.0, -1.2),
            (-20.0, 2.5),
            (135.0, 0.0),
        ] {
            let (nx, ny) = (deg.to_radians().cos(), deg.to_radians().sin());
            let mut want = 0.0;
            for &(x, wx) in &grid {
                for &(y, wy) in &grid {
                    let v = nx * x + ny * y - c;
                    // a grid point on the line counts half
                    if v.abs() < 1e-12 {
                        want += 0.5 * wx * wy;
                    } else if v > 0.0 {
                        want += wx * wy;
                    }
                }
            }
            let got = half_plane_weight(ap, nx, ny, c);
            assert!((got - want).abs() < 2e-4, "{deg}° c {c}: {got} vs {want}");
        }
        // Cell aperture: the exact overlap area of the unit square.
        let got = half_plane_weight(SampleAperture::Cell, 1.0, 0.0, 0.25);
        assert!((got - 0.25).abs() < 1e-12);
        let a = 45f64.to_radians();
        let got = half_plane_weight(SampleAperture::Cell, a.cos(), a.sin(), 0.0);
        assert!((got - 0.5).abs() < 1e-12);
    }

    /// A periodic pattern of period 1 covering [lo, hi] of every period has weight hi − lo
    /// under any aperture of integer width (a partition of unity).
    #[test]
    fn periodic_weight_of_unit_period_is_the_duty_cycle() {
        for ap in [SampleAperture::Cell, SampleAperture::CubicBSpline] {
            let w = periodic_weight(ap, 1.0, -0.13, 0.21);
            assert!((w - 0.34).abs() < 1e-12, "{ap:?}: {w}");
        }
    }
}
