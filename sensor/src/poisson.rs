//! Exact Poisson sampling for the shot noise of step 4.
//!
//! * mean < 10: inversion by sequential search (one uniform);
//! * mean ≥ 10: Ahrens & Dieter's algorithm PD (J. H. Ahrens, U. Dieter, "Computer generation
//!   of Poisson deviates from modified normal distributions", ACM TOMS 8(2), 1982). A normal
//!   deviate `T` gives the candidate `K = ⌊μ + √μ T⌋`; about half of the draws are accepted
//!   at once (`K ≥ ⌊μ − 1.1484⌋`), almost all others after one uniform and a cubic squeeze
//!   (`6μ² U ≥ (μ − K)³`); the rest go through the exact acceptance tests Q and H (a
//!   double-exponential hat). Per-mean set-up is one square root. It is exact at every mean
//!   (no Gaussian approximation at any level).
//!
//! The acceptance tests need the Poisson probabilities `p_K = e^{−μ} μ^K / K!`, written as
//! `p_K = exp(px) / √(2π K)` with `px = K ln(1+v) − (μ − K) − δ(K)`, `v = (μ − K)/K` and
//! `δ(K) = ln K! − ln(√(2πK) (K/e)^K)` (Stirling's correction). Unlike the published
//! algorithm, which uses economised polynomials accurate to ~1e-7, `ln(1+v)` is computed by
//! `ln_1p` and `δ` by five terms of the Stirling series (error < 3e-14 for K ≥ 10), so the
//! sampler is exact up to floating point.
use crate::normal::Ziggurat;
use rand::{Rng, RngExt};
use rand_distr::Exp1;

const LN_FACT_TABLE_LEN: usize = 32;

fn ln_fact_table() -> &'static [f64; LN_FACT_TABLE_LEN] {
    static TABLE: std::sync::OnceLock<[f64; LN_FACT_TABLE_LEN]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0.0; LN_FACT_TABLE_LEN];
        for k in 1..LN_FACT_TABLE_LEN {
            t[k] = t[k - 1] + (k as f64).ln();
        }
        t
    })
}

/// `ln k!` for k ≥ 0.
pub fn ln_factorial(k: f64) -> f64 {
    if k < LN_FACT_TABLE_LEN as f64 {
        return ln_fact_table()[k as usize];
    }
    // Stirling series of ln Γ(x), x = k + 1 ≥ 33: truncation error < 1/(1188 x⁹).
    let x = k + 1.0;
    let r = 1.0 / x;
    let r2 = r * r;
    (x - 0.5) * x.ln() - x
        + 0.918_938_533_204_672_8 // ln √(2π)
        + r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 / 1680.0)))
}

/// Stirling's correction `δ(k) = ln k! − (k + ½) ln k + k − ln √(2π)` for k ≥ 10:
/// `1/(12k) − 1/(360k³) + 1/(1260k⁵) − 1/(1680k⁷) + 1/(1188k⁹)`, truncation error
/// < 691/(360360 k¹¹) < 2e-14.
#[inline]
fn stirling_correction(k: f64) -> f64 {
    let r = 1.0 / k;
    let r2 = r * r;
    r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 * (1.0 / 1680.0 - r2 / 1188.0))))
}

/// floor(x) for |x| < 2^63 without a libm call.
#[inline(always)]
fn fast_floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// The largest mean drawn exactly, 2⁵²: above it f64 does not hold every integer.
pub const EXACT_MEAN_MAX: f64 = 4_503_599_627_370_496.0;

const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// k! for k < 10.
const FACT: [f64; 10] = [
    1.0, 1.0, 2.0, 6.0, 24.0, 120.0, 720.0, 5040.0, 40320.0, 362880.0,
];

/// One exact Poisson(mean) draw, returned as f64 (0 for mean ≤ 0 or NaN).
#[inline]
pub fn sample_poisson<R: Rng + Clone>(rng: &mut R, mean: f64) -> f64 {
    PoissonSampler::default().sample(rng, mean)
}

/// An exact Poisson sampler. Below a mean of 10 it caches `e^{−mean}` of the last mean, so
/// runs of equal means (dark fields) skip the `exp`; above, the set-up (one square root) is
/// cheaper than a cache. Same draws as [`sample_poisson`].
#[derive(Debug, Clone, Default)]
pub struct PoissonSampler {
    // inversion (mean < 10): the last mean and e^{-mean}
    mean: f64,
    exp_neg: f64,
    normal: Ziggurat,
}

/// The constants of the modified normal hat of algorithm PD (its "procedure P"), for one mean.
struct Hat {
    omega: f64,
    c0: f64,
    c1: f64,
    c2: f64,
    c3: f64,
}

impl Hat {
    fn new(mu: f64, s: f64) -> Self {
        let b1 = 1.0 / (24.0 * mu);
        let b2 = 0.3 * b1 * b1;
        let c3 = b1 * b2 / 7.0;
        Hat {
            omega: INV_SQRT_2PI / s,
            c3,
            c2: b2 - 15.0 * c3,
            c1: b1 - 6.0 * b2 + 45.0 * c3,
            c0: 1.0 - b1 + 3.0 * b2 - 15.0 * c3,
        }
    }

    /// "Procedure F": `(px, py, fx, fy)` with `p_K = py · e^{px}` (exact Poisson
    /// probability) and `f_K = fy · e^{fx}` (the hat), for K ≥ 0.
    fn f(&self, mu: f64, s: f64, k: f64) -> (f64, f64, f64, f64) {
        let (px, py) = if k < 10.0 {
            (-mu, mu.powi(k as i32) / FACT[k as usize])
        } else {
            let v = (mu - k) / k;
            (
                k * v.ln_1p() - (mu - k) - stirling_correction(k),
                INV_SQRT_2PI / k.sqrt(),
            )
        };
        let x = (k - mu + 0.5) / s;
        let xx = x * x;
        let fx = -0.5 * xx;
        let fy = self.omega * (((self.c3 * xx + self.c2) * xx + self.c1) * xx + self.c0);
        (px, py, fx, fy)
    }
}

impl PoissonSampler {
    /// One exact Poisson(mean) draw, returned as f64 (0 for mean ≤ 0 or NaN).
    ///
    /// A mean of +∞ (light that overflowed) gives +∞, which the caller clips at the full well.
    /// Above [`EXACT_MEAN_MAX`] f64 no longer holds consecutive integers, so no draw can be
    /// exact; there the draw is the normal limit `⌊μ + √μ·T⌋` (the relative error of its
    /// probabilities is O(1/√μ) < 2e-8), which also keeps the algorithm's integer arithmetic
    /// (|K| < 2⁶³) in range.
    #[inline(always)]
    pub fn sample<R: Rng + Clone>(&mut self, rng: &mut R, mean: f64) -> f64 {
        self.draw::<R, false>(rng, mean)
    }

    /// As [`PoissonSampler::sample`], except that a NaN mean is light that overflowed upstream
    /// (∞·0 or ∞ − ∞ in a blur) and gives +∞, like a mean of +∞: the sensor kernel's draw, so
    /// such a pixel saturates instead of reading black.
    #[inline(always)]
    pub fn sample_saturating<R: Rng + Clone>(&mut self, rng: &mut R, mean: f64) -> f64 {
        self.draw::<R, true>(rng, mean)
    }

    /// The draw behind both public methods. The tests are ordered so that an ordinary mean
    /// meets two comparisons (μ < 10, then μ > 0 or μ < 2⁵²); NaN fails both range tests and
    /// is sorted out in the rare branch.
    #[inline(always)]
    fn draw<R: Rng + Clone, const NAN_IS_LIGHT: bool>(&mut self, rng: &mut R, mean: f64) -> f64 {
        if mean < 10.0 {
            if !(mean > 0.0) {
                return 0.0;
            }
            if mean != self.mean {
                self.mean = mean;
                self.exp_neg = (-mean).exp();
            }
            return self.inversion(rng, mean);
        }
        if !(mean < EXACT_MEAN_MAX) {
            if mean.is_nan() {
                return if NAN_IS_LIGHT { f64::INFINITY } else { 0.0 };
            }
            if mean == f64::INFINITY {
                return f64::INFINITY;
            }
            return (mean + mean.sqrt() * self.normal.sample(rng))
                .floor()
                .max(0.0);
        }
        // Case μ ≥ 10: set-up s = √μ, L = ⌊μ − 1.1484⌋, d = 6μ².
        let s = mean.sqrt();
        let big_l = fast_floor(mean - 1.1484);
        let d = 6.0 * mean * mean;
        // Step N: a normal deviate, candidate K = ⌊μ + sT⌋.
        let t = self.normal.sample(rng);
        let g = mean + s * t;
        // The uniform of step S is drawn unconditionally: a discarded independent uniform
        // does not change the output distribution, and the combined test below is a
        // well-predicted branch (taken ~99.7 % of the time at μ = 2000).
        let u: f64 = rng.random();
        let k = fast_floor(g);
        let dk = mean - k;
        // Step I (K ≥ L) or step S (squeeze 6μ²U ≥ (μ − K)³); g ≥ 0 keeps K ≥ 0.
        // Non-short-circuit `&`/`|`: one branch instead of the unpredictable K ≥ L.
        if (g >= 0.0) & ((k >= big_l) | (d * u >= dk * dk * dk)) {
            return k;
        }
        // On a copy of the generator (see [`standard_normal`]: keeps the caller's in registers).
        let mut tmp = rng.clone();
        let k = slow(&mut tmp, mean, s, (g >= 0.0).then_some((k, u)));
        *rng = tmp;
        k
    }

    /// Inversion (mean < 10): smallest k with F(k) ≥ u.
    #[inline]
    fn inversion<R: Rng>(&self, rng: &mut R, mean: f64) -> f64 {
        let u: f64 = rng.random();
        let mut p = self.exp_neg;
        let mut cdf = p;
        let mut k = 0.0;
        while u > cdf && k < 1000.0 {
            k += 1.0;
            p *= mean / k;
            cdf += p;
        }
        k
    }
}

/// Algorithm PD, μ ≥ 10, s = √μ: steps P, Q (for a candidate of step N that the squeeze did
/// not accept) and the double-exponential rejection loop, steps E and H.
#[cold]
#[inline(never)]
fn slow<R: Rng + Clone>(rng: &mut R, mu: f64, s: f64, cand: Option<(f64, f64)>) -> f64 {
    let hat = Hat::new(mu, s);
    if let Some((k, u)) = cand {
        // Step Q.
        let (px, py, fx, fy) = hat.f(mu, s, k);
        if fy * (1.0 - u) <= py * (px - fx).exp() {
            return k;
        }
    }
    let c = 0.1069 / mu;
    loop {
        // Step E: T = 1.8 ± E, E standard exponential, sign from a uniform in (−1, 1).
        let e: f64 = rng.sample(Exp1);
        let u: f64 = 2.0 * rng.random::<f64>() - 1.0;
        let t = 1.8 + if u < 0.0 { -e } else { e };
        if t <= -0.6744 {
            continue;
        }
        let k = fast_floor(mu + s * t);
        let (px, py, fx, fy) = hat.f(mu, s, k);
        // Step H.
        if c * u.abs() <= py * (px + e).exp() - fy * (fx + e).exp() {
            return k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn ln_factorial_matches_direct_sum() {
        let mut s = 0.0;
        for k in 1..2000u32 {
            s += (k as f64).ln();
            assert_relative_eq!(ln_factorial(k as f64), s, max_relative = 1e-13);
        }
        assert_eq!(ln_factorial(0.0), 0.0);
    }

    #[test]
    fn stirling_correction_matches_ln_factorial() {
        // δ(k) = ln k! − (k + ½) ln k + k − ln √(2π), the sum ln k! compensated (Kahan); the
        // direct difference loses ~ε·k ln k to cancellation, which sets the tolerance.
        let (mut s, mut comp) = (0.0f64, 0.0f64);
        for k in 1..3000u32 {
            let kf = k as f64;
            let y = kf.ln() - comp;
            let t = s + y;
            comp = (t - s) - y;
            s = t;
            if k < 10 {
                continue;
            }
            let direct = s - (kf + 0.5) * kf.ln() + kf - 0.918_938_533_204_672_8;
            let tol = 1e-15 + 8.0 * f64::EPSILON * kf * kf.ln();
            let got = stirling_correction(kf);
            assert!((got - direct).abs() < tol, "k {k}: {got} vs {direct}");
            // The correction is much larger than that tolerance (so the test has power).
            assert!(got > 20.0 * tol);
        }
    }

    #[test]
    fn probabilities_of_procedure_f_are_exact() {
        // py·e^{px} must be the Poisson pmf (relative 1e-12) on both branches (K < 10, K ≥ 10).
        for &mu in &[10.0, 10.5, 37.2, 1900.3, 2e5] {
            let s = f64::sqrt(mu);
            let hat = Hat::new(mu, s);
            let lo = (mu - 6.0 * s).max(0.0) as u64;
            for k in (lo..(mu + 6.0 * s) as u64).step_by(1 + (s as usize) / 4) {
                let kf = k as f64;
                let (px, py, _, _) = hat.f(mu, s, kf);
                let want = -mu + kf * mu.ln() - ln_factorial(kf);
                let got = py.ln() + px;
                // ln pmf to 1e-12 absolute relative to the magnitude of its terms.
                let scale = 1.0 + mu * mu.ln().abs() * 1e-3;
                assert!(
                    (got - want).abs() < 1e-12 * scale,
                    "mu {mu} k {k}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn infinite_and_huge_means_return_at_once() {
        let mut r = camsim_core::rng::stream(2, &[]);
        assert_eq!(sample_poisson(&mut r, f64::INFINITY), f64::INFINITY);
        assert_eq!(sample_poisson(&mut r, f64::MAX), f64::MAX);
        // Above 2^52: the normal limit, z-test of the mean over 4000 draws (|z| < 4.5).
        let mu = 1e18;
        let n = 4000;
        let mean = (0..n).map(|_| sample_poisson(&mut r, mu) - mu).sum::<f64>() / n as f64;
        let z = mean / (mu.sqrt() / (n as f64).sqrt());
        assert!(z.abs() < 4.5, "z = {z}");
        let x = sample_poisson(&mut r, 1e300);
        assert!(x.is_finite() && x > 0.99e300);
    }

    #[test]
    fn zero_and_negative_means_give_zero() {
        let mut r = camsim_core::rng::stream(1, &[]);
        assert_eq!(sample_poisson(&mut r, 0.0), 0.0);
        assert_eq!(sample_poisson(&mut r, -3.0), 0.0);
        assert_eq!(sample_poisson(&mut r, f64::NAN), 0.0);
    }
}
