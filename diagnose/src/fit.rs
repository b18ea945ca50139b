//! Small numerical tools: weighted line fits, Lawson–Hanson non-negative least squares,
//! 2-D polynomial surfaces, robust location/scale.
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Weighted least-squares line `y = intercept + slope · x` with known point standard errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeightedLine {
    /// Slope.
    pub slope: f64,
    /// Intercept.
    pub intercept: f64,
    /// Standard error of the slope (scaled by √(χ²/dof) when that exceeds 1).
    pub slope_se: f64,
    /// Standard error of the intercept (same scaling).
    pub intercept_se: f64,
    /// χ² of the fit with the given errors.
    pub chi2: f64,
    /// Points used.
    pub n: usize,
}

/// Weighted least squares with point standard errors `se` (all > 0). Needs two distinct x.
/// The covariance comes from the given errors; when the points scatter more than their
/// errors allow (χ²/dof > 1, dof ≥ 1) it is inflated by χ²/dof, never deflated.
pub fn weighted_line(x: &[f64], y: &[f64], se: &[f64]) -> Option<WeightedLine> {
    let n = x.len();
    if n < 2 || y.len() != n || se.len() != n {
        return None;
    }
    let w: Vec<f64> = se.iter().map(|s| 1.0 / (s * s).max(1e-300)).collect();
    let sw: f64 = w.iter().sum();
    let mx = x.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() / sw;
    let my = y.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() / sw;
    let sxx: f64 = x.iter().zip(&w).map(|(a, b)| b * (a - mx).powi(2)).sum();
    if !(sxx > 0.0) {
        return None;
    }
    let sxy: f64 = (0..n).map(|i| w[i] * (x[i] - mx) * (y[i] - my)).sum();
    let slope = sxy / sxx;
    let intercept = my - slope * mx;
    let chi2: f64 = (0..n)
        .map(|i| w[i] * (y[i] - intercept - slope * x[i]).powi(2))
        .sum();
    let scale = if n > 2 {
        (chi2 / (n - 2) as f64).max(1.0)
    } else {
        1.0
    };
    let var_slope = scale / sxx;
    let var_int = scale * (1.0 / sw + mx * mx / sxx);
    Some(WeightedLine {
        slope,
        intercept,
        slope_se: var_slope.sqrt(),
        intercept_se: var_int.sqrt(),
        chi2,
        n,
    })
}

/// Lawson–Hanson non-negative least squares: `min ‖A x − b‖` subject to `x ≥ 0`.
pub fn nnls(a: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let n = a.ncols();
    let mut x = DVector::zeros(n);
    let mut passive = vec![false; n];
    let atb = a.transpose() * b;
    let ata = a.transpose() * a;
    let tol = 1e-12 * ata.diagonal().amax().max(1e-300) * n as f64;
    for _outer in 0..(3 * n + 10) {
        let grad = &atb - &ata * &x;
        // Most positive gradient among the active (zero) set.
        let mut best = None;
        for j in 0..n {
            if !passive[j] && grad[j] > tol && best.is_none_or(|(_, g)| grad[j] > g) {
                best = Some((j, grad[j]));
            }
        }
        let Some((j, _)) = best else { break };
        passive[j] = true;
        for _inner in 0..(3 * n + 10) {
            let idx: Vec<usize> = (0..n).filter(|&k| passive[k]).collect();
            let sub = DMatrix::from_fn(idx.len(), idx.len(), |r, c| ata[(idx[r], idx[c])]);
            let rhs = DVector::from_iterator(idx.len(), idx.iter().map(|&k| atb[k]));
            let z = match sub.clone().cholesky() {
                Some(ch) => ch.solve(&rhs),
                None => sub
                    .svd(true, true)
                    .solve(&rhs, 1e-14)
                    .unwrap_or_else(|_| DVector::zeros(idx.len())),
            };
            if z.iter().all(|&v| v > 0.0) {
                for (k, &i) in idx.iter().enumerate() {
                    x[i] = z[k];
                }
                break;
            }
            // Step towards z until the first passive variable hits zero.
            let mut alpha = 1.0f64;
            for (k, &i) in idx.iter().enumerate() {
                if z[k] <= 0.0 {
                    let d = x[i] - z[k];
                    if d > 0.0 {
                        alpha = alpha.min(x[i] / d);
                    }
                }
            }
            for (k, &i) in idx.iter().enumerate() {
                x[i] += alpha * (z[k] - x[i]);
                if x[i] <= 1e-15 * (1.0 + z[k].abs()) {
                    x[i] = 0.0;
                    passive[i] = false;
                }
            }
        }
    }
    x
}

/// Median of a slice (copied and partially sorted).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut w = v.to_vec();
    let k = w.len() / 2;
    let (_, m, _) = w.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    let m = *m;
    if w.len() % 2 == 1 {
        m
    } else {
        let lo = w[..k].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (m + lo)
    }
}

/// Median and MAD-based robust standard deviation (1.4826 · MAD).
pub fn robust_location_scale(v: &[f64]) -> (f64, f64) {
    let m = median(v);
    let dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    (m, 1.4826 * median(&dev))
}

/// Least-squares 2-D polynomial surface of total degree `degree` in normalised coordinates
/// (x, y ∈ [−1, 1]) through the values `v[k]` at pixel positions `pos[k] = (row, col)`;
/// returns the fitted value at every position and the number of terms.
pub fn poly_surface(
    pos: &[(usize, usize)],
    v: &[f64],
    rows: usize,
    cols: usize,
    degree: usize,
) -> (Vec<f64>, usize) {
    let terms: Vec<(i32, i32)> = (0..=degree as i32)
        .flat_map(|d| (0..=d).map(move |i| (d - i, i)))
        .collect();
    let nt = terms.len();
    let sx = 2.0 / (cols.max(2) - 1) as f64;
    let sy = 2.0 / (rows.max(2) - 1) as f64;
    let basis = |r: usize, c: usize, out: &mut [f64]| {
        let x = c as f64 * sx - 1.0;
        let y = r as f64 * sy - 1.0;
        for (o, &(px, py)) in out.iter_mut().zip(&terms) {
            *o = x.powi(px) * y.powi(py);
        }
    };
    // Normal equations from fixed chunks summed in order: the same bits at any thread count
    // (a rayon fold/reduce splits by work stealing).
    const CHUNK: usize = 4096;
    let (ata, atb) = pos
        .par_chunks(CHUNK)
        .zip(v.par_chunks(CHUNK))
        .map(|(pc, vc)| {
            let (mut a, mut b, mut phi) = (vec![0.0; nt * nt], vec![0.0; nt], vec![0.0; nt]);
            for (&(r, c), &val) in pc.iter().zip(vc) {
                basis(r, c, &mut phi);
                for i in 0..nt {
                    b[i] += phi[i] * val;
                    for j in 0..nt {
                        a[i * nt + j] += phi[i] * phi[j];
                    }
                }
            }
            (a, b)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold(
            (vec![0.0; nt * nt], vec![0.0; nt]),
            |(mut a, mut b), (a2, b2)| {
                a.iter_mut().zip(a2).for_each(|(x, y)| *x += y);
                b.iter_mut().zip(b2).for_each(|(x, y)| *x += y);
                (a, b)
            },
        );
    let a = DMatrix::from_row_slice(nt, nt, &ata);
    let b = DVector::from_vec(atb);
    let coef = a
        .clone()
        .svd(true, true)
        .solve(&b, 1e-12)
        .unwrap_or_else(|_| DVector::zeros(nt));
    let fitted = pos
        .par_iter()
        .map_init(
            || vec![0.0; nt],
            |phi, &(r, c)| {
                basis(r, c, phi);
                phi.iter().zip(coef.iter()).map(|(p, k)| p * k).sum()
            },
        )
        .collect();
    (fitted, nt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn weighted_line_exact_and_errors() {
        let x = [0.0, 1.0, 2.0, 3.0];
        let y = [1.0, 3.0, 5.0, 7.0];
        let f = weighted_line(&x, &y, &[0.1; 4]).unwrap();
        assert_relative_eq!(f.slope, 2.0, epsilon = 1e-12);
        assert_relative_eq!(f.intercept, 1.0, epsilon = 1e-12);
        // OLS with σ = 0.1: var(slope) = σ²/Sxx = 0.01/5.
        assert_relative_eq!(f.slope_se, (0.01f64 / 5.0).sqrt(), epsilon = 1e-12);
        assert!(weighted_line(&[1.0, 1.0], &[1.0, 2.0], &[1.0, 1.0]).is_none());
    }

    #[test]
    fn nnls_matches_known_solution() {
        // Unconstrained solution has a negative entry; NNLS clamps it and refits.
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let b = DVector::from_vec(vec![2.0, -1.0, 1.0]);
        let x = nnls(&a, &b);
        assert!(x[1] == 0.0);
        assert_relative_eq!(x[0], 1.5, epsilon = 1e-10);
        let b2 = DVector::from_vec(vec![1.0, 2.0, 3.0]);
        let x2 = nnls(&a, &b2);
        assert_relative_eq!(x2[0], 1.0, epsilon = 1e-10);
        assert_relative_eq!(x2[1], 2.0, epsilon = 1e-10);
    }

    #[test]
    fn robust_scale_and_poly() {
        let v: Vec<f64> = (0..1001).map(|i| i as f64).collect();
        assert_eq!(median(&v), 500.0);
        assert_eq!(median(&[1.0, 2.0, 3.0, 10.0]), 2.5);
        let (m, s) = robust_location_scale(&[1.0, 2.0, 3.0, 4.0, 100.0]);
        assert_eq!(m, 3.0);
        assert_relative_eq!(s, 1.4826);
        let pos: Vec<(usize, usize)> = (0..20).flat_map(|r| (0..30).map(move |c| (r, c))).collect();
        let v: Vec<f64> = pos
            .iter()
            .map(|&(r, c)| 1.0 + 0.1 * r as f64 - 0.01 * (c as f64).powi(2))
            .collect();
        let (f, nt) = poly_surface(&pos, &v, 20, 30, 2);
        assert_eq!(nt, 6);
        for (a, b) in f.iter().zip(&v) {
            assert_relative_eq!(a, b, epsilon = 1e-8);
        }
    }
}
