//! Simulated capture sets drawn with camsim_sensor's forward model (`expose`).
#![allow(dead_code)]
use camsim_core::rng::splitmix64;
use camsim_core::Spectrum;
use camsim_diagnose::{CalibrationShot, ShotKind};
use camsim_sensor::{expose, fixed_pattern, Cfa, ElectronRate, NoiseSwitches, SensorModel, Shot};

/// A Bayer (gb/rg) sensor, 12 bits, 1 V swing, flat QE (unused by the noise tests).
pub fn bayer(rows: usize, cols: usize) -> SensorModel {
    SensorModel {
        rows,
        cols,
        pixel_pitch_m: 2.2e-6,
        fill_factor: 0.45,
        cfa: Cfa {
            tile: vec![vec![1, 2], vec![0, 1]],
        },
        channel_names: vec!["r".into(), "g".into(), "b".into()],
        channel_qe: vec![Spectrum::constant(0.3); 3],
        well_capacity_e: 1e5,
        conversion_gain_v_per_e: 1e-4,
        voltage_swing_v: 1.0,
        analog_gain: 1.0,
        analog_offset_v: 0.0,
        adc_bits: 12,
        black_level_dn: 64.0,
        dark_voltage_v_per_s: 5e-3,
        read_noise_v: 1e-3,
        dsnu_sigma_v: 1e-3,
        prnu_sigma_percent: 1.0,
        noise: NoiseSwitches::default(),
        column_fpn: None,
        reset_noise: None,
        effects: Default::default(),
    }
}

/// Uniform per-channel electron rates (e/s) laid out by the CFA.
pub fn channel_rate(s: &SensorModel, per_channel: &[f64]) -> ElectronRate {
    ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: (0..s.rows * s.cols)
            .map(|i| per_channel[s.cfa.channel_at(i / s.cols, i % s.cols)] as f32)
            .collect(),
    }
}

/// One planned shot.
pub struct Plan {
    pub id: String,
    pub kind: ShotKind,
    pub exposure_s: f64,
    pub analog_gain: f64,
    pub frames: usize,
    /// Electron rate per channel (e/s); zeros for darks.
    pub rate: Vec<f64>,
}

pub fn dark(t: f64, frames: usize) -> Plan {
    Plan {
        id: format!("dark-{t}"),
        kind: ShotKind::Dark,
        exposure_s: t,
        analog_gain: 1.0,
        frames,
        rate: vec![0.0; 3],
    }
}

pub fn flat(t: f64, frames: usize, rate: &[f64]) -> Plan {
    Plan {
        id: format!("flat-{t}"),
        kind: ShotKind::Flat {
            radiance: Spectrum::constant(1.0),
        },
        exposure_s: t,
        analog_gain: 1.0,
        frames,
        rate: rate.to_vec(),
    }
}

/// Simulates the plan with one camera (fixed pattern from `seed`).
pub fn simulate(truth: &SensorModel, plan: &[Plan], seed: u64) -> Vec<CalibrationShot> {
    let fp = fixed_pattern(truth, seed);
    plan.iter()
        .enumerate()
        .map(|(si, p)| {
            let rate = channel_rate(truth, &p.rate);
            let shot = Shot {
                exposure_s: p.exposure_s,
                analog_gain: p.analog_gain,
            };
            CalibrationShot {
                id: p.id.clone(),
                kind: p.kind.clone(),
                exposure_s: p.exposure_s,
                analog_gain: p.analog_gain,
                frames: (0..p.frames)
                    .map(|f| expose(truth, &rate, &shot, &fp, seed, &[si as u64, f as u64]))
                    .collect(),
            }
        })
        .collect()
}

/// Uniform and log-uniform draws from a SplitMix64 counter stream (no extra dependency).
pub struct Draw(u64);
impl Draw {
    pub fn new(seed: u64) -> Self {
        Draw(splitmix64(seed ^ 0xD1A6_0000))
    }
    pub fn uni(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(1);
        let u = (splitmix64(self.0) >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
    pub fn log(&mut self, lo: f64, hi: f64) -> f64 {
        (self.uni(lo.ln(), hi.ln())).exp()
    }
}
