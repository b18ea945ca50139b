//! Time within the exposure (`camsim_sensor::temporal`) against closed forms: PWM overlap vs a
//! brute-force time integral, flicker band period and visibility, skew of a moving bar under
//! a rolling shutter, the global shutter as the special case, and the dark-current doubling
//! law.
use camsim_sensor::temporal::{
    dark_at_temperature, flicker_period_rows, time_averaged_rate, Motion, PwmLight, Readout,
    ShutterMode, TimeModel,
};
use camsim_sensor::{ElectronRate, SensorModel};

fn lights() -> Vec<PwmLight> {
    vec![
        PwmLight {
            frequency_hz: 100.0,
            duty_cycle: 0.3,
            phase: 0.0,
        },
        PwmLight {
            frequency_hz: 90.0,
            duty_cycle: 0.5,
            phase: 0.25,
        },
        PwmLight {
            frequency_hz: 217.0,
            duty_cycle: 0.1,
            phase: 0.9,
        },
        PwmLight {
            frequency_hz: 60.0,
            duty_cycle: 1.0,
            phase: 0.5,
        },
    ]
}

/// Midpoint-rule integral of the 0/1 pulse train over the window, normalised by D·T.
fn brute_fraction(l: &PwmLight, t0: f64, t: f64, n: usize) -> f64 {
    let dt = t / n as f64;
    let on = (0..n)
        .filter(|&i| {
            let u = l.frequency_hz * (t0 + (i as f64 + 0.5) * dt) - l.phase;
            u - u.floor() < l.duty_cycle
        })
        .count();
    on as f64 * dt / (l.duty_cycle * t)
}

#[test]
fn overlap_fraction_matches_brute_force_integral() {
    let n = 400_000;
    for l in lights() {
        for &(t0, t) in &[(0.0, 0.001), (0.0123, 0.0037), (0.5, 0.0421), (0.003, 0.25)] {
            let exact = l.window_fraction(t0, t);
            let brute = brute_fraction(&l, t0, t, n);
            // The midpoint rule misclassifies at most one step per pulse edge in the window.
            let edges = 2.0 * (l.frequency_hz * t).ceil() + 2.0;
            let tol = edges * (t / n as f64) / (l.duty_cycle * t);
            assert!(
                (exact - brute).abs() <= tol,
                "f={} D={} t0={t0} T={t}: exact {exact} brute {brute} tol {tol}",
                l.frequency_hz,
                l.duty_cycle
            );
        }
        // A window of whole periods collects exactly the mean.
        let t = 3.0 / l.frequency_hz;
        assert!((l.window_fraction(0.00731, t) - 1.0).abs() < 1e-12);
    }
}

fn flat_rate(rows: usize, cols: usize) -> ElectronRate {
    ElectronRate {
        rows,
        cols,
        electrons_per_s: vec![1000.0; rows * cols],
    }
}

fn row_means(r: &ElectronRate) -> Vec<f64> {
    r.electrons_per_s
        .chunks(r.cols)
        .map(|c| c.iter().map(|&v| v as f64).sum::<f64>() / c.len() as f64)
        .collect()
}

#[test]
fn flicker_bands_repeat_every_period_over_row_time() {
    let (rows, cols) = (400, 4);
    let sensor = SensorModel::mono_test(rows, cols);
    let light = PwmLight {
        frequency_hz: 100.0,
        duty_cycle: 0.25,
        phase: 0.1,
    };
    let readout = Readout {
        mode: ShutterMode::Rolling,
        row_time_s: 1.0 / (100.0 * 40.0),
    };
    let expected = flicker_period_rows(&light, &readout);
    assert!((expected - 40.0).abs() < 1e-9);
    let model = TimeModel {
        readout,
        light: Some(light),
        motion: None,
    };
    let out = time_averaged_rate(&sensor, &flat_rate(rows, cols), 0.0013, &model);
    let m = row_means(&out);
    // Exactly periodic with period 40 rows, and with no shorter period.
    for r in 0..rows - 40 {
        assert!((m[r] - m[r + 40]).abs() <= 1e-3 * m[r].max(1.0), "row {r}");
    }
    for p in 1..40 {
        let d: f64 = (0..rows - p).map(|r| (m[r] - m[r + p]).abs()).sum();
        assert!(d > 1.0, "period {p} also fits");
    }
    // The DFT of the row means peaks at rows/40 cycles.
    let mean = m.iter().sum::<f64>() / rows as f64;
    let power = |k: usize| {
        let (mut re, mut im) = (0.0, 0.0);
        for (r, v) in m.iter().enumerate() {
            let a = 2.0 * std::f64::consts::PI * (k * r) as f64 / rows as f64;
            re += (v - mean) * a.cos();
            im += (v - mean) * a.sin();
        }
        re * re + im * im
    };
    let best = (1..rows / 2)
        .max_by(|&a, &b| power(a).total_cmp(&power(b)))
        .unwrap();
    assert_eq!(best, rows / 40);
}

#[test]
fn band_visibility_follows_duty_cycle_and_exposure() {
    let f = 100.0;
    // 2000 rows per light period: the sampled max/min are within 1/2000 period of the extremes.
    let rows_per_period = 2000.0;
    let rows = 2 * rows_per_period as usize;
    let sensor = SensorModel::mono_test(rows, 1);
    let readout = Readout {
        mode: ShutterMode::Rolling,
        row_time_s: 1.0 / (f * rows_per_period),
    };
    for &d in &[0.1, 0.3, 0.5, 0.8] {
        for &periods in &[0.2, 0.5, 0.9, 1.0, 1.37, 2.0, 3.6] {
            let light = PwmLight {
                frequency_hz: f,
                duty_cycle: d,
                phase: 0.0,
            };
            let t = periods / f;
            let model = TimeModel {
                readout,
                light: Some(light),
                motion: None,
            };
            let m = row_means(&time_averaged_rate(&sensor, &flat_rate(rows, 1), t, &model));
            let (hi, lo) = m
                .iter()
                .fold((f64::MIN, f64::MAX), |(h, l), &v| (h.max(v), l.min(v)));
            let measured = (hi - lo) / (hi + lo);
            let expected = light.band_visibility(t);
            // Sampling error: the on-time moves by at most one row time between rows.
            let tol = 2.0 / rows_per_period / (d * periods) + 1e-6;
            assert!(
                (measured - expected).abs() <= tol,
                "D={d} T={periods}/f: measured {measured} expected {expected}"
            );
            if (periods - periods.round()).abs() < 1e-12 {
                assert!(expected == 0.0 && measured < 1e-5, "D={d} T={periods}/f");
            } else {
                assert!(expected > 0.0);
            }
        }
    }
}

/// A vertical bar 4 pixels wide at columns 20..24 of a 64-column mono sensor.
fn bar_rate(rows: usize) -> ElectronRate {
    let cols = 64;
    let mut e = vec![10.0f32; rows * cols];
    for r in 0..rows {
        for c in 20..24 {
            e[r * cols + c] = 1010.0;
        }
    }
    ElectronRate {
        rows,
        cols,
        electrons_per_s: e,
    }
}

fn row_centroids(r: &ElectronRate, background: f64) -> Vec<f64> {
    r.electrons_per_s
        .chunks(r.cols)
        .map(|row| {
            let (mut s, mut w) = (0.0, 0.0);
            for (c, &v) in row.iter().enumerate() {
                let x = v as f64 - background;
                s += c as f64 * x;
                w += x;
            }
            s / w
        })
        .collect()
}

#[test]
fn moving_bar_skews_by_velocity_times_row_time() {
    let rows = 32;
    let sensor = SensorModel::mono_test(rows, 64);
    let rate = bar_rate(rows);
    let static_c = row_centroids(&rate, 10.0);
    let (v, row_time, t) = (3000.0, 20e-6, 2e-3);
    let model = TimeModel {
        readout: Readout {
            mode: ShutterMode::Rolling,
            row_time_s: row_time,
        },
        light: None,
        motion: Some(Motion {
            velocity_px_per_s: [v, 0.0],
        }),
    };
    let out = time_averaged_rate(&sensor, &rate, t, &model);
    let c = row_centroids(&out, 10.0);
    for r in 0..rows {
        // Centroid = static centroid + v·(t_r + T/2): skew v·row_time per row, blur v·T.
        let expected = static_c[r] + v * (r as f64 * row_time + t / 2.0);
        assert!(
            (c[r] - expected).abs() < 1e-3,
            "row {r}: {} vs {expected}",
            c[r]
        );
    }
    // The bar's signal is conserved (blur spreads it, the time average keeps it).
    let sum = |x: &ElectronRate| x.electrons_per_s.iter().map(|&v| v as f64).sum::<f64>();
    assert!((sum(&out) - sum(&rate)).abs() < 1e-5 * sum(&rate));
}

#[test]
fn global_shutter_is_the_special_case() {
    let rows = 16;
    let sensor = SensorModel::mono_test(rows, 64);
    let rate = bar_rate(rows);
    let (v, t) = (2500.0, 1e-3);
    let light = PwmLight {
        frequency_hz: 300.0,
        duty_cycle: 0.4,
        phase: 0.8,
    };
    let model = TimeModel {
        readout: Readout {
            mode: ShutterMode::Global,
            row_time_s: 20e-6,
        },
        light: Some(light),
        motion: Some(Motion {
            velocity_px_per_s: [v, 0.0],
        }),
    };
    // The window [0, 1 ms] is 0.3 light periods and catches 0.2 periods of light.
    assert!((light.window_fraction(0.0, t) - 0.2 / (0.4 * 0.3)).abs() < 1e-12);
    let out = time_averaged_rate(&sensor, &rate, t, &model);
    let c = row_centroids(&out, 0.0);
    let sums: Vec<f64> = out
        .electrons_per_s
        .chunks(64)
        .map(|r| r.iter().map(|&v| v as f64).sum())
        .collect();
    let static_sum: f64 = rate.electrons_per_s[..64].iter().map(|&v| v as f64).sum();
    for r in 0..rows {
        assert!(
            (c[r] - c[0]).abs() < 1e-9,
            "row {r} skewed: {} vs {}",
            c[r],
            c[0]
        );
        let want = static_sum * light.window_fraction(0.0, t);
        assert!(
            (sums[r] - want).abs() < 1e-5 * want,
            "row {r}: {} vs {want}",
            sums[r]
        );
    }
    // No modulation, no motion: the rate is unchanged whatever the readout.
    let still = TimeModel {
        readout: Readout {
            mode: ShutterMode::Rolling,
            row_time_s: 20e-6,
        },
        light: None,
        motion: None,
    };
    assert!(still.is_static());
    assert_eq!(time_averaged_rate(&sensor, &rate, t, &still), rate);
}

#[test]
fn row_sample_weights_sum_to_the_window_fraction() {
    let light = PwmLight {
        frequency_hz: 150.0,
        duty_cycle: 0.35,
        phase: 0.6,
    };
    let model = TimeModel {
        readout: Readout {
            mode: ShutterMode::Rolling,
            row_time_s: 37e-6,
        },
        light: Some(light),
        motion: Some(Motion {
            velocity_px_per_s: [1234.0, -321.0],
        }),
    };
    for row in [0, 7, 100] {
        let t = 0.0173;
        let w: f64 = model
            .row_samples(row, t, [2.0, 2.0])
            .iter()
            .map(|s| s.weight)
            .sum();
        let want = light.window_fraction(model.readout.row_start_s(row), t);
        assert!((w - want).abs() < 1e-12, "row {row}: {w} vs {want}");
    }
}

#[test]
fn dark_current_doubles_every_doubling_temperature() {
    let d = 2.5e-3;
    assert!((dark_at_temperature(d, 25.0, 25.0, 6.0) - d).abs() < 1e-18);
    assert!((dark_at_temperature(d, 31.0, 25.0, 6.0) - 2.0 * d).abs() < 1e-15);
    assert!((dark_at_temperature(d, 13.0, 25.0, 6.0) - d / 4.0).abs() < 1e-15);
    // ln(dark) is linear in T with slope ln 2 / T_double.
    let slope = (dark_at_temperature(d, 60.0, 25.0, 7.0).ln() - d.ln()) / 35.0;
    assert!((slope - std::f64::consts::LN_2 / 7.0).abs() < 1e-12);
}
