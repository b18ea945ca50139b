//! The clipping term: a pixel-shot with any frame at 0 DN or at the ADC maximum contributes
//! the probability of its rail counts instead of its mean and variance, and its deviance to
//! the χ² summary.
use crate::mismatch::model::Pred;
use std::collections::HashMap;

/// The rail counts of a censored pixel-shot under the model: log-likelihood and the mean
/// number of frames at a rail.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RailStat {
    pub ll: f64,
    /// (Read by the tests only since the χ² summary stopped using it.)
    #[allow(dead_code)]
    pub mean: f64,
}

/// Per-frame rail probabilities of a pixel-shot at the nodes of the fixed-pattern mixture
/// (z ~ N(0, s_f²), 24-point Gauss–Hermite; one node without fixed pattern): weight w,
/// p_lo(z) = Φ((0.5 − y − z)/s_t), p_hi(z) = 1 − Φ((M − 0.5 − y − z)/s_t).
struct RailNodes {
    n: usize,
    w: [f64; 24],
    plo: [f64; 24],
    phi: [f64; 24],
}

impl RailNodes {
    /// (w, p_lo, p_hi) of each node.
    fn iter(&self) -> impl Iterator<Item = (f64, f64, f64)> + '_ {
        (0..self.n).map(|k| (self.w[k], self.plo[k], self.phi[k]))
    }
}

fn rail_nodes(p: &Pred) -> RailNodes {
    use crate::mismatch::num::{gauss_hermite_24, norm_cdf};
    let (s_t, s_f) = (p.s2_t.sqrt(), p.s2_f.sqrt());
    let one = [(0.0, 1.0)];
    let nodes: &[(f64, f64)] = if s_f > 1e-9 * s_t.max(1e-300) {
        gauss_hermite_24()
    } else {
        &one
    };
    let st = s_t.max(1e-9);
    let mut r = RailNodes {
        n: nodes.len(),
        w: [0.0; 24],
        plo: [0.0; 24],
        phi: [0.0; 24],
    };
    for (k, &(z, w)) in nodes.iter().enumerate() {
        let y = p.y + s_f * z;
        r.w[k] = w;
        r.plo[k] = norm_cdf((0.5 - y) / st);
        r.phi[k] = 1.0 - norm_cdf((p.hi - 0.5 - y) / st);
    }
    r
}

/// The frames of a pixel share its fixed pattern, so its rail counts are a mixture over the
/// pixel's fixed offset z ~ N(0, s_f²) of multinomials with per-frame probabilities
/// p_lo(z) = Φ((0.5 − y − z)/s_t), p_hi(z) = 1 − Φ((M − 0.5 − y − z)/s_t) (24-point
/// Gauss–Hermite quadrature over z).
pub(crate) fn rail_stats(p: &Pred, f: f64, nlo: f64, nhi: f64) -> RailStat {
    thread_local! {
        static MEMO: std::cell::RefCell<crate::mismatch::memo::Memo<7, RailStat>> =
            Default::default();
    }
    crate::mismatch::memo::memo_with(&MEMO, [p.y, p.s2_t, p.s2_f, p.hi, f, nlo, nhi], || {
        rail_stats_calc(p, f, nlo, nhi)
    })
}

/// Beyond this many standard deviations Φ is exact to the last bit at 0 or 1 in the sums of
/// [`rail_stats_calc`]: for x ≥ `TAIL` `norm_cdf(x)` is 1.0 (½·(2 − erfc(x/√2)) with
/// erfc(9/√2) ≈ 2.3·10⁻¹⁹ below half an ulp of 2), so 1 − Φ(x) is 0.0; for x ≤ −`TAIL`,
/// Φ(x) ≤ 1.2·10⁻¹⁹ < 2⁻⁵⁴, so 1 − Φ(x) is 1.0 and 1 − Φ(x) − q is 1 − q
/// (test `tail_shortcuts_are_exact`).
const TAIL: f64 = 9.0;

/// ln of the 24-point Gauss–Hermite weights (the bits `w.ln()` gives each time).
fn gh24_ln_weights() -> &'static [f64] {
    static LN: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    LN.get_or_init(|| {
        crate::mismatch::num::gauss_hermite_24()
            .iter()
            .map(|&(_, w)| w.ln())
            .collect()
    })
}

/// The log-likelihood [`rail_stats_calc`] returns when every node's rail probabilities
/// enter as exactly 1 (every logarithm of a count's probability is 0): the log-sum of the
/// weights, computed by the same expressions (per node count: 24 or 1).
fn all_certain_ll(ln_w: &[f64]) -> f64 {
    let lmax = ln_w.iter().fold(f64::NEG_INFINITY, |a, &l| a.max(l));
    let sum: f64 = ln_w.iter().map(|&l| (l - lmax).exp()).sum();
    lmax + sum.ln()
}

/// [`rail_stats`], computed (reads only `y`, `s2_t`, `s2_f` and `hi` of the prediction).
///
/// The same sums as the plain quadrature (each node: p_lo, p_hi by `norm_cdf`, the count
/// terms n·ln p, then a log-sum over the nodes; test
/// `rail_stats_is_the_plain_quadrature_bit_for_bit`) with the work that cannot change a bit
/// left out: Φ beyond ±[`TAIL`] σ (exactly 0 or 1, or a p_lo below 2⁻⁵⁴ that only enters
/// 1 − p_lo − p_hi), ln 1 = 0, the weights' logarithms (a table), and the log-sum when every
/// node's count terms are 0 (a fully saturated or fully mid-range pixel-shot: a constant).
/// `mean` is within 4·ε·F of the plain sum (ε = 2⁻⁵²; p_lo below 2⁻⁵⁴ counts as 0 there, which
/// can round a later addition the other way).
fn rail_stats_calc(p: &Pred, f: f64, nlo: f64, nhi: f64) -> RailStat {
    use crate::mismatch::num::{gauss_hermite_24, norm_cdf};
    if f == 1.0 {
        return rail_stats_single(p, nlo, nhi);
    }
    static ONE: [(f64, f64); 1] = [(0.0, 1.0)];
    static ONE_LN: [f64; 1] = [0.0];
    let nmid = f - nlo - nhi;
    let (s_t, s_f) = (p.s2_t.sqrt(), p.s2_f.sqrt());
    let (nodes, ln_w): (&[(f64, f64)], &[f64]) = if s_f > 1e-9 * s_t.max(1e-300) {
        (gauss_hermite_24(), gh24_ln_weights())
    } else {
        (&ONE, &ONE_LN)
    };
    let st = s_t.max(1e-9);
    let mut lmax = f64::NEG_INFINITY;
    let mut terms = [0.0f64; 24];
    let mut m1 = 0.0;
    // every count term of every node 0 so far
    let mut certain = true;
    // ln p, with ln 1 = +0 exactly
    let ln_p = |x: f64| if x == 1.0 { 0.0 } else { x.max(1e-300).ln() };
    for (k, &(z, w)) in nodes.iter().enumerate() {
        let y = p.y + s_f * z;
        let (a, b) = ((0.5 - y) / st, (p.hi - 0.5 - y) / st);
        let phi = if b <= -TAIL {
            1.0
        } else if b >= TAIL {
            0.0
        } else {
            1.0 - norm_cdf(b)
        };
        // p_lo's value is needed for ln p_lo, or in 1 − p_lo − p_hi unless below 2⁻⁵⁴
        let plo = if a >= TAIL {
            1.0
        } else if a <= -TAIL && nlo == 0.0 {
            0.0
        } else {
            norm_cdf(a)
        };
        let mut l = 0.0;
        if nlo > 0.0 {
            let t = ln_p(plo);
            certain &= t == 0.0;
            l += nlo * t;
        }
        if nhi > 0.0 {
            let t = ln_p(phi);
            certain &= t == 0.0;
            l += nhi * t;
        }
        if nmid > 0.0 {
            let t = ln_p((1.0 - plo - phi).max(0.0));
            certain &= t == 0.0;
            l += nmid * t;
        }
        // (l is exactly 0 when every term is; an infinite count gives NaN, never "certain")
        certain &= l == 0.0;
        let l = l + ln_w[k];
        lmax = lmax.max(l);
        terms[k] = l;
        let pr = (plo + phi).min(1.0);
        m1 += w * pr;
    }
    let ll = if certain {
        // (the weights' log-sum: the same terms as below)
        thread_local! {
            static C: (f64, f64) = (all_certain_ll(gh24_ln_weights()), all_certain_ll(&ONE_LN));
        }
        C.with(|c| if nodes.len() == 1 { c.1 } else { c.0 })
    } else {
        let sum: f64 = terms[..nodes.len()].iter().map(|t| (t - lmax).exp()).sum();
        lmax + sum.ln()
    };
    RailStat { ll, mean: f * m1 }
}

/// The rail probabilities of a single-frame pixel-shot, the fixed-pattern mixture integrated
/// in closed form: with z ~ N(0, s_f²), E_z Φ((c − y − z)/s_t) = Φ((c − y)/√(s_t² + s_f²))
/// (the sum of the independent temporal and fixed-pattern normals; Owen, "A table of normal
/// integrals", Commun. Statist. Simul. Comput. 9(4), 1980, formula 10,010.8:
/// ∫ Φ(a + bx) φ(x) dx = Φ(a/√(1 + b²))). Returns (P_lo, P_hi) = (Φ((0.5 − y)/S),
/// Φ((y − (M − 0.5))/S)), S = √(s_t² + s_f²) (at least 10⁻⁹, as the quadrature's s_t).
fn single_frame_rail_probs(p: &Pred) -> (f64, f64) {
    use crate::mismatch::num::norm_cdf;
    let s = (p.s2_t + p.s2_f).sqrt().max(1e-9);
    (
        norm_cdf((0.5 - p.y) / s),
        norm_cdf((p.y - (p.hi - 0.5)) / s),
    )
}

/// P_mid = Φ((M − 0.5 − y)/S) − Φ((0.5 − y)/S) of a single frame, given
/// [`single_frame_rail_probs`]' (P_lo, P_hi): 1 − P_lo − P_hi while y lies between the rails'
/// thresholds; beyond one, the difference of the two small tail probabilities on that side
/// (Φ(−u) − Φ(−v) for y below the low threshold, Φ(v) − Φ(u) above the high one), which keeps
/// its relative precision where 1 − P_lo − P_hi would cancel to 0 (y ≳ 8 S past a rail).
fn single_frame_mid_prob(p: &Pred, plo: f64, phi: f64) -> f64 {
    use crate::mismatch::num::norm_cdf;
    let s = (p.s2_t + p.s2_f).sqrt().max(1e-9);
    if plo > 0.5 {
        // y below the low threshold: Φ(−u) − Φ(−v) = Φ((y − 0.5)/S) − P_hi
        (norm_cdf((p.y - 0.5) / s) - phi).max(0.0)
    } else if phi > 0.5 {
        // y above the high threshold: Φ(v) − Φ(u) = Φ((M − 0.5 − y)/S) − P_lo
        (norm_cdf((p.hi - 0.5 - p.y) / s) - plo).max(0.0)
    } else {
        (1.0 - plo - phi).max(0.0)
    }
}

/// [`rail_stats_calc`] for F = 1: the mixture over the fixed offset is the single normal of
/// [`single_frame_rail_probs`] (exact; the 24-node quadrature errs where s_f ≫ s_t, e.g. by
/// 10⁻² in P when s_f = 30 s_t, test `single_frame_rail_stats_is_the_exact_mixture`), so the
/// frame's outcome costs one or two `erfc` and one `ln` instead of up to 48 `erfc` and 25
/// `exp`/`ln`. The logarithms are clamped at 10⁻³⁰⁰ as the quadrature's are.
fn rail_stats_single(p: &Pred, nlo: f64, nhi: f64) -> RailStat {
    let (plo, phi) = single_frame_rail_probs(p);
    let pr = if nlo > 0.0 {
        plo
    } else if nhi > 0.0 {
        phi
    } else {
        single_frame_mid_prob(p, plo, phi)
    };
    RailStat {
        ll: pr.max(1e-300).ln(),
        mean: (plo + phi).min(1.0),
    }
}

/// Deviance of a pixel-shot's rail counts (frames at the low rail, at the high rail, between):
/// G² = 2·(Σ_k n_k ln(n_k/F) − lnL_model) ≥ 0, since the model (a mixture of multinomials) is
/// never more likely than the saturated multinomial with the observed frequencies.
pub(crate) fn rail_deviance(rs: &RailStat, f: f64, nlo: f64, nhi: f64) -> f64 {
    let nmid = f - nlo - nhi;
    let sat: f64 = [nlo, nhi, nmid]
        .iter()
        .filter(|&&n| n > 0.0)
        .map(|&n| n * (n / f).ln())
        .sum();
    (2.0 * (sat - rs.ll)).max(0.0)
}

/// Expected deviance E[G²] of a censored pixel-shot's rail counts under the model (the dof
/// of its χ² term): Σ over the outcomes (n_lo, n_hi), n_lo + n_hi ≤ F, of P(n_lo, n_hi) ·
/// G²(n_lo, n_hi), with P the model's own distribution — the same Gauss–Hermite mixture of
/// multinomials as [`rail_stats`] times the multinomial coefficient — and G² as
/// [`rail_deviance`]. Exact for that model (no large-count approximation); a rail the model
/// reaches in under 10⁻¹⁵ frames at every fixed-pattern node is left out of the sum (its
/// share of E[G²] is below ≈ 10⁻¹³). `given_rail`: the pixel-shot is censored only because
/// one of its own frames hit a rail ([`crate::mismatch::data::ShotData::rail_only`]), so it is seen
/// only with n_lo + n_hi ≥ 1 and the expectation is conditional on that. Costs
/// (F + 1)·24 exponentials near one rail, (F + 1)(F + 2)/2·24 near both.
pub(crate) fn rail_expected_deviance(p: &Pred, f: f64, given_rail: bool) -> f64 {
    let nf = f.round().max(0.0) as usize;
    if nf == 0 {
        return 0.0;
    }
    if nf == 1 {
        return single_frame_expected_deviance(p, given_rail);
    }
    let nodes = rail_nodes(p);
    let mut ln_node = [(0.0f64, 0.0f64, 0.0f64, 0.0f64); 24];
    let (mut max_lo, mut max_hi) = (0.0f64, 0.0f64);
    for (k, (w, plo, phi)) in nodes.iter().enumerate() {
        let pm = (1.0 - plo - phi).max(0.0);
        ln_node[k] = (
            w.ln(),
            plo.max(1e-300).ln(),
            phi.max(1e-300).ln(),
            pm.max(1e-300).ln(),
        );
        max_lo = max_lo.max(plo);
        max_hi = max_hi.max(phi);
    }
    let ln_node = &ln_node[..nodes.n];
    let mut lo_on = max_lo * f >= 1e-15;
    let mut hi_on = max_hi * f >= 1e-15;
    if given_rail && !lo_on && !hi_on {
        // Conditional on a rail frame the model all but excludes: keep the likelier rail.
        if max_lo >= max_hi {
            lo_on = true;
        } else {
            hi_on = true;
        }
    }
    let lo_max = if lo_on { nf } else { 0 };
    let hi_max = if hi_on { nf } else { 0 };
    let mut ln_fact = Vec::with_capacity(nf + 1);
    ln_fact.push(0.0f64);
    for k in 1..=nf {
        ln_fact.push(ln_fact[k - 1] + (k as f64).ln());
    }
    // (ln P, G²) of each outcome; normalised at the end (log domain: P can underflow).
    let mut out: Vec<(f64, f64)> = Vec::with_capacity((lo_max + 1) * (hi_max + 1));
    let mut terms = [0.0f64; 24];
    for a in 0..=lo_max {
        for b in 0..=hi_max.min(nf - a) {
            if given_rail && a + b == 0 {
                continue;
            }
            let c = nf - a - b;
            let (af, bf, cf) = (a as f64, b as f64, c as f64);
            let mut lmax = f64::NEG_INFINITY;
            for (k, &(lw, llo, lhi, lmid)) in ln_node.iter().enumerate() {
                let mut l = lw;
                if a > 0 {
                    l += af * llo;
                }
                if b > 0 {
                    l += bf * lhi;
                }
                if c > 0 {
                    l += cf * lmid;
                }
                terms[k] = l;
                lmax = lmax.max(l);
            }
            let sum: f64 = terms[..ln_node.len()]
                .iter()
                .map(|&l| (l - lmax).exp())
                .sum();
            let ll = lmax + sum.ln();
            let sat: f64 = [af, bf, cf]
                .iter()
                .filter(|&&n| n > 0.0)
                .map(|&n| n * (n / f).ln())
                .sum();
            let g2 = (2.0 * (sat - ll)).max(0.0);
            let ln_p = ln_fact[nf] - ln_fact[a] - ln_fact[b] - ln_fact[c] + ll;
            out.push((ln_p, g2));
        }
    }
    let m = out.iter().fold(f64::NEG_INFINITY, |a, x| a.max(x.0));
    if !m.is_finite() {
        return 0.0;
    }
    let (mut sp, mut sg) = (0.0, 0.0);
    for &(lp, g2) in &out {
        let w = (lp - m).exp();
        sp += w;
        sg += w * g2;
    }
    sg / sp
}

/// [`rail_expected_deviance`] for F = 1, with the outcome probabilities of
/// [`rail_stats_single`] (the same likelihood the fit maximises): the outcomes low, high,
/// mid with probability P_k have G² = −2 ln P_k (the saturated term of one frame is 0), so
/// E[G²] = Σ_k P_k·(−2 ln P_k) over the outcomes kept by the rule of the general sum (a rail
/// reached with P < 10⁻¹⁵ left out; `given_rail`: the mid outcome left out and the rest
/// renormalised, the likelier rail kept when both are left out).
fn single_frame_expected_deviance(p: &Pred, given_rail: bool) -> f64 {
    let (plo, phi) = single_frame_rail_probs(p);
    let pm = single_frame_mid_prob(p, plo, phi);
    let mut lo_on = plo >= 1e-15;
    let mut hi_on = phi >= 1e-15;
    if given_rail && !lo_on && !hi_on {
        if plo >= phi {
            lo_on = true;
        } else {
            hi_on = true;
        }
    }
    let mut outcomes: Vec<f64> = Vec::with_capacity(3);
    if !given_rail {
        outcomes.push(pm);
    }
    if lo_on {
        outcomes.push(plo);
    }
    if hi_on {
        outcomes.push(phi);
    }
    let (mut sp, mut sg) = (0.0, 0.0);
    for &pr in &outcomes {
        let g2 = (-2.0 * pr.max(1e-300).ln()).max(0.0);
        sp += pr;
        sg += pr * g2;
    }
    if sp > 0.0 {
        sg / sp
    } else {
        // (every kept outcome underflowed: the likelier rail's own deviance)
        (-2.0 * plo.max(phi).max(1e-300).ln()).max(0.0)
    }
}

/// Memo of [`rail_expected_deviance`] within one block of an evaluation: the pixel-shots of a
/// uniform (e.g. dark) shot share their prediction, so most lookups hit.
#[derive(Default)]
pub(crate) struct ExpectedDevianceCache {
    map: HashMap<[u64; 6], f64>,
}

impl ExpectedDevianceCache {
    /// Entries kept before the memo is cleared (a textured scene has a prediction per pixel).
    const MAX: usize = 1 << 14;

    fn get(&mut self, p: &Pred, f: f64, given_rail: bool) -> f64 {
        let key = [
            p.y.to_bits(),
            p.s2_t.to_bits(),
            p.s2_f.to_bits(),
            p.hi.to_bits(),
            f.to_bits(),
            given_rail as u64,
        ];
        if let Some(&v) = self.map.get(&key) {
            return v;
        }
        if self.map.len() >= Self::MAX {
            self.map.clear();
        }
        let v = rail_expected_deviance(p, f, given_rail);
        self.map.insert(key, v);
        v
    }

    /// The χ² summary's (χ², dof) of a censored pixel-shot: (G², E[G²]).
    pub(crate) fn term(
        &mut self,
        p: &Pred,
        f: f64,
        nlo: f64,
        nhi: f64,
        given_rail: bool,
    ) -> (f64, f64) {
        let rs = rail_stats(p, f, nlo, nhi);
        (rail_deviance(&rs, f, nlo, nhi), self.get(p, f, given_rail))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mismatch::num::norm_cdf;

    /// The plain 24-node quadrature (the implementation before the shortcuts of
    /// [`rail_stats_calc`]): every node's Φ, every logarithm, every exponential.
    fn rail_stats_plain(p: &Pred, f: f64, nlo: f64, nhi: f64) -> RailStat {
        let nmid = f - nlo - nhi;
        let nodes = rail_nodes(p);
        let mut lmax = f64::NEG_INFINITY;
        let mut terms = [0.0f64; 24];
        let mut m1 = 0.0;
        for (k, (w, plo, phi)) in nodes.iter().enumerate() {
            let pm = (1.0 - plo - phi).max(0.0);
            let mut l = 0.0;
            if nlo > 0.0 {
                l += nlo * plo.max(1e-300).ln();
            }
            if nhi > 0.0 {
                l += nhi * phi.max(1e-300).ln();
            }
            if nmid > 0.0 {
                l += nmid * pm.max(1e-300).ln();
            }
            let l = l + w.ln();
            lmax = lmax.max(l);
            terms[k] = l;
            m1 += w * (plo + phi).min(1.0);
        }
        let sum: f64 = terms[..nodes.n].iter().map(|t| (t - lmax).exp()).sum();
        RailStat {
            ll: lmax + sum.ln(),
            mean: f * m1,
        }
    }

    /// Φ beyond ±TAIL is what the shortcuts of `rail_stats_calc` assume, bit for bit: 1 at
    /// x ≥ TAIL (so 1 − Φ = 0), 1 − Φ(x) = 1 and Φ(x) < 2⁻⁵⁴ at x ≤ −TAIL (so 1 − Φ(x) − q
    /// = 1 − q), on a dense grid up to 40 and a geometric one up to 10³⁰⁰.
    #[test]
    fn tail_shortcuts_are_exact() {
        let mut xs: Vec<f64> = (0..=31_000).map(|i| TAIL + i as f64 * 1e-3).collect();
        xs.extend((0..=600).map(|i| 40.0 * 10f64.powf(i as f64 * 0.5)));
        xs.push(f64::INFINITY);
        for &x in &xs {
            assert_eq!(norm_cdf(x), 1.0, "Φ({x})");
            assert_eq!(1.0 - norm_cdf(x), 0.0, "1 − Φ({x})");
            let q = norm_cdf(-x);
            assert!(q < 2f64.powi(-54), "Φ(−{x}) = {q}");
            assert_eq!(1.0 - q, 1.0, "1 − Φ(−{x})");
            for &r in &[0.0, 1e-300, 1e-17, 0.25, 0.5, 0.999_999] {
                assert_eq!((1.0 - q - r).to_bits(), (1.0 - 0.0 - r).to_bits());
            }
        }
    }

    /// `rail_stats_calc` (with its shortcuts) returns the plain quadrature's log-likelihood
    /// bit for bit, and its mean within 4·ε·F, over predictions from the low rail to past
    /// the high one, with and without fixed pattern, and every rail-count pattern.
    #[test]
    fn rail_stats_is_the_plain_quadrature_bit_for_bit() {
        let mut rng = Rng(0x5EED_0023);
        let mut checked = 0usize;
        let mut certain = 0usize;
        for _ in 0..40_000 {
            let hi = if rng.unif() < 0.5 { 4095.0 } else { 255.0 };
            // y anywhere from below 0 to well above hi, often near a rail
            let y = match (rng.u64() % 4) as u8 {
                0 => hi * (1.3 * rng.unif() - 0.15),
                1 => hi + 200.0 * (rng.unif() - 0.3),
                2 => 60.0 * (rng.unif() - 0.3),
                _ => hi + 5000.0 * rng.unif(),
            };
            let s2_t = 10f64.powf(4.0 * rng.unif() - 1.0);
            let s2_f = match rng.u64() % 3 {
                0 => 0.0,
                1 => s2_t * 1e-20,
                _ => 10f64.powf(5.0 * rng.unif() - 2.0),
            };
            let p = Pred {
                y,
                s2_t,
                s2_f,
                hi,
                ..Default::default()
            };
            // (F = 1 has its closed form: `single_frame_rail_stats_is_the_exact_mixture`)
            let nf = 2 + (rng.u64() % 8) as usize;
            let lo = (rng.u64() % (nf as u64 + 1)) as usize;
            let hi_n = (rng.u64() % ((nf - lo) as u64 + 1)) as usize;
            let (f, nlo, nhi) = (nf as f64, lo as f64, hi_n as f64);
            let want = rail_stats_plain(&p, f, nlo, nhi);
            let got = rail_stats_calc(&p, f, nlo, nhi);
            assert_eq!(
                got.ll.to_bits(),
                want.ll.to_bits(),
                "y {y} s2_t {s2_t} s2_f {s2_f} hi {hi} F {f} lo {nlo} hi {nhi}: {} vs {}",
                got.ll,
                want.ll
            );
            assert!(
                (got.mean - want.mean).abs() <= 4.0 * f64::EPSILON * f,
                "mean {} vs {}",
                got.mean,
                want.mean
            );
            checked += 1;
            if want.ll == rail_stats_plain(&Pred { y: hi + 1e9, ..p }, f, 0.0, f).ll {
                certain += 1;
            }
        }
        // the shortcut of fully certain nodes was exercised too
        assert!(checked == 40_000 && certain > 1000, "certain {certain}");
    }

    /// F = 1: the closed form (`rail_stats_single`) is the mixture over the fixed offset
    /// integrated numerically (midpoint rule over ±12 s_f, 40 000 points) to 10⁻⁹ in P
    /// (relative, or 10⁻¹² absolute), for every outcome and predictions from below the low
    /// rail to past the high one, s_f from 0 to 300 s_t; the 24-node quadrature it replaced
    /// misses the same integral by more than 10⁻³ where s_f ≫ s_t (so this test fails on the
    /// old code).
    #[test]
    fn single_frame_rail_stats_is_the_exact_mixture() {
        let mut rng = Rng(0x5EED_0001);
        let mut worst_quadrature = 0f64;
        for case in 0..3000 {
            let hi = if rng.unif() < 0.5 { 4095.0 } else { 255.0 };
            let s2_t = 10f64.powf(3.0 * rng.unif() - 1.0);
            let s2_f = match case % 3 {
                0 => 0.0,
                1 => s2_t * 10f64.powf(2.0 * rng.unif() - 2.0),
                _ => s2_t * 10f64.powf(5.0 * rng.unif()),
            };
            let s = (s2_t + s2_f).sqrt();
            let y = match rng.u64() % 3 {
                0 => 0.5 + 8.0 * s * (rng.unif() - 0.5),
                1 => hi - 0.5 + 8.0 * s * (rng.unif() - 0.5),
                _ => hi * rng.unif(),
            };
            let p = Pred {
                y,
                s2_t,
                s2_f,
                hi,
                ..Default::default()
            };
            // the mixture by the midpoint rule (one node when there is no fixed pattern)
            let (s_t, s_f) = (s2_t.sqrt(), s2_f.sqrt());
            let n = if s_f > 0.0 { 40_000 } else { 1 };
            let (mut plo, mut phi) = (0.0, 0.0);
            for k in 0..n {
                let (z, w) = if n == 1 {
                    (0.0, 1.0)
                } else {
                    let x = -12.0 + 24.0 * (k as f64 + 0.5) / n as f64;
                    (x * s_f, 24.0 / n as f64 * crate::mismatch::num::norm_pdf(x))
                };
                plo += w * norm_cdf((0.5 - y - z) / s_t);
                phi += w * norm_cdf((y + z - (hi - 0.5)) / s_t);
            }
            let pm = 1.0 - plo - phi;
            for (nlo, nhi, want) in [(1.0, 0.0, plo), (0.0, 1.0, phi), (0.0, 0.0, pm)] {
                if want < 1e-250 {
                    continue;
                }
                let got = rail_stats_calc(&p, 1.0, nlo, nhi).ll.exp();
                assert!(
                    (got - want).abs() <= 1e-9 * want + 1e-12,
                    "y {y} s2_t {s2_t} s2_f {s2_f} hi {hi} lo {nlo} hi {nhi}: {got} vs {want}"
                );
                let quad = rail_stats_plain(&p, 1.0, nlo, nhi).ll.exp();
                worst_quadrature = worst_quadrature.max((quad - want).abs());
            }
        }
        assert!(
            worst_quadrature > 1e-3,
            "quadrature error {worst_quadrature}"
        );
    }

    /// A mid-range frame of a prediction far past a rail (an outlier, e.g. a hot pixel) keeps
    /// its tail probability: 20 S below the low threshold P_mid = Φ(−20) − P_hi, where
    /// 1 − P_lo − P_hi is 0 and its logarithm the 10⁻³⁰⁰ clamp (−690.8); likewise above the
    /// high threshold, and in E[G²].
    #[test]
    fn single_frame_mid_probability_far_past_a_rail_keeps_its_tail() {
        use crate::mismatch::num::norm_cdf;
        for (s2_t, s2_f) in [(1.0, 0.0), (0.5, 4.0)] {
            let s = f64::sqrt(s2_t + s2_f);
            for (y, d) in [(0.5 - 20.0 * s, 20.0), (254.5 + 12.0 * s, 12.0)] {
                let p = Pred {
                    y,
                    s2_t,
                    s2_f,
                    hi: 255.0,
                    ..Default::default()
                };
                let want = norm_cdf(-d).ln();
                let got = rail_stats_calc(&p, 1.0, 0.0, 0.0).ll;
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs(),
                    "y {y} S {s}: ln P_mid {got} vs {want}"
                );
            }
        }
    }

    /// Without fixed pattern the rail counts are multinomial: the deviance must equal the
    /// closed-form binomial deviance 2[n ln(n/(Fp)) + (F−n) ln((F−n)/(F(1−p)))] with
    /// p = Φ((0.5 − y)/σ), and stay of order ln(1/(Fp)) for a rare rail frame, where
    /// Pearson's (n − Fp)²/(Fp(1−p)) explodes (the issue-6 χ² inconsistency).
    #[test]
    fn rail_deviance_is_binomial_deviance_and_bounded_for_rare_events() {
        let f = 16.0;
        for &(y, n) in &[(0.3, 5.0), (2.0, 1.0), (4.5, 1.0), (1.0, 16.0), (0.0, 0.0)] {
            let p = Pred {
                y,
                s2_t: 1.0,
                s2_f: 0.0,
                hi: 255.0,
                ..Default::default()
            };
            let rs = rail_stats(&p, f, n, 0.0);
            let q = norm_cdf(0.5 - y);
            let term = |k: f64, pr: f64| {
                if k > 0.0 {
                    k * (k / (f * pr)).ln()
                } else {
                    0.0
                }
            };
            let want = 2.0 * (term(n, q) + term(f - n, 1.0 - q));
            let got = rail_deviance(&rs, f, n, 0.0);
            assert!(
                (got - want).abs() < 1e-6 * want.max(1.0),
                "y {y} n {n}: deviance {got} vs closed form {want}"
            );
            assert!(got >= 0.0);
            if y == 4.5 {
                let pearson = (n - f * q).powi(2) / (f * q * (1.0 - q));
                assert!(pearson > 100.0 * got, "pearson {pearson} deviance {got}");
            }
        }
    }

    /// SplitMix64: a fixed-seed generator for the simulations below.
    struct Rng(u64);

    impl Rng {
        fn u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn unif(&mut self) -> f64 {
            ((self.u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.unif(), self.unif());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// A dark prediction whose per-frame probability of the low rail is `p_lo` at zero fixed
    /// offset (temporal σ 1 DN, fixed-pattern σ `s_f`).
    fn dark_pred(p_lo: f64, s_f: f64) -> Pred {
        use statrs::distribution::{ContinuousCDF, Normal};
        let q = Normal::new(0.0, 1.0).unwrap().inverse_cdf(p_lo);
        Pred {
            y: 0.5 - q,
            s2_t: 1.0,
            s2_f: s_f * s_f,
            hi: 255.0,
            ..Default::default()
        }
    }

    /// Rail counts of one pixel-shot drawn from the model: a fixed offset z ~ N(0, s_f²) per
    /// pixel-shot, then F independent frames.
    fn draw(rng: &mut Rng, p: &Pred, f: usize) -> (f64, f64) {
        let (s_t, s_f) = (p.s2_t.sqrt(), p.s2_f.sqrt());
        let y = p.y + s_f * rng.normal();
        let plo = norm_cdf((0.5 - y) / s_t);
        let phi = 1.0 - norm_cdf((p.hi - 0.5 - y) / s_t);
        let (mut lo, mut hi) = (0.0, 0.0);
        for _ in 0..f {
            let u = rng.unif();
            if u < plo {
                lo += 1.0;
            } else if u > 1.0 - phi {
                hi += 1.0;
            }
        }
        (lo, hi)
    }

    /// Without fixed pattern E[G²] is the binomial sum Σ_n C(F,n) pⁿ(1−p)^(F−n) G²(n).
    #[test]
    fn rail_expected_deviance_is_the_binomial_expectation() {
        for &f in &[1usize, 2, 4, 8, 16] {
            for &p in &[1e-9, 1e-3, 0.02, 0.3, 0.5, 0.9, 0.999] {
                let ff = f as f64;
                let g2 = |n: f64| {
                    let t = |k: f64, pr: f64| {
                        if k > 0.0 {
                            k * (k / (ff * pr)).ln()
                        } else {
                            0.0
                        }
                    };
                    2.0 * (t(n, p) + t(ff - n, 1.0 - p))
                };
                let mut want = 0.0;
                let mut want_given = (0.0, 0.0);
                let mut c = 1.0;
                for n in 0..=f {
                    if n > 0 {
                        c *= (f - n + 1) as f64 / n as f64;
                    }
                    let pr = c * p.powi(n as i32) * (1.0 - p).powi((f - n) as i32);
                    want += pr * g2(n as f64);
                    if n > 0 {
                        want_given.0 += pr * g2(n as f64);
                        want_given.1 += pr;
                    }
                }
                let want_given = want_given.0 / want_given.1;
                let pred = dark_pred(p, 0.0);
                let got = rail_expected_deviance(&pred, ff, false);
                let got_given = rail_expected_deviance(&pred, ff, true);
                let tol = |w: f64| 1e-7 * w.max(1e-6) + 1e-12;
                assert!(
                    (got - want).abs() < tol(want),
                    "F {f} p {p}: E[G²] {got} vs {want}"
                );
                assert!(
                    (got_given - want_given).abs() < tol(want_given),
                    "F {f} p {p}: E[G² | rail] {got_given} vs {want_given}"
                );
            }
        }
    }

    /// E[G²] (including the fixed-pattern mixture and the conditional form) agrees with the
    /// Monte-Carlo mean of G² over counts drawn from the model.
    #[test]
    fn rail_expected_deviance_matches_monte_carlo() {
        let mut rng = Rng(0x5EED_0006);
        let n = 200_000;
        for &(p_lo, s_f, f, given) in &[
            (0.01, 0.0, 2usize, false),
            (0.2, 0.0, 4, false),
            (0.05, 0.0, 8, false),
            (0.003, 0.5, 4, false),
            (0.05, 1.0, 8, false),
            (0.3, 2.0, 2, false),
            (0.01, 0.7, 4, true),
            (0.05, 1.0, 1, false),
            (0.02, 3.0, 1, false),
            (0.01, 0.7, 1, true),
        ] {
            let pred = dark_pred(p_lo, s_f);
            let want = rail_expected_deviance(&pred, f as f64, given);
            let mut cache = ExpectedDevianceCache::default();
            let (mut s1, mut s2, mut k) = (0.0, 0.0, 0.0);
            while k < n as f64 {
                let (lo, hi) = draw(&mut rng, &pred, f);
                if given && lo + hi == 0.0 {
                    continue;
                }
                let (g2, e) = cache.term(&pred, f as f64, lo, hi, given);
                assert_eq!(e, want);
                s1 += g2;
                s2 += g2 * g2;
                k += 1.0;
            }
            let mean = s1 / k;
            // (F = 1 given a rail count: only the low rail is reachable here, so G² is one
            // constant and its scatter is rounding, possibly below 0: compare to 1e-9.)
            let se = ((s2 / k - mean * mean).max(0.0) / k).sqrt();
            assert!(
                (mean - want).abs() < 4.0 * se + 1e-9 * want.abs(),
                "p {p_lo} s_f {s_f} F {f} given {given}: MC {mean} ± {se} vs E[G²] {want}"
            );
        }
    }

    /// Under the model the summary is calibrated for any sparsity: Σ G² / Σ E[G²] ≈ 1 over
    /// thousands of rail-count terms with per-frame probabilities 10⁻³…0.5 (z-test with the
    /// terms' own scatter).
    #[test]
    fn chi2_per_dof_of_sparse_rail_counts_is_one_under_the_model() {
        let mut rng = Rng(0xF1EA_0003);
        let mut cache = ExpectedDevianceCache::default();
        for &f in &[2usize, 4, 8] {
            for &s_f in &[0.0, 0.8] {
                let (mut chi2, mut dof, mut var) = (0.0, 0.0, 0.0);
                for i in 0..6000 {
                    // log-uniform 10⁻³ … 0.5, on a grid so that the memo is exercised
                    let p = 1e-3 * 500f64.powf((i % 60) as f64 / 59.0);
                    let pred = dark_pred(p, s_f);
                    let (lo, hi) = draw(&mut rng, &pred, f);
                    let (g2, e) = cache.term(&pred, f as f64, lo, hi, false);
                    chi2 += g2;
                    dof += e;
                    var += (g2 - e) * (g2 - e);
                }
                let z = (chi2 - dof) / var.sqrt();
                assert!(
                    z.abs() < 4.0,
                    "F {f} s_f {s_f}: χ²/dof {:.4} (χ² {chi2:.1}, dof {dof:.1}, z {z:.2})",
                    chi2 / dof
                );
            }
        }
    }

    /// The summary of counts drawn from `truth` and compared with the model `truth × k`
    /// (per-frame rail probability): new (χ², dof), −lnL, and the old summary's (χ², dof)
    /// (terms whose minority outcome is expected in under half a frame and not seen skipped,
    /// 1 dof per kept term).
    struct Summary {
        chi2: f64,
        dof: f64,
        nll: f64,
        old_chi2: f64,
        old_dof: f64,
    }

    impl Summary {
        fn r(&self) -> f64 {
            self.chi2 / self.dof
        }
        fn old_r(&self) -> f64 {
            self.old_chi2 / self.old_dof
        }
    }

    fn summarise(k: f64, f: usize, seed: u64) -> Summary {
        let mut rng = Rng(seed);
        let mut cache = ExpectedDevianceCache::default();
        let ff = f as f64;
        let mut s = Summary {
            chi2: 0.0,
            dof: 0.0,
            nll: 0.0,
            old_chi2: 0.0,
            old_dof: 0.0,
        };
        for i in 0..20_000 {
            let p = 1e-3 * 100f64.powf((i % 40) as f64 / 39.0);
            let (lo, hi) = draw(&mut rng, &dark_pred(p, 0.0), f);
            let model = dark_pred((k * p).min(0.9), 0.0);
            let (g2, e) = cache.term(&model, ff, lo, hi, false);
            s.chi2 += g2;
            s.dof += e;
            s.nll -= rail_stats(&model, ff, lo, hi).ll;
            let mean = ff * norm_cdf(0.5 - model.y);
            let q = mean.min(ff - mean);
            let minority = if mean > 0.5 * ff { ff - lo } else { lo };
            if !(q < 0.5 && minority == 0.0) {
                s.old_chi2 += g2;
                s.old_dof += 1.0;
            }
        }
        s
    }

    /// Issue 6: under a wrong model the summary and the likelihood must agree. Counts drawn
    /// with per-frame rail probabilities 10⁻³…0.1 (F = 2, 4). At the truth χ²/dof ≈ 1 (the
    /// old summary: ≈ 4, it keeps only the sparse terms with a rail frame). A model that
    /// under-predicts the rail frames has χ²/dof ≫ 1, and moving it towards the truth lowers
    /// −lnL and χ²/dof together. One that over-predicts them (the Flea3 direction: the
    /// believed camera expects non-zero frames the data do not have) is off too (below 1 at
    /// F = 2, either side at F = 4); there moving towards the truth lowers χ² by exactly
    /// 2Δ(−lnL) (every term kept, saturated term fixed), while the old summary rose — but
    /// χ²/dof is not monotone on the way, since the model's own E[G²] moves as much as the
    /// misfit for counts this sparse.
    #[test]
    fn chi2_per_dof_moves_with_the_likelihood_under_a_wrong_model() {
        for &f in &[2usize, 4] {
            let seed = 0xBAD0_0000 + f as u64;
            let t = summarise(1.0, f, seed);
            let [a, b, c, d] = [0.2, 0.5, 5.0, 2.0].map(|k| summarise(k, f, seed));
            eprintln!(
                "F {f}: χ²/dof ×0.2 {:.3} ×0.5 {:.3} ×1 {:.3} ×2 {:.3} ×5 {:.3}; old ×5 {:.3} ×2 {:.3} ×1 {:.3}",
                a.r(), b.r(), t.r(), d.r(), c.r(), c.old_r(), d.old_r(), t.old_r()
            );
            let z_true = (t.chi2 - t.dof) / (2.0 * t.dof).sqrt();
            assert!(
                z_true.abs() < 4.0 && (t.r() - 1.0).abs() < 0.05,
                "F {f}: χ²/dof {} at the truth",
                t.r()
            );
            // Under-predicted rail frames.
            assert!(
                a.r() > 1.5,
                "F {f}: χ²/dof {} with rails under-predicted ×5",
                a.r()
            );
            assert!(
                a.nll > b.nll && b.nll > t.nll,
                "F {f}: −lnL {} {} {}",
                a.nll,
                b.nll,
                t.nll
            );
            assert!(
                a.r() > b.r() && b.r() > t.r(),
                "F {f}: χ²/dof {} {} {}",
                a.r(),
                b.r(),
                t.r()
            );
            // Over-predicted rail frames.
            assert!(
                (c.r() - 1.0).abs() > 0.1 && (d.r() - 1.0).abs() > 0.1,
                "F {f}: χ²/dof {} {}",
                c.r(),
                d.r()
            );
            assert!(
                c.nll > d.nll && d.nll > t.nll,
                "F {f}: −lnL {} {} {}",
                c.nll,
                d.nll,
                t.nll
            );
            for (x, y) in [(&c, &d), (&d, &t), (&a, &b), (&b, &t)] {
                let (dchi2, dnll) = (x.chi2 - y.chi2, x.nll - y.nll);
                assert!(
                    (dchi2 - 2.0 * dnll).abs() < 1e-6 * dchi2.abs(),
                    "F {f}: Δχ² {dchi2} vs 2Δ(−lnL) {dnll}"
                );
            }
            // The old summary on the same counts: far from 1 at the truth, and higher there
            // than for the ×5 over-predicting model.
            assert!(
                t.old_r() > 1.5 && c.old_r() < t.old_r(),
                "F {f}: old χ²/dof {} {}",
                c.old_r(),
                t.old_r()
            );
        }
    }
}
