//! Numerical helpers of the mismatch diagnosis: the normal distribution, moments of a clipped
//! (censored) normal variable, a small-rank Woodbury log-likelihood and 1-D minimisation.

/// Standard normal density φ(x).
#[inline]
pub fn norm_pdf(x: f64) -> f64 {
    0.398_942_280_401_432_7 * (-0.5 * x * x).exp()
}

/// Standard normal distribution function Φ(x) = erfc(−x/√2)/2.
#[inline]
pub fn norm_cdf(x: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-x * std::f64::consts::FRAC_1_SQRT_2)
}

/// Moments of `Y = clamp(X, lo, hi)` for `X ~ N(m, s²)` (Tobit / censored normal moments:
/// Greene, *Econometric Analysis*, §19.3): the mean, the variance, and the probabilities of
/// the two clipped tails.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Censored {
    /// `E[Y]`.
    pub mean: f64,
    /// `Var[Y]`.
    pub var: f64,
    /// P(X ≤ lo).
    pub p_lo: f64,
    /// P(X ≥ hi).
    pub p_hi: f64,
}

/// See [`Censored`]; `lo` may be −∞ and `hi` +∞. With `s = 0` the variable is `clamp(m)`.
pub fn censored(m: f64, s: f64, lo: f64, hi: f64) -> Censored {
    thread_local! {
        static MEMO: std::cell::RefCell<super::memo::Memo<4, Censored>> = Default::default();
    }
    super::memo::memo_with(&MEMO, [m, s, lo, hi], || censored_calc(m, s, lo, hi))
}

/// [`censored`], computed.
fn censored_calc(m: f64, s: f64, lo: f64, hi: f64) -> Censored {
    if !(s > 0.0) {
        let y = m.clamp(lo, hi);
        return Censored {
            mean: y,
            var: 0.0,
            p_lo: if m <= lo { 1.0 } else { 0.0 },
            p_hi: if m >= hi { 1.0 } else { 0.0 },
        };
    }
    let (a, b) = ((lo - m) / s, (hi - m) / s);
    let (pa, pb) = (
        if a.is_finite() { norm_cdf(a) } else { 0.0 },
        if b.is_finite() { norm_cdf(b) } else { 1.0 },
    );
    let (fa, fb) = (
        if a.is_finite() { norm_pdf(a) } else { 0.0 },
        if b.is_finite() { norm_pdf(b) } else { 0.0 },
    );
    let mid = (pb - pa).max(0.0);
    let lo_t = if a.is_finite() { lo * pa } else { 0.0 };
    let hi_t = if b.is_finite() { hi * (1.0 - pb) } else { 0.0 };
    // E[X; lo<X<hi] = m·ΔΦ + s(φa − φb)
    let mean = lo_t + hi_t + m * mid + s * (fa - fb);
    // E[X²; lo<X<hi] = (m²+s²)ΔΦ + s φa (m+lo) − s φb (m+hi)
    let m2_mid = (m * m + s * s) * mid
        + if a.is_finite() {
            s * fa * (m + lo)
        } else {
            0.0
        }
        - if b.is_finite() {
            s * fb * (m + hi)
        } else {
            0.0
        };
    let lo2 = if a.is_finite() { lo * lo * pa } else { 0.0 };
    let hi2 = if b.is_finite() {
        hi * hi * (1.0 - pb)
    } else {
        0.0
    };
    let var = (lo2 + hi2 + m2_mid - mean * mean).max(0.0);
    Censored {
        mean,
        var,
        p_lo: pa,
        p_hi: 1.0 - pb,
    }
}

/// A product of positive factors kept as mantissa × 2^exponent, so that `ln Π x` costs one
/// logarithm however many factors (the determinants of the per-pixel likelihoods: one `ln`
/// per pixel instead of one per pixel-shot). Zero, infinite or NaN factors go to `ln` directly.
#[derive(Debug, Clone, Copy)]
pub struct LogProd {
    m: f64,
    e: i64,
    extra: f64,
}

impl Default for LogProd {
    fn default() -> Self {
        LogProd {
            m: 1.0,
            e: 0,
            extra: 0.0,
        }
    }
}

impl LogProd {
    /// Multiplies `x` into the product.
    #[inline]
    pub fn mul(&mut self, x: f64) {
        let m = self.m * x;
        // (NaN fails the test and goes to the slow path)
        if m > 1e-150 && m < 1e150 {
            self.m = m;
        } else {
            self.mul_slow(x);
        }
    }

    /// `mul` when the running mantissa leaves (1e-150, 1e150): move the exponents of the
    /// product and of `x` into `e`, keeping the mantissa in [1, 2).
    #[cold]
    fn mul_slow(&mut self, x: f64) {
        if !(x.is_normal() && x > 0.0) {
            self.extra += x.ln();
            return;
        }
        let split = |v: f64| -> (f64, i64) {
            let bits = v.to_bits();
            (
                f64::from_bits((bits & !(0x7ffu64 << 52)) | (1023u64 << 52)),
                ((bits >> 52) & 0x7ff) as i64 - 1023,
            )
        };
        // self.m is positive and normal here (it only ever holds in-range products)
        let (xm, xe) = split(x);
        let (pm, pe) = split(self.m * xm);
        self.m = pm;
        self.e += xe + pe;
    }

    /// Multiplies `x^k` into the product.
    #[inline]
    pub fn mul_pow(&mut self, x: f64, k: u32) {
        // (k = 1, 2 written out: the bits `powi` gives — r = 1·x, r = 1·(x·x) in its
        // square-and-multiply — without the library call; test `mul_pow_is_powi`)
        let xk = match k {
            1 => x,
            2 => x * x,
            _ => x.powi(k as i32),
        };
        if k <= 32 && xk > 1e-150 && xk < 1e150 {
            self.mul(xk);
        } else {
            for _ in 0..k {
                self.mul(x);
            }
        }
    }

    /// `ln` of the product.
    #[inline]
    pub fn ln(&self) -> f64 {
        self.m.ln() + self.e as f64 * std::f64::consts::LN_2 + self.extra
    }
}

/// Accumulates the Gaussian log-likelihood of a residual vector `r` with covariance
/// `diag(a) + Σ_k b_k b_kᵀ` (rank ≤ 2) by the Woodbury identity and the matrix determinant
/// lemma: `rᵀC⁻¹r = Σ r²/a − qᵀM⁻¹q`, `ln det C = Σ ln a + ln det M`, `M = I + BᵀA⁻¹B`,
/// `q = BᵀA⁻¹r` (Golub & Van Loan, *Matrix Computations*, §2.1.4).
#[derive(Debug, Clone, Copy, Default)]
pub struct Woodbury {
    rr: f64,
    det: LogProd,
    q: [f64; 2],
    m: [f64; 3],
    n: usize,
}

impl Woodbury {
    /// Adds one component: residual `r`, diagonal variance `a > 0`, low-rank loadings `b`.
    #[inline]
    pub fn add(&mut self, r: f64, a: f64, b: [f64; 2]) {
        let ia = 1.0 / a;
        self.rr += r * r * ia;
        self.det.mul(a);
        let (b0, b1) = (b[0] * ia, b[1] * ia);
        self.q[0] += b0 * r;
        self.q[1] += b1 * r;
        self.m[0] += b0 * b[0];
        self.m[1] += b1 * b[0];
        self.m[2] += b1 * b[1];
        self.n += 1;
    }

    /// Multiplies an extra factor `x^k` into the determinant (a term `−k/2 · ln x` of
    /// [`Woodbury::log_likelihood`] that costs no logarithm of its own).
    #[inline]
    pub fn mul_det_pow(&mut self, x: f64, k: u32) {
        self.det.mul_pow(x, k);
    }

    /// Number of components added.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True when nothing was added.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// (quadratic form rᵀC⁻¹r, ln det C).
    pub fn finish(&self) -> (f64, f64) {
        // Cholesky of M = I + BᵀA⁻¹B (symmetric positive definite, 2×2).
        let l00 = (self.m[0] + 1.0).max(1e-300).sqrt();
        let l10 = self.m[1] / l00;
        let l11 = (self.m[2] + 1.0 - l10 * l10).max(1e-300).sqrt();
        // qᵀM⁻¹q = |L⁻¹q|²
        let y0 = self.q[0] / l00;
        let y1 = (self.q[1] - l10 * y0) / l11;
        let qmq = y0 * y0 + y1 * y1;
        let mut det = self.det;
        det.mul(l00 * l00);
        det.mul(l11 * l11);
        ((self.rr - qmq).max(0.0), det.ln())
    }

    /// Gaussian log-likelihood without the `−n/2 ln 2π` constant.
    pub fn log_likelihood(&self) -> f64 {
        let (quad, logdet) = self.finish();
        -0.5 * (quad + logdet)
    }
}

/// `ln(e^a + e^b)` without overflow.
#[inline]
pub fn log_add_exp(a: f64, b: f64) -> f64 {
    if a == f64::NEG_INFINITY {
        return b;
    }
    if b == f64::NEG_INFINITY {
        return a;
    }
    let m = a.max(b);
    m + ((a - m).exp() + (b - m).exp()).ln()
}

/// Minimum of `f` on [lo, hi] by Brent's method (golden section with parabolic steps;
/// Brent, *Algorithms for Minimization without Derivatives*, 1973, ch. 5), started from the
/// best of `grid` evenly spaced points (so a coarse global search guards against local
/// minima). Returns (x, f(x)).
pub fn minimize_1d(
    mut f: impl FnMut(f64) -> f64,
    lo: f64,
    hi: f64,
    grid: usize,
    xtol: f64,
) -> (f64, f64) {
    let grid = grid.max(3);
    let mut best = (lo, f64::INFINITY);
    let mut xs = Vec::with_capacity(grid);
    let mut fs = Vec::with_capacity(grid);
    for i in 0..grid {
        let x = lo + (hi - lo) * i as f64 / (grid - 1) as f64;
        let v = f(x);
        let v = if v.is_finite() { v } else { f64::INFINITY };
        xs.push(x);
        fs.push(v);
        if v < best.1 {
            best = (x, v);
        }
    }
    let i = xs.iter().position(|&x| x == best.0).unwrap_or(0);
    let a = xs[i.saturating_sub(1)];
    let b = xs[(i + 1).min(grid - 1)];
    let (x, fx) = brent(&mut f, a, b, best.0, best.1, xtol);
    if fx <= best.1 {
        (x, fx)
    } else {
        best
    }
}

/// Minimum of `f` on [lo, hi] from a start `x0` near it (a warm start): steps of the grid
/// spacing h = (hi − lo)/(grid − 1) from `x0` downhill, each twice the last, until `f` rises
/// or a bound is reached, then Brent's method in the bracket of the best point's neighbours
/// (as [`minimize_1d`], same tolerance). About 3 + (steps) + (Brent's) evaluations instead of
/// `grid` + (Brent's); finds the minimum of the valley holding `x0` (the grid scan of
/// [`minimize_1d`] guards against other valleys: use this only from a previous optimum of
/// a nearby problem). Returns (x, f(x)).
pub fn minimize_1d_local(
    mut f: impl FnMut(f64) -> f64,
    lo: f64,
    hi: f64,
    grid: usize,
    xtol: f64,
    x0: f64,
) -> (f64, f64) {
    let h = (hi - lo) / (grid.max(3) - 1) as f64;
    let mut g = |x: f64| {
        let v = f(x);
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    let x0 = x0.clamp(lo, hi);
    let f0 = g(x0);
    let (xr, xl) = ((x0 + h).min(hi), (x0 - h).max(lo));
    let fr = if xr > x0 { g(xr) } else { f64::INFINITY };
    let fl = if xl < x0 { g(xl) } else { f64::INFINITY };
    // (bracket low, best x, best f, bracket high)
    let (a, bx, bf, b) = if f0 <= fr && f0 <= fl {
        (xl, x0, f0, xr)
    } else {
        // walk downhill: dir = +1 towards hi when the right step is the lower one
        let dir = if fr < fl { 1.0 } else { -1.0 };
        let (mut prev, mut x, mut fx) = (x0, if dir > 0.0 { xr } else { xl }, fr.min(fl));
        let mut step = 2.0 * h;
        loop {
            let xn = (x + dir * step).clamp(lo, hi);
            if xn == x {
                // at a bound
                break (prev.min(x), x, fx, prev.max(x));
            }
            let fnx = g(xn);
            if fnx >= fx {
                break (prev.min(xn), x, fx, prev.max(xn));
            }
            prev = x;
            x = xn;
            fx = fnx;
            step *= 2.0;
        }
    };
    let (x, fx) = brent(&mut g, a, b, bx, bf, xtol);
    if fx <= bf {
        (x, fx)
    } else {
        (bx, bf)
    }
}

/// Brent's minimisation on [a, b] from the point `x` with value `fx`.
fn brent(
    f: &mut impl FnMut(f64) -> f64,
    mut a: f64,
    mut b: f64,
    x0: f64,
    f0: f64,
    xtol: f64,
) -> (f64, f64) {
    const CGOLD: f64 = 0.381_966_011_250_105;
    let (mut x, mut w, mut v) = (x0, x0, x0);
    let (mut fx, mut fw, mut fv) = (f0, f0, f0);
    let mut d: f64 = 0.0;
    let mut e: f64 = 0.0;
    for _ in 0..60 {
        let xm = 0.5 * (a + b);
        let tol1 = xtol.max(1e-12 * x.abs());
        let tol2 = 2.0 * tol1;
        if (x - xm).abs() <= tol2 - 0.5 * (b - a) {
            break;
        }
        let mut golden = true;
        if e.abs() > tol1 {
            let r = (x - w) * (fx - fv);
            let mut q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            let etemp = e;
            e = d;
            if p.abs() < (0.5 * q * etemp).abs() && p > q * (a - x) && p < q * (b - x) {
                d = p / q;
                let u = x + d;
                if u - a < tol2 || b - u < tol2 {
                    d = if xm >= x { tol1 } else { -tol1 };
                }
                golden = false;
            }
        }
        if golden {
            e = if x >= xm { a - x } else { b - x };
            d = CGOLD * e;
        }
        let u = if d.abs() >= tol1 {
            x + d
        } else {
            x + if d >= 0.0 { tol1 } else { -tol1 }
        };
        let fu = f(u);
        let fu = if fu.is_finite() { fu } else { f64::INFINITY };
        if fu <= fx {
            if u >= x {
                a = x;
            } else {
                b = x;
            }
            v = w;
            fv = fw;
            w = x;
            fw = fx;
            x = u;
            fx = fu;
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                v = w;
                fv = fw;
                w = u;
                fw = fu;
            } else if fu <= fv || v == x || v == w {
                v = u;
                fv = fu;
            }
        }
    }
    (x, fx)
}

/// Nodes and weights of the n-point Gauss–Hermite rule for expectations over N(0, 1)
/// (Golub & Welsch, Math. Comp. 23, 1969: eigen-decomposition of the Jacobi matrix of the
/// probabilists' Hermite polynomials).
pub fn gauss_hermite(n: usize) -> Vec<(f64, f64)> {
    let mut j = nalgebra::DMatrix::<f64>::zeros(n, n);
    for k in 1..n {
        let b = (k as f64).sqrt();
        j[(k, k - 1)] = b;
        j[(k - 1, k)] = b;
    }
    let e = nalgebra::SymmetricEigen::new(j);
    let mut out: Vec<(f64, f64)> = (0..n)
        .map(|i| (e.eigenvalues[i], e.eigenvectors[(0, i)].powi(2)))
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

/// The 24-point rule of [`gauss_hermite`], computed once.
pub fn gauss_hermite_24() -> &'static [(f64, f64)] {
    static GH: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    GH.get_or_init(|| gauss_hermite(24))
}

/// Upper tail of the χ² distribution with `k` degrees of freedom.
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    if !(x > 0.0) {
        return 1.0;
    }
    ChiSquared::new(k.max(1e-9))
        .map(|d| d.sf(x))
        .unwrap_or(f64::NAN)
}

/// Median of a slice (NaNs ignored); NaN when empty.
pub fn median(v: &[f64]) -> f64 {
    let mut w: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if w.is_empty() {
        return f64::NAN;
    }
    w.sort_by(|a, b| a.total_cmp(b));
    let n = w.len();
    if n % 2 == 1 {
        w[n / 2]
    } else {
        0.5 * (w[n / 2 - 1] + w[n / 2])
    }
}

/// Robust standard deviation: 1.4826 × the median absolute deviation.
pub fn robust_sigma(v: &[f64]) -> f64 {
    let m = median(v);
    let d: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn censored_moments_match_numerical_integration() {
        for &(m, s, lo, hi) in &[
            (0.3, 1.0, 0.0, 10.0),
            (5.0, 2.0, 0.0, 6.0),
            (-1.0, 0.5, 0.0, f64::INFINITY),
            (3.0, 1.5, f64::NEG_INFINITY, 2.5),
        ] {
            let c = censored(m, s, lo, hi);
            // midpoint rule over ±12 σ
            let n = 200_000;
            let (x0, x1) = (m - 12.0 * s, m + 12.0 * s);
            let dx = (x1 - x0) / n as f64;
            let (mut e1, mut e2, mut pl, mut ph) = (0.0, 0.0, 0.0, 0.0);
            for i in 0..n {
                let x = x0 + (i as f64 + 0.5) * dx;
                let p = norm_pdf((x - m) / s) / s * dx;
                let y = x.clamp(lo, hi);
                e1 += y * p;
                e2 += y * y * p;
                if x <= lo {
                    pl += p;
                }
                if x >= hi {
                    ph += p;
                }
            }
            let var = e2 - e1 * e1;
            assert!((c.mean - e1).abs() < 1e-6, "{m} {s}: {} vs {e1}", c.mean);
            assert!((c.var - var).abs() < 1e-5, "{m} {s}: {} vs {var}", c.var);
            assert!(
                (c.p_lo - pl).abs() < 1e-4 && (c.p_hi - ph).abs() < 1e-4,
                "{} {} vs {pl} {ph}",
                c.p_lo,
                c.p_hi
            );
        }
    }

    #[test]
    fn woodbury_matches_dense_inverse() {
        // C = diag(a) + b1 b1ᵀ + b2 b2ᵀ, 4×4, against an explicit nalgebra computation.
        let a = [1.0, 2.0, 0.5, 3.0];
        let b1 = [0.3, -0.2, 0.7, 0.1];
        let b2 = [0.5, 0.5, 0.0, -0.4];
        let r = [0.2, -1.0, 0.4, 2.0];
        let mut w = Woodbury::default();
        for i in 0..4 {
            w.add(r[i], a[i], [b1[i], b2[i]]);
        }
        // an extra determinant factor x^k adds k·ln x to ln det
        let mut wx = w;
        wx.mul_det_pow(3.0, 2);
        assert!((wx.finish().1 - w.finish().1 - 2.0 * 3f64.ln()).abs() < 1e-12);
        let (q, ld) = w.finish();
        let mut c = nalgebra::DMatrix::<f64>::zeros(4, 4);
        for i in 0..4 {
            for j in 0..4 {
                c[(i, j)] = b1[i] * b1[j] + b2[i] * b2[j] + if i == j { a[i] } else { 0.0 };
            }
        }
        let rv = nalgebra::DVector::from_row_slice(&r);
        let ci = c.clone().try_inverse().unwrap();
        let q_ref = (rv.transpose() * ci * rv)[(0, 0)];
        let ld_ref = c.determinant().ln();
        assert!((q - q_ref).abs() < 1e-10 && (ld - ld_ref).abs() < 1e-10);
    }

    #[test]
    fn log_prod_equals_the_sum_of_logarithms() {
        // factors far beyond f64's range when multiplied: 200 × 1e200, 200 × 1e-200, mixed
        let mut xs: Vec<f64> = Vec::new();
        for i in 0..600 {
            xs.push(match i % 3 {
                0 => 1e200 * (1.0 + i as f64 * 1e-3),
                1 => 3.7e-200 / (1.0 + i as f64),
                _ => 0.5 + i as f64,
            });
        }
        let mut p = LogProd::default();
        for &x in &xs {
            p.mul(x);
        }
        let want: f64 = xs.iter().map(|x| x.ln()).sum();
        assert!(
            (p.ln() - want).abs() < 1e-12 * want.abs().max(1.0),
            "{} {want}",
            p.ln()
        );
        let mut q = LogProd::default();
        q.mul_pow(7.5, 5);
        assert!((q.ln() - 5.0 * 7.5f64.ln()).abs() < 1e-13);
        // a zero factor gives −∞, a subnormal one its own logarithm
        let mut z = LogProd::default();
        z.mul(2.0);
        z.mul(0.0);
        assert_eq!(z.ln(), f64::NEG_INFINITY);
        let mut sub = LogProd::default();
        sub.mul(1e-310);
        sub.mul(4.0);
        assert!((sub.ln() - (1e-310f64.ln() + 4f64.ln())).abs() < 1e-12);
    }

    /// The written-out powers of `LogProd::mul_pow` are `powi`'s bits.
    #[test]
    fn mul_pow_is_powi() {
        let mut x = 0.37f64;
        for i in 0..100_000 {
            x = (x * 3.9 * (1.0 - x)).clamp(1e-9, 1.0 - 1e-9);
            let v = x * 10f64.powi(i % 400 - 200);
            for k in 1..=2u32 {
                let mut a = LogProd::default();
                a.mul_pow(v, k);
                let mut b = LogProd::default();
                let vk = std::hint::black_box(v).powi(std::hint::black_box(k as i32));
                if vk > 1e-150 && vk < 1e150 {
                    b.mul(vk);
                } else {
                    for _ in 0..k {
                        b.mul(v);
                    }
                }
                assert_eq!(a.ln().to_bits(), b.ln().to_bits(), "{v}^{k}");
            }
        }
    }

    #[test]
    fn gauss_hermite_integrates_normal_moments() {
        let gh = gauss_hermite(24);
        let m = |k: i32| gh.iter().map(|(x, w)| w * x.powi(k)).sum::<f64>();
        assert!((m(0) - 1.0).abs() < 1e-12);
        assert!(m(1).abs() < 1e-12);
        assert!((m(2) - 1.0).abs() < 1e-10);
        assert!((m(4) - 3.0).abs() < 1e-9);
        assert!((m(6) - 15.0).abs() < 1e-8);
        // E[Φ(a + b Z)] = Φ(a / √(1 + b²))
        let e: f64 = gh.iter().map(|(x, w)| w * norm_cdf(0.3 + 0.8 * x)).sum();
        assert!((e - norm_cdf(0.3 / (1.0f64 + 0.64).sqrt())).abs() < 1e-6);
    }

    #[test]
    fn minimize_finds_parabola_minimum() {
        let (x, fx) = minimize_1d(|x| (x - 0.37).powi(2) + 2.0, -3.0, 5.0, 9, 1e-9);
        assert!((x - 0.37).abs() < 1e-6 && (fx - 2.0).abs() < 1e-10);
        // a function with a local minimum: the grid start finds the global one
        let f = |x: f64| (x * x - 4.0).powi(2) + x;
        let (x, _) = minimize_1d(f, -3.0, 3.0, 13, 1e-9);
        assert!(x < 0.0, "{x}");
    }

    /// The warm-start search from any start in a unimodal function's valley (at the
    /// minimum, beside it, far from it, at either bound) ends at the grid search's minimum
    /// within the tolerance, in fewer evaluations than the grid's; a minimum at a bound is
    /// found from the other side.
    #[test]
    fn local_search_from_a_warm_start_finds_the_grid_minimum() {
        let cases: Vec<(&str, Box<dyn Fn(f64) -> f64>, f64, f64)> = vec![
            (
                "parabola",
                Box::new(|x: f64| 3e4 * (x - 1.93).powi(2) + 1e6),
                0.0,
                4.0,
            ),
            (
                "V",
                Box::new(|x: f64| 1e6 + 5e5 * (x - 0.117).abs()),
                -1.0,
                1.0,
            ),
            ("skewed", Box::new(|x: f64| (x - 0.3).exp() - x), -2.0, 3.0),
            ("at lo", Box::new(|x: f64| x * 10.0), 0.0, 1.0),
            ("at hi", Box::new(|x: f64| -x * 10.0), 0.0, 1.0),
        ];
        let xtol = 1e-7;
        for (name, f, lo, hi) in &cases {
            let mut n_grid = 0;
            let (xg, fg) = minimize_1d(
                |x| {
                    n_grid += 1;
                    f(x)
                },
                *lo,
                *hi,
                17,
                xtol,
            );
            for t in [0.0, 0.05, 0.3, 0.5, 0.9, 1.0] {
                let x0 = lo + t * (hi - lo);
                let mut n = 0;
                let (x, fx) = minimize_1d_local(
                    |x| {
                        n += 1;
                        f(x)
                    },
                    *lo,
                    *hi,
                    17,
                    xtol,
                    x0,
                );
                // within the tolerance of the grid's minimum, and no worse than f there
                let f_tol = f((xg - 10.0 * xtol).max(*lo)).max(f((xg + 10.0 * xtol).min(*hi)));
                assert!(
                    (x - xg).abs() < 10.0 * xtol && fx <= f_tol.max(fg),
                    "{name} from {x0}: {x} ({fx}) vs grid {xg} ({fg})"
                );
                if (x0 - xg).abs() < 0.1 * (hi - lo) {
                    assert!(n < n_grid, "{name} from {x0}: {n} vs {n_grid} evaluations");
                }
            }
        }
    }
}
