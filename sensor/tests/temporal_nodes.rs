//! Per-row integration of a scene sampled at time nodes (`camsim_sensor::temporal_nodes`)
//! against closed forms: the weights of a row sum to its window's light fraction, a rate
//! linear in time is integrated exactly (`a·F + b·F·t̄` with F the light fraction and t̄ the
//! light-weighted mean time), the centroid of an edge moving at constant speed sits at
//! `e₀ + v·t̄_r` in every row, and a video frame starting at `F` sees the light with its
//! phase advanced by `f·F` periods.
use camsim_sensor::temporal::{time_averaged_rate, time_averaged_rate_from};
use camsim_sensor::{
    ElectronRate, Motion, NodeIntegrator, PwmLight, Readout, SensorModel, ShutterMode, TimeModel,
    TimeNodes,
};

fn rolling(light: Option<PwmLight>) -> TimeModel {
    TimeModel {
        readout: Readout {
            mode: ShutterMode::Rolling,
            row_time_s: 20e-6,
        },
        light,
        motion: None,
    }
}

fn pwm() -> PwmLight {
    PwmLight {
        frequency_hz: 1000.0,
        duty_cycle: 0.2,
        phase: 0.35,
    }
}

#[test]
fn weights_sum_to_the_light_fraction_and_integrate_a_linear_rate_exactly() {
    let rows = 120;
    for (light, exposure_s, frame_start_s) in [
        (None, 3e-4, 0.0),
        (Some(pwm()), 3e-4, 0.0),
        (Some(pwm()), 2.5e-3, 0.0123),
        (Some(pwm()), 0.0, 0.001),
    ] {
        let model = rolling(light);
        let (t0, t1) = camsim_sensor::frame_span_s(&model, rows, exposure_s, frame_start_s);
        // an irregular spacing that does not divide the windows
        let nodes = TimeNodes::covering(t0, t1, 7.3e-5).unwrap();
        // R(t) = a + b·t for every pixel: node k carries a + b·t_k
        let (a, b) = (1000.0, 2.0e5);
        let mut acc =
            NodeIntegrator::new(&model, rows, 1, exposure_s, frame_start_s, &nodes).unwrap();
        for k in 0..nodes.count {
            let r = ElectronRate {
                rows,
                cols: 1,
                electrons_per_s: vec![(a + b * nodes.time_s(k)) as f32; rows],
            };
            acc.add(k, &r).unwrap();
        }
        let out = acc.finish();
        for r in 0..rows {
            let start = frame_start_s + model.readout.row_start_s(r);
            let frac = light.map_or(1.0, |l| l.window_fraction(start, exposure_s));
            // light-weighted mean time, shifted to the frame: the model's for frame 0
            let mean_t = if exposure_s > 0.0 {
                let m = TimeModel {
                    light: light.map(|l| PwmLight {
                        phase: (l.phase - l.frequency_hz * frame_start_s).rem_euclid(1.0),
                        ..l
                    }),
                    ..model
                };
                frame_start_s + m.row_mean_time_s(r, exposure_s)
            } else {
                start
            };
            let want = a * frac + b * frac * mean_t;
            let got = out.electrons_per_s[r] as f64;
            assert!(
                (got - want).abs() <= 2e-6 * want.abs().max(1.0),
                "light {light:?} T {exposure_s} F {frame_start_s} row {r}: {got} vs {want}"
            );
        }
    }
}

/// Box-integrated step edge at x = e (pixel c covers [c − ½, c + ½]): dark left, bright right.
fn edge_row(cols: usize, e: f64, dark: f64, bright: f64) -> Vec<f64> {
    (0..cols)
        .map(|c| {
            let right = ((c as f64 + 0.5) - e).clamp(0.0, 1.0);
            dark + (bright - dark) * right
        })
        .collect()
}

#[test]
fn edge_centroid_follows_the_light_weighted_mean_time() {
    let (rows, cols) = (80, 48);
    let v_px_per_s = 2000.0;
    let (dark, bright) = (100.0, 5000.0);
    for exposure_s in [3e-4, 2.5e-3] {
        let model = rolling(Some(pwm()));
        let (t0, t1) = camsim_sensor::frame_span_s(&model, rows, exposure_s, 0.0);
        let nodes = TimeNodes::covering(t0, t1, 1e-4).unwrap();
        let mut acc = NodeIntegrator::new(&model, rows, cols, exposure_s, 0.0, &nodes).unwrap();
        for k in 0..nodes.count {
            let e = 10.0 + v_px_per_s * nodes.time_s(k);
            let row = edge_row(cols, e, dark, bright);
            let plane: Vec<f32> = (0..rows)
                .flat_map(|_| row.iter().map(|v| *v as f32))
                .collect();
            acc.add(
                k,
                &ElectronRate {
                    rows,
                    cols,
                    electrons_per_s: plane,
                },
            )
            .unwrap();
        }
        let out = acc.finish();
        for r in 0..rows {
            let row = &out.electrons_per_s[r * cols..(r + 1) * cols];
            let frac = pwm().window_fraction(model.readout.row_start_s(r), exposure_s);
            if frac < 0.05 {
                continue; // the row saw (almost) no light
            }
            let (a, b) = (dark * frac, bright * frac);
            let pos: f64 = row.iter().map(|v| (b - *v as f64) / (b - a)).sum::<f64>() - 0.5;
            let want = 10.0 + v_px_per_s * model.row_mean_time_s(r, exposure_s);
            assert!(
                (pos - want).abs() < 2e-3,
                "T {exposure_s} row {r}: edge at {pos}, model {want}"
            );
        }
    }
}

#[test]
fn a_video_frame_sees_the_light_phase_advanced() {
    // frame k of a video at F = k/frame_rate: the PWM phase becomes frac(φ − f·F) and a
    // rigid motion has moved by v·F
    let sensor = SensorModel::mono_test(60, 40);
    let rate = ElectronRate {
        rows: 60,
        cols: 40,
        electrons_per_s: (0..60 * 40)
            .map(|i| 1000.0 + ((i % 40) as f32 - 20.0).max(0.0) * 50.0)
            .collect(),
    };
    let light = pwm();
    let frame_start_s = 3.0 / 240.0;
    let shifted = PwmLight {
        phase: (light.phase - light.frequency_hz * frame_start_s).rem_euclid(1.0),
        ..light
    };
    let a = time_averaged_rate_from(&sensor, &rate, 4e-4, &rolling(Some(light)), frame_start_s);
    let b = time_averaged_rate(&sensor, &rate, 4e-4, &rolling(Some(shifted)));
    for (x, y) in a.electrons_per_s.iter().zip(&b.electrons_per_s) {
        assert!((x - y).abs() <= 1e-4 * y.abs(), "{x} vs {y}");
    }
    // motion: the frame at F equals frame 0 of the image shifted by v·F (interior columns)
    let v = 400.0; // px/s: v·F = 5 px
    let moving = TimeModel {
        motion: Some(Motion {
            velocity_px_per_s: [v, 0.0],
        }),
        ..rolling(None)
    };
    let a = time_averaged_rate_from(&sensor, &rate, 4e-4, &moving, frame_start_s);
    let b = time_averaged_rate(&sensor, &rate, 4e-4, &moving);
    for r in 0..60 {
        for c in 10..40 {
            let (x, y) = (
                a.electrons_per_s[r * 40 + c],
                b.electrons_per_s[r * 40 + c - 5],
            );
            assert!((x - y).abs() <= 1e-3 * y.abs(), "({r}, {c}): {x} vs {y}");
        }
    }
}

#[test]
fn windows_outside_the_nodes_and_image_velocity_are_refused() {
    let model = rolling(None);
    let nodes = TimeNodes::covering(0.0, 1e-3, 1e-4).unwrap();
    let e = NodeIntegrator::new(&model, 100, 1, 3e-4, 0.0, &nodes).unwrap_err();
    assert!(e.contains("outside the time nodes"), "{e}");
    let moving = TimeModel {
        motion: Some(Motion {
            velocity_px_per_s: [1.0, 0.0],
        }),
        ..model
    };
    let e = NodeIntegrator::new(&moving, 2, 1, 1e-4, 0.0, &nodes).unwrap_err();
    assert!(e.contains("motion"), "{e}");
    assert!(TimeNodes::covering(0.0, 1.0, 0.0)
        .unwrap_err()
        .contains("time_step_s"));
}
