//! Dual-pixel readout: two half-photodiodes (left, right) under one microlens per pixel.
//!
//! The microlens images the exit pupil onto the pixel, so the left half-photodiode collects
//! the light through one half of the pupil and the right one the other half (Wadhwa et al.,
//! "Synthetic depth-of-field with a single-camera mobile phone", SIGGRAPH 2018, §3; the
//! optics side is `camsim_optics::dual_pixel`). With the electron rates `L`, `R` of the
//! light through the left and right pupil halves (each about half the pixel's rate at
//! focus), the photodiodes collect
//!
//! `e_left = s L + (1 − s) R`, `e_right = s R + (1 − s) L`,
//!
//! with the separation `s` ∈ [½, 1] (1: an ideal split; ½: no split, both see the whole
//! pupil); the charge is conserved, `e_left + e_right = L + R`, the rate of the normal pixel
//! ([`DualPixelRates::sum`]). Each half-photodiode is the camera's pixel with half its area:
//! half the full well and half the dark current ([`DualPixel::half_photodiode_sensor`]), read
//! with the camera's conversion gain, read noise and ADC.
use crate::{ElectronRate, PatternSource, RawFrame, SensorError, SensorModel, Shot};

/// A dual-pixel sensor (`sensor.dual_pixel` in camera.json).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DualPixel {
    /// Fraction of one pupil half's light collected by its own half-photodiode (½ … 1).
    pub separation: f64,
}

/// The electron rates of the two half-photodiodes of every pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct DualPixelRates {
    /// Left half-photodiodes.
    pub left: ElectronRate,
    /// Right half-photodiodes.
    pub right: ElectronRate,
}

/// Expected (noise-free) frames of the two half-photodiodes (DN, unrounded, row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct DualPixelExpected {
    /// Left half-photodiodes.
    pub left_dn: Vec<f32>,
    /// Right half-photodiodes.
    pub right_dn: Vec<f32>,
}

/// One noisy readout of the two half-photodiodes.
#[derive(Debug, Clone, PartialEq)]
pub struct DualPixelFrame {
    /// Left half-photodiodes.
    pub left: RawFrame,
    /// Right half-photodiodes.
    pub right: RawFrame,
}

impl DualPixel {
    /// Check the separation (½ ≤ s ≤ 1).
    pub fn validate(&self) -> Result<(), SensorError> {
        let s = self.separation;
        if s.is_finite() && (0.5..=1.0).contains(&s) {
            Ok(())
        } else {
            Err(SensorError::InvalidField {
                field: "dual_pixel.separation".into(),
                value: format!("{s}"),
                reason: "must be between 0.5 (no split) and 1 (ideal split)".into(),
            })
        }
    }

    /// The half-photodiode rates from the rates of the light through the left and right pupil
    /// halves (module docs).
    pub fn photodiode_rates(
        &self,
        left_pupil: &ElectronRate,
        right_pupil: &ElectronRate,
    ) -> DualPixelRates {
        assert!(
            left_pupil.rows == right_pupil.rows && left_pupil.cols == right_pupil.cols,
            "pupil-half rates differ in size"
        );
        let s = self.separation as f32;
        let mix = |own: &ElectronRate, other: &ElectronRate| ElectronRate {
            rows: own.rows,
            cols: own.cols,
            electrons_per_s: own
                .electrons_per_s
                .iter()
                .zip(&other.electrons_per_s)
                .map(|(a, b)| s * a + (1.0 - s) * b)
                .collect(),
        };
        DualPixelRates {
            left: mix(left_pupil, right_pupil),
            right: mix(right_pupil, left_pupil),
        }
    }

    /// The camera's sensor as one half-photodiode: half the full well, half the dark current
    /// (both scale with the photodiode's area), the rest unchanged.
    pub fn half_photodiode_sensor(&self, sensor: &SensorModel) -> SensorModel {
        let mut s = sensor.clone();
        s.well_capacity_e *= 0.5;
        s.dark_voltage_v_per_s *= 0.5;
        s
    }
}

impl DualPixelRates {
    /// The normal pixel: `e_left + e_right`.
    pub fn sum(&self) -> ElectronRate {
        ElectronRate {
            rows: self.left.rows,
            cols: self.left.cols,
            electrons_per_s: self
                .left
                .electrons_per_s
                .iter()
                .zip(&self.right.electrons_per_s)
                .map(|(a, b)| a + b)
                .collect(),
        }
    }
}

/// The expected frames of both half-photodiodes under `shot` ([`crate::expected_dn`] of the
/// half-photodiode sensor).
pub fn expected_dual_pixel_dn(
    sensor: &SensorModel,
    dual: &DualPixel,
    rates: &DualPixelRates,
    shot: &Shot,
) -> DualPixelExpected {
    let half = dual.half_photodiode_sensor(sensor);
    DualPixelExpected {
        left_dn: crate::expected_dn(&half, &rates.left, shot),
        right_dn: crate::expected_dn(&half, &rates.right, shot),
    }
}

/// One noisy readout of both half-photodiodes ([`crate::expose_with`] of the half-photodiode
/// sensor): temporal noise from the streams `(seed, [stream…, 0])` (left) and
/// `(seed, [stream…, 1])` (right); fixed patterns drawn from the seeds `pattern_seed` (left)
/// and `pattern_seed + 1` (right), independent per half-photodiode.
pub fn expose_dual_pixel(
    sensor: &SensorModel,
    dual: &DualPixel,
    rates: &DualPixelRates,
    shot: &Shot,
    pattern_seed: u64,
    seed: u64,
    stream: &[u64],
) -> DualPixelFrame {
    let half = dual.half_photodiode_sensor(sensor);
    let read = |rate: &ElectronRate, k: u64| {
        let mut ids = stream.to_vec();
        ids.push(k);
        crate::expose_with(
            &half,
            rate,
            shot,
            PatternSource::Seeded(pattern_seed.wrapping_add(k)),
            seed,
            &ids,
        )
    };
    DualPixelFrame {
        left: read(&rates.left, 0),
        right: read(&rates.right, 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rate(v: &[f32]) -> ElectronRate {
        ElectronRate {
            rows: 1,
            cols: v.len(),
            electrons_per_s: v.to_vec(),
        }
    }

    #[test]
    fn split_conserves_charge_and_mixes_by_separation() {
        let (l, r) = (rate(&[100.0, 0.0, 30.0]), rate(&[0.0, 50.0, 30.0]));
        for s in [0.5, 0.8, 1.0] {
            let dp = DualPixel { separation: s };
            dp.validate().unwrap();
            let pr = dp.photodiode_rates(&l, &r);
            let sum = pr.sum();
            for k in 0..3 {
                let total = l.electrons_per_s[k] + r.electrons_per_s[k];
                assert!((sum.electrons_per_s[k] - total).abs() < 1e-4);
            }
            assert!((pr.left.electrons_per_s[0] - 100.0 * s as f32).abs() < 1e-4);
            assert!((pr.right.electrons_per_s[0] - 100.0 * (1.0 - s) as f32).abs() < 1e-4);
        }
        assert!(DualPixel { separation: 0.4 }.validate().is_err());
        assert!(DualPixel {
            separation: f64::NAN
        }
        .validate()
        .is_err());
    }

    /// Each half-photodiode clips at half the full well: a rate far above it reads the same
    /// DN as half the well's charge.
    #[test]
    fn half_photodiode_clips_at_half_the_well() {
        let mut sensor = SensorModel::mono_test(1, 2);
        sensor.voltage_swing_v = 10.0; // the well, not the swing, clips
        let dp = DualPixel { separation: 1.0 };
        let shot = Shot::new(&sensor, 1.0);
        let pr = DualPixelRates {
            left: rate(&[1e9, 0.0]),
            right: rate(&[0.0, 0.0]),
        };
        let e = expected_dual_pixel_dn(&sensor, &dp, &pr, &shot);
        let half = dp.half_photodiode_sensor(&sensor);
        let at_half_well = crate::expected_dn(
            &half,
            &rate(&[(sensor.well_capacity_e / 2.0) as f32, 0.0]),
            &shot,
        );
        assert!((e.left_dn[0] - at_half_well[0]).abs() < 1e-3);
        assert!(e.left_dn[0] > e.right_dn[0]);
    }
}
