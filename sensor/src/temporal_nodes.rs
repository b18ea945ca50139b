//! Per-row time integration of a scene that changes during the exposure (objects and camera
//! moving, an animated glTF scene), sampled at equally spaced time nodes.
//!
//! Row r collects `(1/T) ∫_{t_r}^{t_r+T} m(t) R(t) dt` (the electronic rolling shutter's
//! window, [`crate::temporal`]; m the light's normalised modulation) where R(t) is the electron
//! rate of the scene as it is at time t. R is known at nodes `t_k = t₀ + k·Δt` (one render per
//! node) and taken as the piecewise-linear interpolant between them,
//! `R(t) = Σ_k φ_k(t) R(t_k)` with φ_k the hat function of node k; the integral of each hat
//! against the (piecewise-constant) modulation is exact, so row r's rate is
//! `Σ_k w_rk R(t_k)` with
//! `w_rk = (1/T) Σ_pieces level · ∫_piece φ_k(t) dt` (trapezoidal product integration,
//! Davis & Rabinowitz, "Methods of Numerical Integration", 2nd ed., 1984, §2.5). For a steady
//! light the weights of a row sum to 1; for a PWM light to the window's light fraction
//! ([`crate::PwmLight::window_fraction`]). The only approximation is the interpolation of R
//! in time: a measure linear in the image (an edge or bar centroid) is interpolated exactly
//! for a constant image velocity, and the error elsewhere is O(Δt²·R'') (a pixel that an
//! edge crosses within one Δt).
use crate::{ElectronRate, TimeModel};

/// Equally spaced time nodes `t_k = start_s + k · step_s`, k = 0 … count − 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeNodes {
    /// Time of the first node (s).
    pub start_s: f64,
    /// Spacing (s), > 0.
    pub step_s: f64,
    /// Number of nodes, ≥ 2.
    pub count: usize,
}

impl TimeNodes {
    /// The fewest nodes of spacing `step_s` from `t0_s` that reach `t1_s` (at least two).
    pub fn covering(t0_s: f64, t1_s: f64, step_s: f64) -> Result<TimeNodes, String> {
        if !(step_s.is_finite() && step_s > 0.0) {
            return Err(format!(
                "time_step_s = {step_s}: must be a positive number of seconds"
            ));
        }
        if !(t0_s.is_finite() && t1_s.is_finite() && t1_s >= t0_s) {
            return Err(format!(
                "time window [{t0_s}, {t1_s}] s: must be finite and ordered"
            ));
        }
        let n = ((t1_s - t0_s) / step_s * (1.0 - 1e-12)).ceil() as usize + 1;
        if n > 1_000_000 {
            return Err(format!(
                "time_step_s = {step_s}: {n} time nodes to cover {} s (at most 10⁶)",
                t1_s - t0_s
            ));
        }
        Ok(TimeNodes {
            start_s: t0_s,
            step_s,
            count: n.max(2),
        })
    }

    /// Time of node k (s).
    pub fn time_s(&self, k: usize) -> f64 {
        self.start_s + k as f64 * self.step_s
    }

    /// Time of the last node (s).
    pub fn end_s(&self) -> f64 {
        self.time_s(self.count - 1)
    }
}

/// The span `[first row's start, last row's end]` (s) of a frame of `rows` rows starting at
/// `frame_start_s` with exposure `exposure_s` under `model`'s readout.
pub fn frame_span_s(
    model: &TimeModel,
    rows: usize,
    exposure_s: f64,
    frame_start_s: f64,
) -> (f64, f64) {
    let last = model.readout.row_start_s(rows.saturating_sub(1));
    (frame_start_s, frame_start_s + last + exposure_s.max(0.0))
}

/// The weights of one row: `weights[i]` belongs to node `first + i`.
#[derive(Debug, Clone, PartialEq)]
pub struct RowNodeWeights {
    /// First node with a weight.
    pub first: usize,
    /// Weights of nodes `first, first + 1, …`.
    pub weights: Vec<f64>,
}

/// The node weights `w_rk` of row `row` (module documentation) for a frame starting at
/// `frame_start_s`. `model.motion` must be None (the motion is in the rendered scene). Errors
/// when the row's window is not inside the nodes.
pub fn row_node_weights(
    model: &TimeModel,
    row: usize,
    exposure_s: f64,
    frame_start_s: f64,
    nodes: &TimeNodes,
) -> Result<RowNodeWeights, String> {
    if model.motion.is_some() {
        return Err("motion: an image velocity cannot be combined with a scene sampled in time (the scene's animation moves it)".into());
    }
    let t0 = frame_start_s + model.readout.row_start_s(row);
    let t1 = t0 + exposure_s.max(0.0);
    let slack = 1e-9 * nodes.step_s;
    if t0 < nodes.start_s - slack || t1 > nodes.end_s() + slack {
        return Err(format!(
            "row {row}: exposure window [{t0}, {t1}] s is outside the time nodes [{}, {}] s",
            nodes.start_s,
            nodes.end_s()
        ));
    }
    let dt = nodes.step_s;
    let last = nodes.count - 1;
    // segment index of a time (clamped so that t_k ≤ t ≤ t_{k+1})
    let seg = |t: f64| (((t - nodes.start_s) / dt).floor().max(0.0) as usize).min(last - 1);
    let first = seg(t0);
    let mut w = vec![0.0; seg(t1) + 2 - first];
    if exposure_s <= 0.0 {
        // the instantaneous rate: the interpolant at t0 times the light level there
        let level = model.light.map_or(1.0, |l| l.window_fraction(t0, 0.0));
        let u = ((t0 - nodes.time_s(first)) / dt).clamp(0.0, 1.0);
        w[0] = level * (1.0 - u);
        w[1] = level * u;
        return Ok(RowNodeWeights { first, weights: w });
    }
    let (pieces, level) = match &model.light {
        Some(l) => (l.on_intervals_s(t0, t1), 1.0 / l.duty_cycle),
        None => (vec![(t0, t1)], 1.0),
    };
    let scale = level / exposure_s;
    for (p, q) in pieces {
        for k in seg(p)..=seg(q) {
            let (tk, tk1) = (nodes.time_s(k), nodes.time_s(k + 1));
            let (a, b) = (p.max(tk), q.min(tk1));
            if b <= a {
                continue;
            }
            // ∫_a^b (t_{k+1} − t)/Δt dt and ∫_a^b (t − t_k)/Δt dt
            w[k - first] += scale * ((tk1 - a).powi(2) - (tk1 - b).powi(2)) / (2.0 * dt);
            w[k + 1 - first] += scale * ((b - tk).powi(2) - (a - tk).powi(2)) / (2.0 * dt);
        }
    }
    Ok(RowNodeWeights { first, weights: w })
}

/// Accumulates `Σ_k w_rk R(t_k)` row by row as the node rates arrive (one render at a time,
/// nothing stored but the result).
#[derive(Debug, Clone)]
pub struct NodeIntegrator {
    rows: usize,
    cols: usize,
    weights: Vec<RowNodeWeights>,
    sum: Vec<f64>,
}

impl NodeIntegrator {
    /// The integrator of a `rows × cols` frame starting at `frame_start_s` over `nodes`.
    pub fn new(
        model: &TimeModel,
        rows: usize,
        cols: usize,
        exposure_s: f64,
        frame_start_s: f64,
        nodes: &TimeNodes,
    ) -> Result<NodeIntegrator, String> {
        let weights = (0..rows)
            .map(|r| row_node_weights(model, r, exposure_s, frame_start_s, nodes))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(NodeIntegrator {
            rows,
            cols,
            weights,
            sum: vec![0.0; rows * cols],
        })
    }

    /// True when some row gives node `k` a weight (nodes without one need no render).
    pub fn needs(&self, k: usize) -> bool {
        self.weights
            .iter()
            .any(|w| k >= w.first && k < w.first + w.weights.len() && w.weights[k - w.first] != 0.0)
    }

    /// Adds node `k`'s electron rate.
    pub fn add(&mut self, k: usize, rate: &ElectronRate) -> Result<(), String> {
        if rate.rows != self.rows || rate.cols != self.cols {
            return Err(format!(
                "node {k}: rate is {}×{}, the frame {}×{}",
                rate.rows, rate.cols, self.rows, self.cols
            ));
        }
        let cols = self.cols;
        for (r, w) in self.weights.iter().enumerate() {
            if k < w.first || k >= w.first + w.weights.len() {
                continue;
            }
            let wk = w.weights[k - w.first];
            if wk == 0.0 {
                continue;
            }
            for (o, v) in self.sum[r * cols..(r + 1) * cols]
                .iter_mut()
                .zip(&rate.electrons_per_s[r * cols..(r + 1) * cols])
            {
                *o += wk * *v as f64;
            }
        }
        Ok(())
    }

    /// The per-row time-integrated electron rate.
    pub fn finish(self) -> ElectronRate {
        ElectronRate {
            rows: self.rows,
            cols: self.cols,
            electrons_per_s: self.sum.into_iter().map(|v| v as f32).collect(),
        }
    }
}
