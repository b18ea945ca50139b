//! Row noise, RTN pixels, black-level drift and dark current against temperature
//! (`camsim_sensor::line_noise`) against their closed forms: the variance of row means across
//! frames (EMVA 1288 R4.0 §8.3), the two-state Markov statistics of RTN (occupancy
//! p = p_up/(p_up + p_down), variance A²p(1−p), transition probabilities, lag-1
//! autocorrelation 1 − p_up − p_down), the drift slope, and the doubling law per shot.
use camsim_sensor::*;

/// A dark test sensor with only read noise on (no shot/dark/DSNU/PRNU terms).
fn dark_sensor(rows: usize, cols: usize) -> SensorModel {
    let mut s = SensorModel::mono_test(rows, cols);
    s.noise = NoiseSwitches {
        read: true,
        ..NoiseSwitches::none()
    };
    s.dark_voltage_v_per_s = 0.0;
    s
}

fn zero_rate(s: &SensorModel) -> ElectronRate {
    ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![0.0; s.rows * s.cols],
    }
}

fn frame(s: &SensorModel, seed: u64, shot: u64, k: u64, index: u64) -> Vec<f64> {
    let rate = zero_rate(s);
    let sh = Shot::new(s, 0.01);
    expose_frame(
        s,
        &rate,
        &sh,
        PatternSource::Seeded(seed),
        seed,
        &[shot, k],
        index,
    )
    .dn
    .iter()
    .map(|&v| v as f64)
    .collect()
}

/// Without the blocks a frame at any index is `expose_with`'s, bit for bit; with a zero-size
/// block (σ = 0, drift 0) too.
#[test]
fn absent_blocks_leave_frames_unchanged() {
    let s = dark_sensor(16, 24);
    let rate = zero_rate(&s);
    let sh = Shot::new(&s, 0.01);
    let a = expose_with(&s, &rate, &sh, PatternSource::Seeded(3), 3, &[1, 2]);
    let b = expose_frame(&s, &rate, &sh, PatternSource::Seeded(3), 3, &[1, 2], 17);
    assert_eq!(a.dn, b.dn);
    let mut z = s.clone();
    z.effects.row_noise = Some(RowNoise { sigma_v: 0.0 });
    z.effects.black_level_drift = Some(BlackLevelDrift { dn_per_frame: 0.0 });
    let c = expose_frame(&z, &rate, &sh, PatternSource::Seeded(3), 3, &[1, 2], 17);
    assert_eq!(a.dn, c.dn);
}

/// Row noise: the pooled variance of row means across frames equals
/// k²σ_row² + (k²σ_read² + 1/12)/cols (k = DN per volt), a z-test with the pooled sample
/// variance's standard error V·√(2/ν), ν = rows·(F − 1). The pixel variance about the row
/// means is the read noise alone (row noise is common to the row).
#[test]
fn row_noise_variance_of_row_means() {
    let (rows, cols, frames) = (32usize, 64usize, 60usize);
    let mut s = dark_sensor(rows, cols);
    s.black_level_dn = 200.0;
    let sigma_row = 2e-3;
    s.effects.row_noise = Some(RowNoise { sigma_v: sigma_row });
    let k = s.dn_per_output_v();
    let means: Vec<Vec<f64>> = (0..frames)
        .map(|f| {
            let d = frame(&s, 11, 0, f as u64, f as u64);
            (0..rows)
                .map(|r| d[r * cols..(r + 1) * cols].iter().sum::<f64>() / cols as f64)
                .collect()
        })
        .collect();
    let mut ss = 0.0;
    for r in 0..rows {
        let m = means.iter().map(|x| x[r]).sum::<f64>() / frames as f64;
        ss += means.iter().map(|x| (x[r] - m).powi(2)).sum::<f64>();
    }
    let nu = (rows * (frames - 1)) as f64;
    let v = ss / nu;
    let expect =
        k * k * sigma_row * sigma_row + (k * k * s.read_noise_v.powi(2) + 1.0 / 12.0) / cols as f64;
    let z = (v - expect) / (expect * (2.0 / nu).sqrt());
    assert!(z.abs() < 4.0, "row-mean variance {v} vs {expect}: z = {z}");
    // without the block the row means vary by the read noise alone
    let mut s0 = s.clone();
    s0.effects.row_noise = None;
    let d0: Vec<Vec<f64>> = (0..frames)
        .map(|f| frame(&s0, 11, 0, f as u64, f as u64))
        .collect();
    let mut ss0 = 0.0;
    for r in 0..rows {
        let rm: Vec<f64> = d0
            .iter()
            .map(|d| d[r * cols..(r + 1) * cols].iter().sum::<f64>() / cols as f64)
            .collect();
        let m = rm.iter().sum::<f64>() / frames as f64;
        ss0 += rm.iter().map(|x| (x - m).powi(2)).sum::<f64>();
    }
    let v0 = ss0 / nu;
    let e0 = (k * k * s.read_noise_v.powi(2) + 1.0 / 12.0) / cols as f64;
    let z0 = (v0 - e0) / (e0 * (2.0 / nu).sqrt());
    assert!(z0.abs() < 4.0, "no row noise: {v0} vs {e0}: z = {z0}");
}

/// RTN: the map holds round(f·N) distinct pixels; over many independent pixel chains the high
/// state's occupancy at frames 0 and 40 is p = p_up/(p_up + p_down) (binomial z-test); the
/// transition frequencies are 1 − p_down (stay high) and p_up (go high); one long chain's
/// lag-1 autocorrelation is 1 − p_up − p_down.
#[test]
fn rtn_two_state_statistics() {
    let b = Rtn {
        fraction: 1.0,
        amplitude_v: 0.01,
        log_sigma: 0.0,
        p_up: 0.3,
        p_down: 0.2,
    };
    let p = b.high_probability();
    assert!((p - 0.6).abs() < 1e-15);
    let n = 20000u64;
    for j in [0u64, 40] {
        let hi = (0..n).filter(|&i| rtn_state(&b, 5, i, j)).count() as f64;
        let z = (hi / n as f64 - p) / (p * (1.0 - p) / n as f64).sqrt();
        assert!(
            z.abs() < 4.0,
            "frame {j}: occupancy {} vs {p}: z = {z}",
            hi / n as f64
        );
    }
    let (mut n_hh, mut n_h, mut n_lh, mut n_l) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        let a = rtn_state(&b, 5, i, 9);
        let c = rtn_state(&b, 5, i, 10);
        if a {
            n_h += 1.0;
            n_hh += c as u8 as f64;
        } else {
            n_l += 1.0;
            n_lh += c as u8 as f64;
        }
    }
    let stay = 1.0 - b.p_down;
    let z = (n_hh / n_h - stay) / (stay * (1.0 - stay) / n_h).sqrt();
    assert!(
        z.abs() < 4.0,
        "P(high→high) {} vs {stay}: z = {z}",
        n_hh / n_h
    );
    let z = (n_lh / n_l - b.p_up) / (b.p_up * (1.0 - b.p_up) / n_l).sqrt();
    assert!(
        z.abs() < 4.0,
        "P(low→high) {} vs {}: z = {z}",
        n_lh / n_l,
        b.p_up
    );
    // lag-1 autocorrelation of one chain over 4000 frames (states from one stream: the
    // chain stepped once per frame; the estimate's SE ≈ √((1 − ρ²)/n) for a Markov chain)
    let m = 4000u64;
    let x: Vec<f64> = (0..m)
        .map(|j| rtn_state(&b, 8, 77, j) as u8 as f64)
        .collect();
    let mu = x.iter().sum::<f64>() / m as f64;
    let var = x.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / m as f64;
    let cov = x.windows(2).map(|w| (w[0] - mu) * (w[1] - mu)).sum::<f64>() / (m - 1) as f64;
    let rho = cov / var;
    let rho0 = 1.0 - b.p_up - b.p_down;
    let se = ((1.0 - rho0 * rho0) / m as f64).sqrt();
    assert!((rho - rho0).abs() < 4.0 * se, "lag-1 ρ {rho} vs {rho0}");
}

/// RTN in frames: every pixel a trap (fraction 1), no other noise: the pixel DN over pixels of
/// one frame has mean black + A_dn·p and variance A_dn²·p(1−p) (A_dn = the rounded step); the
/// map has round(f·N) distinct sorted pixels.
#[test]
fn rtn_frames_have_the_two_state_mean_and_variance() {
    let (rows, cols) = (64usize, 96usize);
    let mut s = dark_sensor(rows, cols);
    s.noise = NoiseSwitches::none();
    let b = Rtn {
        fraction: 1.0,
        amplitude_v: 10.0 / s.dn_per_output_v(),
        log_sigma: 0.0,
        p_up: 0.1,
        p_down: 0.3,
    };
    s.effects.rtn = Some(b);
    let p = b.high_probability();
    let d = frame(&s, 2, 0, 0, 25);
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let (a, black) = (10.0, s.black_level_dn);
    let z = (mean - black - a * p) / (a * (p * (1.0 - p) / n).sqrt());
    assert!(z.abs() < 4.0, "mean {mean}: z = {z}");
    let v0 = a * a * p * (1.0 - p);
    // variance of a Bernoulli sample variance: (μ4 − σ⁴)/n with μ4 = a⁴p(1−p)(1 − 3p(1−p))
    let mu4 = a.powi(4) * p * (1.0 - p) * (1.0 - 3.0 * p * (1.0 - p));
    let z = (var - v0) / ((mu4 - v0 * v0) / n).sqrt();
    assert!(z.abs() < 4.0, "variance {var} vs {v0}: z = {z}");
    let mut s2 = s.clone();
    s2.effects.rtn = Some(Rtn {
        fraction: 0.013,
        log_sigma: 0.5,
        ..b
    });
    let map = rtn_pixel_map(&s2, 4);
    assert_eq!(map.len(), (0.013f64 * n).round() as usize);
    assert_eq!(map.len(), rtn_pixel_count(&s2));
    assert!(map
        .windows(2)
        .all(|w| (w[0].row, w[0].col) < (w[1].row, w[1].col)));
    assert!(map.iter().any(|p| p.amplitude_v != b.amplitude_v));
}

/// Black-level drift: the frame mean of frame j is black + rate·j; the least-squares slope over
/// 40 frames (read noise only) is within 4 standard errors of the rate.
#[test]
fn black_level_drift_slope() {
    let (rows, cols) = (16usize, 32usize);
    let mut s = dark_sensor(rows, cols);
    s.black_level_dn = 100.0;
    let rate = 0.25;
    s.effects.black_level_drift = Some(BlackLevelDrift { dn_per_frame: rate });
    let f = 40usize;
    let y: Vec<f64> = (0..f)
        .map(|j| frame(&s, 3, 0, j as u64, j as u64).iter().sum::<f64>() / (rows * cols) as f64)
        .collect();
    let xm = (f as f64 - 1.0) / 2.0;
    let ym = y.iter().sum::<f64>() / f as f64;
    let sxx: f64 = (0..f).map(|j| (j as f64 - xm).powi(2)).sum();
    let slope = (0..f).map(|j| (j as f64 - xm) * (y[j] - ym)).sum::<f64>() / sxx;
    let k = s.dn_per_output_v();
    let var_mean = (k * k * s.read_noise_v.powi(2) + 1.0 / 12.0) / (rows * cols) as f64;
    let se = (var_mean / sxx).sqrt();
    assert!(
        (slope - rate).abs() < 4.0 * se,
        "slope {slope} vs {rate} (SE {se})"
    );
    let intercept = ym - slope * xm;
    assert!((intercept - 100.0).abs() < 4.0 * (var_mean / f as f64).sqrt() + 4.0 * se * xm);
    let d = BlackLevelDrift { dn_per_frame: rate };
    assert_eq!(d.magnitude_dn(41), 10.0);
    assert_eq!(d.black_level_dn(100.0, 8), 102.0);
}

/// Dark current against temperature per shot: the block's reference temperature gives the
/// sensor's own dark voltage, one doubling temperature above it twice that, 2.5 doublings
/// below 2^−2.5 of it; no block or no shot temperature: the sensor's own.
#[test]
fn dark_voltage_follows_the_doubling_law_per_shot() {
    let mut s = SensorModel::mono_test(4, 4);
    s.dark_voltage_v_per_s = 3e-3;
    assert_eq!(dark_voltage_at(&s, Some(40.0)), 3e-3);
    s.effects.dark_temperature = Some(DarkTemperature {
        reference_temperature_c: 25.0,
        doubling_temperature_c: 6.5,
    });
    assert_eq!(dark_voltage_at(&s, None), 3e-3);
    assert!((dark_voltage_at(&s, Some(25.0)) - 3e-3).abs() < 1e-18);
    assert!((dark_voltage_at(&s, Some(31.5)) - 6e-3).abs() < 1e-15);
    assert!((dark_voltage_at(&s, Some(25.0 - 2.5 * 6.5)) - 3e-3 * 2f64.powf(-2.5)).abs() < 1e-15);
    s.effects.dark_temperature = Some(DarkTemperature {
        reference_temperature_c: 25.0,
        doubling_temperature_c: 0.0,
    });
    assert!(s
        .validate()
        .unwrap_err()
        .to_string()
        .contains("dark_doubling_temperature_c"));
}
