//! Fit and select: every candidate fitted alone against the current model, the best accepted
//! when its BIC improves by more than the threshold (ΔBIC = k ln n − 2 ΔlnL), the accepted
//! ones refitted jointly, and again until nothing improves significantly (Schwarz, "Estimating
//! the dimension of a model", Ann. Statist. 6, 1978; Kass & Raftery, JASA 90, 1995: ΔBIC < −10
//! is very strong evidence). When an alike effect explains the data nearly as well, the
//! diagnosis says it cannot tell them apart instead of guessing.
use super::candidates::{fit_effect, fit_effect_warm, magnitude, Evidence, FitOutcome, Warm};
use super::effects::{alike, Effect};
use super::identify::{identifiability, Identifiability};
use super::like::{Ctx, Eval, RowSel};
use super::model::ModelState;

/// Settings of the selection.
#[derive(Debug, Clone)]
pub struct SelectOptions {
    /// Accept a candidate when ΔBIC < −threshold.
    pub bic_threshold: f64,
    /// Alike candidates whose ΔBIC lie within this margin cannot be told apart.
    pub alike_margin: f64,
    /// Least share of the current model's lack of fit (|χ² − dof| on the fit rows) a
    /// candidate must remove to be accepted (0: off).
    pub min_misfit_share: f64,
    /// Least reduction of the lack of fit |χ² − dof| a candidate must bring, in standard
    /// deviations of the χ² of the fit rows (√(2·dof)): the effect must show in the
    /// goodness of fit.
    pub min_drop_sigma: f64,
    /// Most acceptance rounds.
    pub max_rounds: usize,
    /// Effects to consider (default all).
    pub effects: Vec<Effect>,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions {
            bic_threshold: 10.0,
            alike_margin: 10.0,
            min_misfit_share: 0.0,
            min_drop_sigma: 3.0,
            max_rounds: 8,
            effects: Effect::ALL.to_vec(),
        }
    }
}

/// One candidate in one round.
#[derive(Debug, Clone)]
pub struct CandidateRow {
    /// The effect.
    pub effect: Effect,
    /// ΔBIC against the model of that round (None when not testable).
    pub delta_bic: Option<f64>,
    /// Δ log-likelihood.
    pub delta_logl: f64,
    /// Parameters.
    pub k: usize,
    /// Magnitude of the candidate's fit (effects.md units).
    pub magnitude: f64,
    /// Why it could not be tested.
    pub not_testable: Option<String>,
}

/// An accepted effect.
#[derive(Debug, Clone)]
pub struct Finding {
    /// The effect.
    pub effect: Effect,
    /// ΔBIC when accepted.
    pub delta_bic: f64,
    /// Δ log-likelihood when accepted.
    pub delta_logl: f64,
    /// Parameters.
    pub k: usize,
    /// Round in which it was accepted.
    pub round: usize,
    /// Fit (all pixels) after it was accepted and the model refitted.
    pub after: Eval,
    /// The model just after it was accepted (before later findings).
    pub state_after: ModelState,
    /// The model just before.
    pub state_before: ModelState,
    /// The other candidates of that round, (effect, ΔBIC), best first.
    pub alternatives: Vec<(Effect, f64)>,
    /// Part of an undecided group: kept in the fitted camera, not reported as a finding.
    pub undecided: bool,
}

/// Effects the set cannot tell apart.
#[derive(Debug, Clone)]
pub struct Undecided {
    /// The effects (the first is the one kept in the fitted camera).
    pub effects: Vec<Effect>,
    /// Their ΔBIC (NaN for a look-alike the shots cannot tell from the baseline: not fitted).
    pub delta_bic: Vec<f64>,
    /// Their magnitudes (NaN where not fitted).
    pub magnitudes: Vec<f64>,
    /// Evidence that would separate them.
    pub separated_by: Vec<String>,
    /// Round.
    pub round: usize,
}

/// The outcome of the selection.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Findings in order of acceptance.
    pub findings: Vec<Finding>,
    /// Undecided groups.
    pub undecided: Vec<Undecided>,
    /// Effects that could not be tested, with the reason.
    pub not_testable: Vec<(Effect, String)>,
    /// Candidate table of every round.
    pub rounds: Vec<Vec<CandidateRow>>,
    /// The final model.
    pub state: ModelState,
    /// Observations behind the BIC penalty (fit rows).
    pub n_obs: f64,
    /// The identifiability check of the candidates (Fisher information at the believed
    /// model); those it marks `cannot_tell` were not fitted.
    pub identifiability: Vec<Identifiability>,
}

fn neg_ll(ctx: &Ctx, st: &ModelState) -> Result<f64, String> {
    Ok(-ctx.evaluate(st, RowSel::Fit)?.logl)
}

/// Lack of fit of a model: |χ² − dof| on the fit rows.
fn misfit_abs(ctx: &Ctx, st: &ModelState) -> Result<f64, String> {
    let e = ctx.evaluate(st, RowSel::Fit)?;
    Ok((e.chi2 - e.dof).abs())
}

/// The goodness of fit of a model on the fit rows: χ²/dof, dof, and the share of the
/// pixel-shots compared through their rail counts (censored).
fn fit_summary(ctx: &Ctx, st: &ModelState) -> Result<(f64, f64, f64), String> {
    let e = ctx.evaluate(st, RowSel::Fit)?;
    let cens: f64 = e.per_sc.iter().map(|x| x.censored).sum();
    let unc: f64 = e.per_sc.iter().map(|x| x.n).sum();
    let dof = e.dof.max(1.0);
    Ok((e.chi2 / dof, dof, cens / (cens + unc).max(1.0)))
}

/// Most coordinate sweeps of the joint refit.
const JOINT_SWEEPS: usize = 8;

/// Refits the effects in `model` one at a time (sweeps until converged), each from its
/// current values.
fn joint_refit(
    ctx: &Ctx,
    ev: &Evidence,
    model: &[Effect],
    mut state: ModelState,
) -> Result<ModelState, String> {
    if model.len() < 2 {
        return Ok(state);
    }
    let mut f = neg_ll(ctx, &state)?;
    // Correlated effects (a fall-off and glare both change the corners relative to the
    // centre) need several coordinate sweeps; stop when a sweep gains < 0.5 in lnL.
    for _ in 0..JOINT_SWEEPS {
        let f_start = f;
        for &e in model {
            if let FitOutcome::Fitted {
                state: st, neg_ll, ..
            } = fit_effect(ctx, ev, e, &state)?
            {
                if neg_ll < f {
                    state = st;
                    f = neg_ll;
                }
            }
        }
        if f_start - f < 0.5 {
            break;
        }
    }
    Ok(state)
}

/// `state` with the parameters of `e` put back to their believed values.
fn without_effect(e: Effect, state: &ModelState, believed: &ModelState) -> ModelState {
    let mut st = state.clone();
    let (s, b) = (&mut st.sensor, &believed.sensor);
    match e {
        Effect::ExposureScale => st.exposure_factor = believed.exposure_factor,
        Effect::ConversionGain => s.conversion_gain_v_per_e = b.conversion_gain_v_per_e,
        Effect::BlackLevel => s.black_level_dn = b.black_level_dn,
        Effect::DarkCurrent => s.dark_voltage_v_per_s = b.dark_voltage_v_per_s,
        Effect::ReadNoise => s.read_noise_v = b.read_noise_v,
        Effect::Dsnu => s.dsnu_sigma_v = b.dsnu_sigma_v,
        Effect::Prnu => s.prnu_sigma_percent = b.prnu_sigma_percent,
        Effect::ColumnFpn => s.column_fpn = b.column_fpn,
        Effect::HotPixels => s.effects.hot_pixels = b.effects.hot_pixels,
        Effect::Nonlinearity => s.effects.nonlinearity = b.effects.nonlinearity,
        Effect::FullWell => s.well_capacity_e = b.well_capacity_e,
        Effect::Crosstalk => s.effects.crosstalk = b.effects.crosstalk,
        Effect::RelativeIllumination => st.rates.falloff = believed.rates.falloff.clone(),
        Effect::VeilingGlare => st.rates.glare_fraction = believed.rates.glare_fraction,
        Effect::Defocus => st.rates.defocus_sigma_um = believed.rates.defocus_sigma_um,
        Effect::Distortion => st.rates.distortion = believed.rates.distortion,
        Effect::LateralColor => st.rates.lateral_color_um = believed.rates.lateral_color_um,
        Effect::IrLeakage => st.rates.ir_leakage = believed.rates.ir_leakage.clone(),
        Effect::QeShift => st.rates.qe_shift_nm = believed.rates.qe_shift_nm.clone(),
        Effect::RowNoise => s.effects.row_noise = b.effects.row_noise,
        Effect::Rtn => s.effects.rtn = b.effects.rtn,
        Effect::BlackLevelDrift => s.effects.black_level_drift = b.effects.black_level_drift,
        Effect::DarkTemperature => s.effects.dark_temperature = b.effects.dark_temperature,
    }
    st
}

/// Backward elimination (Efroymson's stepwise regression, applied to BIC): after the joint
/// refit, an accepted effect whose removal (the others refitted without it) no longer worsens
/// the criterion by more than the threshold is no longer supported by the data — it had
/// absorbed part of an effect found later — and leaves the model. The weakest such effect
/// goes first; repeat until every remaining effect is needed. Returns the dropped effects.
#[allow(clippy::too_many_arguments)]
fn backward_eliminate(
    ctx: &Ctx,
    ev: &Evidence,
    believed: &ModelState,
    model: &mut Vec<Effect>,
    ks: &mut Vec<usize>,
    state: &mut ModelState,
    f_cur: &mut f64,
    ln_n: f64,
    threshold: f64,
    keep: Effect,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<Effect>, String> {
    let mut dropped = Vec::new();
    while model.len() >= 2 {
        let mut weakest: Option<(usize, f64, ModelState, f64)> = None;
        for (i, &e) in model.iter().enumerate() {
            if e == keep {
                continue;
            }
            progress(&format!("backward: without {}", e.id()));
            let rest: Vec<Effect> = model.iter().copied().filter(|&x| x != e).collect();
            let mut st = without_effect(e, state, believed);
            if rest.len() == 1 {
                if let FitOutcome::Fitted { state: s2, .. } = fit_effect(ctx, ev, rest[0], &st)? {
                    if neg_ll(ctx, &s2)? < neg_ll(ctx, &st)? {
                        st = s2;
                    }
                }
            } else {
                st = joint_refit(ctx, ev, &rest, st)?;
            }
            let f_without = neg_ll(ctx, &st)?;
            // ΔBIC of putting e back into the model without it.
            let dbic = ks[i] as f64 * ln_n - 2.0 * (f_without - *f_cur);
            if dbic > -threshold && weakest.as_ref().is_none_or(|w| dbic > w.1) {
                weakest = Some((i, dbic, st, f_without));
            }
        }
        let Some((i, _, st, f)) = weakest else {
            break;
        };
        dropped.push(model.remove(i));
        ks.remove(i);
        *state = st;
        *f_cur = f;
    }
    Ok(dropped)
}

/// Runs the greedy selection from the believed model.
pub(crate) fn select(
    ctx: &Ctx,
    believed: &ModelState,
    opts: &SelectOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Selection, String> {
    let ev = Evidence::new(ctx, believed);
    progress("identifiability (Fisher information of the shots)");
    let identifiability = identifiability(ctx, &ev, believed, &opts.effects)?;
    let mut state = believed.clone();
    let first = ctx.evaluate(&state, RowSel::Fit)?;
    let n_obs = first.dof.max(2.0);
    let ln_n = n_obs.ln();
    let mut f_cur = -first.logl;
    let mut model: Vec<Effect> = Vec::new();
    let mut ks: Vec<usize> = Vec::new();
    let mut dropped_ever: Vec<Effect> = Vec::new();
    let mut findings: Vec<Finding> = Vec::new();
    let mut undecided: Vec<Undecided> = Vec::new();
    let mut not_testable: Vec<(Effect, String)> = Vec::new();
    let mut rounds = Vec::new();
    // Each candidate's 1-D search optimum of the last round: the next round's fit starts
    // there (the model changed by one effect; a local search from it converges to the same
    // tolerance in about half the evaluations of the grid scan, issue 23). Round 1 scans.
    let mut warm_x: Vec<(Effect, f64)> = Vec::new();
    for round in 0..opts.max_rounds {
        let mut rows: Vec<CandidateRow> = Vec::new();
        let mut fits: Vec<(Effect, ModelState, usize, f64)> = Vec::new();
        for &e in &opts.effects {
            if model.contains(&e)
                || dropped_ever.contains(&e)
                || not_testable.iter().any(|x| x.0 == e)
                || identifiability
                    .iter()
                    .any(|x| x.effect == e && x.cannot_tell)
            {
                continue;
            }
            progress(&format!("round {}: {}", round + 1, e.id()));
            let warm = Warm {
                prev: warm_x.iter().find(|x| x.0 == e).map(|x| x.1),
                ..Warm::default()
            };
            let outcome = fit_effect_warm(ctx, &ev, e, &state, &warm)?;
            if let Some(x) = warm.found.get() {
                warm_x.retain(|w| w.0 != e);
                warm_x.push((e, x));
            }
            match outcome {
                FitOutcome::NotTestable(why) => {
                    not_testable.push((e, why.clone()));
                    rows.push(CandidateRow {
                        effect: e,
                        delta_bic: None,
                        delta_logl: 0.0,
                        k: 0,
                        magnitude: f64::NAN,
                        not_testable: Some(why),
                    });
                }
                FitOutcome::Fitted {
                    state: st,
                    neg_ll,
                    k,
                } => {
                    let dl = (f_cur - neg_ll).max(0.0);
                    let dbic = k as f64 * ln_n - 2.0 * dl;
                    rows.push(CandidateRow {
                        effect: e,
                        delta_bic: Some(dbic),
                        delta_logl: dl,
                        k,
                        magnitude: magnitude(e, &st, believed),
                        not_testable: None,
                    });
                    fits.push((e, st, k, dbic));
                }
            }
        }
        rows.sort_by(|a, b| {
            a.delta_bic
                .unwrap_or(f64::INFINITY)
                .total_cmp(&b.delta_bic.unwrap_or(f64::INFINITY))
        });
        rounds.push(rows.clone());
        fits.sort_by(|a, b| a.3.total_cmp(&b.3));
        let Some((best, best_state, k, dbic)) = fits.first().cloned() else {
            break;
        };
        if dbic > -opts.bic_threshold {
            break;
        }
        // Misfit share: the fitted forms are approximations of the true shapes (a tanh
        // nonlinearity, a two-circle vignetting, … seen through a quadratic, a polynomial), so
        // once an effect is found a systematic residual of its form error remains, and with
        // 10⁴–10⁵ data terms any extra free parameter projects onto it with ΔlnL far above
        // the BIC penalty (which only guards against pure noise). A candidate that explains
        // only a small share of the remaining lack of fit is such a projection, not a cause.
        // Likewise a drop of 2ΔlnL within the noise of the fit's overall χ² (σ = √(2·dof)) is
        // an effect the goodness of fit cannot see: the model already explains the recording.
        // The improvement is the larger of the deviance drop 2ΔlnL and the χ² the candidate
        // removes from the lack of fit, |χ² − dof| before minus after (a variance term that
        // overshoots gets no credit for pushing χ² below dof). For a mean term the two agree;
        // they differ for variance terms and censored data: 2ΔlnL undercounts random-effect
        // terms (column offsets on the below-noise set: 2ΔlnL ≈ 900, χ² drop ≈ 6 300), the χ²
        // drop undercounts light added to dark regions (glare after a fall-off: 2ΔlnL ≈ 1 690,
        // χ² drop ≈ 580).
        let lack_before = misfit_abs(ctx, &state)?;
        let share_needed =
            (opts.min_misfit_share * lack_before).max(opts.min_drop_sigma * (2.0 * n_obs).sqrt());
        let dl_best = (dbic - k as f64 * ln_n) / -2.0;
        let gain = (lack_before - misfit_abs(ctx, &best_state)?).max(2.0 * dl_best);
        if gain < share_needed {
            progress(&format!(
                "round {}: {} brings χ² closer to dof by {:.1}, needs {:.1}: stop",
                round + 1,
                best.id(),
                gain,
                share_needed
            ));
            break;
        }
        // Censored-dominated data (e.g. 8-bit darks at the black rail): the rail
        // counts are sparse, 2ΔlnL there is large for any shift of the per-frame rail
        // probabilities, and the χ² summary's dof (the model's own expected deviance) moves
        // with the model. A finding must then also bring χ²/dof closer to 1 (within the noise
        // of χ²/dof, min_drop_sigma·√(2/dof)): an effect that the likelihood prefers but that
        // leaves the recording worse explained is not accepted.
        let (r_before, _, cens_share) = fit_summary(ctx, &state)?;
        let (r_after, dof_after, _) = fit_summary(ctx, &best_state)?;
        let worse = (r_after - 1.0).abs() - (r_before - 1.0).abs();
        if cens_share > 0.5 && worse > opts.min_drop_sigma * (2.0 / dof_after).sqrt() {
            progress(&format!(
                "round {}: {} moves χ²/dof from {:.3} to {:.3} on censored data: stop",
                round + 1,
                best.id(),
                r_before,
                r_after
            ));
            break;
        }
        let alternatives: Vec<(Effect, f64)> = fits.iter().skip(1).map(|x| (x.0, x.3)).collect();
        // An effect left undecided earlier and still needed now: both were present.
        let partners: Vec<(Effect, f64, ModelState)> = fits
            .iter()
            .skip(1)
            .filter(|x| {
                alike(best, x.0).is_some()
                    && x.3 < -opts.bic_threshold
                    && x.3 - dbic < opts.alike_margin
                    && misfit_abs(ctx, &x.1).is_ok_and(|m| {
                        (lack_before - m).max(x.2 as f64 * ln_n - x.3) >= share_needed
                    })
            })
            .map(|x| (x.0, x.3, x.1.clone()))
            .collect();
        // An exposure-scale winner whose look-alike partner the identifiability check marked
        // cannot-tell: that partner changes the frames only as light does (on flats veiling
        // glare, QE shift, IR leakage are exposure scales), so the shots cannot tell it from this
        // winner either. The partner was not fitted (no ΔBIC, no magnitude); the pair is
        // undecided, never a finding. (Only exposure: a cannot-tell light effect is not
        // degenerate with black level or gain when darks or photon transfer separate those.)
        let blind: Vec<Effect> = if best == Effect::ExposureScale {
            identifiability
                .iter()
                .filter(|x| x.cannot_tell && alike(best, x.effect).is_some())
                .filter(|x| !partners.iter().any(|p| p.0 == x.effect))
                .map(|x| x.effect)
                .collect()
        } else {
            Vec::new()
        };
        // Relative illumination seen only through structured targets could be the scene's own
        // shading: without a uniform flat the set cannot tell.
        let scene_content = best == Effect::RelativeIllumination && !ev.uniform_light;
        let before = state.clone();
        let dl = (dbic - k as f64 * ln_n) / -2.0;
        state = best_state;
        model.push(best);
        ks.push(k);
        state = joint_refit(ctx, &ev, &model, state)?;
        f_cur = neg_ll(ctx, &state)?;
        let dropped = backward_eliminate(
            ctx,
            &ev,
            believed,
            &mut model,
            &mut ks,
            &mut state,
            &mut f_cur,
            ln_n,
            opts.bic_threshold,
            best,
            progress,
        )?;
        for e in &dropped {
            findings.retain(|f| f.effect != *e);
            undecided.retain(|u| u.effects[0] != *e);
            dropped_ever.push(*e);
        }
        let after = ctx.evaluate(&state, RowSel::All)?;
        if !partners.is_empty() || scene_content || !blind.is_empty() {
            let mut effects = vec![best];
            let mut dbics = vec![dbic];
            let mut mags = vec![magnitude(best, &state, believed)];
            let mut sep = Vec::new();
            for (e, b, st) in &partners {
                effects.push(*e);
                dbics.push(*b);
                mags.push(magnitude(*e, st, believed));
                sep.push(alike(best, *e).expect("alike").separated_by.to_string());
            }
            for e in &blind {
                effects.push(*e);
                dbics.push(f64::NAN);
                mags.push(f64::NAN);
                sep.push(alike(best, *e).expect("alike").separated_by.to_string());
            }
            if scene_content {
                sep.push("a uniform flat-field shot: seen only on structured targets, a fall-off towards the corners could be the scene's own shading (relative illumination vs scene content)".to_string());
            }
            undecided.push(Undecided {
                effects,
                delta_bic: dbics,
                magnitudes: mags,
                separated_by: sep,
                round,
            });
            // Kept in the model (the fitted camera must reproduce the recording) but not
            // reported as a finding.
            findings.push(Finding {
                effect: best,
                delta_bic: dbic,
                delta_logl: dl,
                k,
                round,
                after,
                state_after: state.clone(),
                state_before: before,
                alternatives,
                undecided: true,
            });
            continue;
        }
        // A partner of an earlier undecided group that is needed on top of it: both effects
        // are present, so the group becomes two findings.
        if let Some(pos) = undecided
            .iter()
            .position(|u| u.effects[1..].contains(&best))
        {
            let u = undecided.remove(pos);
            if let Some(f) = findings.iter_mut().find(|f| f.effect == u.effects[0]) {
                f.undecided = false;
            }
        }
        findings.push(Finding {
            effect: best,
            delta_bic: dbic,
            delta_logl: dl,
            k,
            round,
            after,
            state_after: state.clone(),
            state_before: before,
            alternatives,
            undecided: false,
        });
    }
    Ok(Selection {
        findings,
        undecided,
        not_testable,
        rounds,
        state,
        n_obs,
        identifiability,
    })
}

impl Selection {
    /// Findings that are reported (not part of an undecided group).
    pub fn reported(&self) -> impl Iterator<Item = &Finding> {
        self.findings.iter().filter(|f| !f.undecided)
    }
}
