//! Closed-form and statistical tests of the baseline forward model (fixed seeds; every test
//! states its significance level or its tolerance in standard errors).
use camsim_core::{SensorIrradiance, SpectralImage, Spectrum};
use camsim_sensor::poisson::sample_poisson;
use camsim_sensor::*;
use statrs::distribution::{ChiSquared, ContinuousCDF, Discrete, Normal, Poisson};

fn mono(rows: usize, cols: usize) -> SensorModel {
    let mut s = SensorModel::mono_test(rows, cols);
    s.well_capacity_e = 20000.0;
    s
}

fn flat_rate(s: &SensorModel, r: f32) -> ElectronRate {
    ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![r; s.rows * s.cols],
    }
}

fn mean_var(x: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = x.clone().count() as f64;
    let m = x.clone().sum::<f64>() / n;
    let v = x.map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0);
    (m, v)
}

/// Pearson chi-square p-value of observed counts against probabilities (bins already merged
/// so that every expected count is ≥ 5; the probabilities sum to 1).
fn chi_square_p(observed: &[f64], probs: &[f64], n: f64) -> f64 {
    let stat: f64 = observed
        .iter()
        .zip(probs)
        .map(|(o, p)| (o - n * p).powi(2) / (n * p))
        .sum::<f64>();
    ChiSquared::new((observed.len() - 1) as f64)
        .unwrap()
        .sf(stat)
}

/// Bins 0..K of a discrete distribution merged from both tails until expected counts ≥ 5.
fn poisson_gof(samples: &[f64], model_mean: f64) -> f64 {
    let n = samples.len() as f64;
    let pois = Poisson::new(model_mean).unwrap();
    let sd = model_mean.sqrt();
    let lo = (model_mean - 8.0 * sd - 10.0).max(0.0) as u64;
    let hi = (model_mean + 8.0 * sd + 10.0) as u64;
    // Bin edges: start a new bin once its expected count reaches 5.
    let mut edges = vec![]; // (first k, last k, prob)
    let (mut start, mut acc) = (lo, 0.0);
    for k in lo..=hi {
        acc += pois.pmf(k);
        if acc * n >= 5.0 {
            edges.push((start, k, acc));
            start = k + 1;
            acc = 0.0;
        }
    }
    // Tails: everything below lo into the first bin, above the last edge into the last bin.
    let below: f64 = (0..lo).map(|k| pois.pmf(k)).sum();
    edges[0].0 = 0;
    edges[0].2 += below;
    let last = edges.len() - 1;
    edges[last].1 = u64::MAX;
    edges[last].2 = 1.0 - edges[..last].iter().map(|e| e.2).sum::<f64>();
    let mut obs = vec![0f64; edges.len()];
    for &s in samples {
        let k = s as u64;
        let i = edges.partition_point(|e| e.1 < k);
        obs[i] += 1.0;
    }
    let probs: Vec<f64> = edges.iter().map(|e| e.2).collect();
    chi_square_p(&obs, &probs, n)
}

#[test]
fn poisson_sampler_chi_square_goodness_of_fit() {
    // H0: the sampler draws Poisson(mean). Reject at α = 1e-3 per mean. The inversion branch
    // (3, 9.99), algorithm PD just above its threshold (10, 10.5: steps S, Q and E often run,
    // and candidates K < 10 use the exact small-K probabilities), mid (30, 1900.3, 3000) and
    // large means (2e5) are covered.
    let n = 200_000;
    for (i, &mean) in [3.0, 9.99, 10.0, 10.5, 30.0, 1900.3, 3000.0, 2e5]
        .iter()
        .enumerate()
    {
        let mut rng = camsim_core::rng::stream(11, &[i as u64]);
        let x: Vec<f64> = (0..n).map(|_| sample_poisson(&mut rng, mean)).collect();
        let p = poisson_gof(&x, mean);
        assert!(p > 1e-3, "mean {mean}: chi-square p = {p}");
        let (m, v) = mean_var(x.iter().copied());
        // variance = mean (5 standard errors; var of the sample variance ≈ 2σ⁴/n + μ₄ excess)
        let se_v = mean * (2.0 / n as f64).sqrt() * (1.0 + 1.0 / mean).sqrt();
        assert!((v - mean).abs() < 5.0 * se_v, "mean {mean}: var {v}");
        assert!(
            (m - mean).abs() < 5.0 * (mean / n as f64).sqrt(),
            "mean {mean}: mean {m}"
        );
    }
    // A sampler reused across alternating means (its per-mean cache is refreshed on every
    // call) draws the right mixture: each mean's draws fit separately.
    let mut rng = camsim_core::rng::stream(13, &[]);
    let mut ps = camsim_sensor::poisson::PoissonSampler::default();
    let means = [12.5, 2000.0, 4.0];
    let mut xs = vec![Vec::with_capacity(n); 3];
    for i in 0..3 * n {
        xs[i % 3].push(ps.sample(&mut rng, means[i % 3]));
    }
    for (x, &mean) in xs.iter().zip(&means) {
        let p = poisson_gof(x, mean);
        assert!(p > 1e-3, "alternating, mean {mean}: chi-square p = {p}");
    }
    // Power: the same test rejects a 1.7 % error in the mean (30 drawn, 30.5 modelled).
    let mut rng = camsim_core::rng::stream(12, &[]);
    let x: Vec<f64> = (0..n).map(|_| sample_poisson(&mut rng, 30.0)).collect();
    assert!(poisson_gof(&x, 30.5) < 1e-3);
}

#[test]
fn ziggurat_normal_chi_square_goodness_of_fit() {
    // H0: standard_normal draws N(0, 1). 4e6 draws in 0.05-wide bins over [−4.5, 4.5] (the
    // layer edges of the ziggurat fall inside bins, and the tail method takes over at 3.654),
    // the two tails beyond ±4.5 in their own bins; α = 1e-3. Also the mean, the variance and
    // the tail masses beyond ±3.654 (where the tail algorithm acts) within 5 standard errors.
    use camsim_sensor::normal::standard_normal;
    let n = 4_000_000usize;
    let mut rng =
        camsim_sensor::pixel_rng::PixelRng::from_stream(camsim_core::rng::stream(21, &[]));
    let x: Vec<f64> = (0..n).map(|_| standard_normal(&mut rng)).collect();
    let nd = Normal::new(0.0, 1.0).unwrap();
    let w = 0.05;
    let nb = (9.0 / w) as usize; // 180 bins over [−4.5, 4.5]
    let mut obs = vec![0f64; nb + 2];
    for &v in &x {
        let i = if v < -4.5 {
            0
        } else if v >= 4.5 {
            nb + 1
        } else {
            1 + (((v + 4.5) / w) as usize).min(nb - 1)
        };
        obs[i] += 1.0;
    }
    let mut probs = vec![nd.cdf(-4.5)];
    probs.extend((0..nb).map(|b| {
        let a = -4.5 + w * b as f64;
        nd.cdf(a + w) - nd.cdf(a)
    }));
    probs.push(nd.sf(4.5));
    let p = chi_square_p(&obs, &probs, n as f64);
    assert!(p > 1e-3, "normal chi-square p = {p}");
    let (m, v) = mean_var(x.iter().copied());
    assert!(m.abs() < 5.0 / (n as f64).sqrt(), "mean {m}");
    assert!((v - 1.0).abs() < 5.0 * (2.0 / n as f64).sqrt(), "var {v}");
    let r = 3.654_152_885_361_008_8;
    let pt = nd.sf(r);
    let se = (pt * (1.0 - pt) / n as f64).sqrt();
    for (name, count) in [
        ("upper", x.iter().filter(|&&v| v > r).count()),
        ("lower", x.iter().filter(|&&v| v < -r).count()),
    ] {
        let f = count as f64 / n as f64;
        assert!((f - pt).abs() < 5.0 * se, "{name} tail {f} vs {pt}");
    }
    // Power: a 1 % error in σ is rejected by the same test.
    let y: Vec<f64> = x.iter().map(|v| v * 1.01).collect();
    let mut obs2 = vec![0f64; nb + 2];
    for &v in &y {
        let i = if v < -4.5 {
            0
        } else if v >= 4.5 {
            nb + 1
        } else {
            1 + (((v + 4.5) / w) as usize).min(nb - 1)
        };
        obs2[i] += 1.0;
    }
    assert!(chi_square_p(&obs2, &probs, n as f64) < 1e-3);
}

#[test]
fn read_noise_is_normal_in_dn() {
    // Only read noise: DN = round(black + σ_dn z). The exact distribution of the rounded normal
    // is P(k) = Φ((k+½−μ)/σ) − Φ((k−½−μ)/σ); chi-square over 5-DN bins, α = 1e-3.
    let mut s = mono(1000, 1000);
    s.noise = NoiseSwitches {
        read: true,
        ..NoiseSwitches::none()
    };
    s.adc_bits = 16;
    s.dark_voltage_v_per_s = 0.0;
    s.black_level_dn = 1000.0;
    let sigma_dn = 30.0;
    s.read_noise_v = sigma_dn / 65535.0;
    let rate = flat_rate(&s, 0.0);
    let shot = Shot::new(&s, 0.01);
    let f = expose(&s, &rate, &shot, &fixed_pattern(&s, 1), 3, &[0, 0]);
    let nd = Normal::new(1000.0, sigma_dn).unwrap();
    let (lo, hi, w) = (1000 - 130, 1000 + 130, 5); // ±4.3σ, tails merged
    let nb = ((hi - lo) / w) as usize;
    let mut obs = vec![0f64; nb + 2];
    let mut probs = vec![0f64; nb + 2];
    for &d in &f.dn {
        let d = d as i64;
        let i = if d < lo {
            0
        } else if d >= hi {
            nb + 1
        } else {
            1 + ((d - lo) / w) as usize
        };
        obs[i] += 1.0;
    }
    probs[0] = nd.cdf(lo as f64 - 0.5);
    probs[nb + 1] = nd.sf(hi as f64 - 0.5);
    for b in 0..nb {
        let a = (lo + w * b as i64) as f64 - 0.5;
        probs[b + 1] = nd.cdf(a + w as f64) - nd.cdf(a);
    }
    let p = chi_square_p(&obs, &probs, f.dn.len() as f64);
    assert!(p > 1e-3, "read noise chi-square p = {p}");
    // Power: a 3 % wrong σ is rejected.
    let nd2 = Normal::new(1000.0, sigma_dn * 1.03).unwrap();
    probs[0] = nd2.cdf(lo as f64 - 0.5);
    probs[nb + 1] = nd2.sf(hi as f64 - 0.5);
    for b in 0..nb {
        let a = (lo + w * b as i64) as f64 - 0.5;
        probs[b + 1] = nd2.cdf(a + w as f64) - nd2.cdf(a);
    }
    assert!(chi_square_p(&obs, &probs, f.dn.len() as f64) < 1e-3);
}

#[test]
fn photon_transfer_slope_is_conversion_gain_in_dn_per_e() {
    // Only shot noise: var(DN) = K² e + 1/12 and mean(DN) = K e + black, so var vs mean has
    // slope K = analog_gain · g / swing · (2^bits − 1). 40 000 pixels per exposure give a
    // variance standard error of 0.7 %; tolerance 2 % on the fitted slope.
    let mut s = mono(200, 200);
    s.noise = NoiseSwitches {
        shot: true,
        ..NoiseSwitches::none()
    };
    s.dark_voltage_v_per_s = 0.0;
    let shot_gain = 2.0;
    let k = s.dn_per_e(shot_gain);
    assert!((k - 2.0 * 1e-4 * 4095.0).abs() < 1e-12);
    let rate = flat_rate(&s, 1e5);
    let fp = fixed_pattern(&s, 1);
    let (mut xs, mut ys) = (vec![], vec![]);
    for (i, t) in [0.002, 0.005, 0.01, 0.015, 0.02, 0.025, 0.03, 0.04]
        .iter()
        .enumerate()
    {
        let shot = Shot {
            exposure_s: *t,
            analog_gain: shot_gain,
        };
        let f = expose(&s, &rate, &shot, &fp, 9, &[i as u64, 0]);
        let (m, v) = mean_var(f.dn.iter().map(|&d| d as f64));
        xs.push(m);
        ys.push(v);
    }
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let slope = sxy / sxx;
    assert!(
        (slope / k - 1.0).abs() < 0.02,
        "PTC slope {slope} vs K = {k}"
    );
}

#[test]
fn quantisation_adds_one_twelfth_and_clamps() {
    // Only read noise with σ = 1.5 DN: var(DN) = σ² + 1/12 (Sheppard; exact to < 1e-15 here).
    // 1e6 pixels: standard error of the variance ≈ σ²√(2/n) ≈ 0.0033 DN²; 4 s.e. tolerance;
    // the 1/12 = 0.083 DN² term is 25 s.e., so omitting it fails.
    let mut s = mono(1000, 1000);
    s.noise = NoiseSwitches {
        read: true,
        ..NoiseSwitches::none()
    };
    s.dark_voltage_v_per_s = 0.0;
    s.black_level_dn = 100.3;
    let sigma_dn = 1.5;
    s.read_noise_v = sigma_dn / 4095.0;
    let rate = flat_rate(&s, 0.0);
    let f = expose(
        &s,
        &rate,
        &Shot::new(&s, 0.01),
        &fixed_pattern(&s, 1),
        4,
        &[0, 0],
    );
    let (m, v) = mean_var(f.dn.iter().map(|&d| d as f64));
    let want = sigma_dn * sigma_dn + 1.0 / 12.0;
    let se = sigma_dn * sigma_dn * (2.0 / 1e6f64).sqrt();
    assert!((v - want).abs() < 4.0 * se, "var {v} vs {want}");
    assert!((m - 100.3).abs() < 4.0 * 1.53 / 1000.0, "mean {m}");

    // Clamping at 2^bits − 1: bright pixels, large black level.
    let mut b = mono(10, 10);
    b.black_level_dn = 300.0;
    b.well_capacity_e = 1e9;
    let f = expose(
        &b,
        &flat_rate(&b, 1e9),
        &Shot::new(&b, 1.0),
        &fixed_pattern(&b, 1),
        1,
        &[0],
    );
    assert!(f.dn.iter().all(|&d| d == 4095));
    // Clamping at 0: negative output voltage (offset −0.5 V).
    let mut z = mono(10, 10);
    z.analog_offset_v = -0.5;
    let f = expose(
        &z,
        &flat_rate(&z, 0.0),
        &Shot::new(&z, 0.01),
        &fixed_pattern(&z, 1),
        1,
        &[0],
    );
    assert!(f.dn.iter().all(|&d| d == 0));
    // Rounding to nearest: fractional black level, no noise, no light.
    let mut r = mono(2, 2);
    r.noise = NoiseSwitches::none();
    r.dark_voltage_v_per_s = 0.0;
    for (bl, want) in [(0.4, 0u16), (0.6, 1), (7.49, 7), (7.51, 8)] {
        r.black_level_dn = bl;
        let f = expose(
            &r,
            &flat_rate(&r, 0.0),
            &Shot::new(&r, 0.1),
            &fixed_pattern(&r, 1),
            1,
            &[],
        );
        assert!(f.dn.iter().all(|&d| d == want), "black {bl}");
    }
}

#[test]
fn well_clipping() {
    // Mean far above the well: every pixel holds exactly the well, DN = round(well·g/swing·4095
    // + black) = round(0.5·4095 + 64.2) = 2112; with read/DSNU off the frame is constant.
    let mut s = mono(50, 50);
    s.noise = NoiseSwitches {
        shot: true,
        dark: true,
        prnu: true,
        ..NoiseSwitches::none()
    };
    s.well_capacity_e = 5000.0;
    s.black_level_dn = 64.2;
    let rate = flat_rate(&s, 1e6);
    let f = expose(
        &s,
        &rate,
        &Shot::new(&s, 0.1),
        &fixed_pattern(&s, 2),
        1,
        &[0, 0],
    );
    assert!(f.dn.iter().all(|&d| d == 2112), "{:?}", &f.dn[..5]);
    let e = expected_dn(&s, &rate, &Shot::new(&s, 0.1));
    assert!((e[0] - 2111.7).abs() < 1e-3);
    // At mean = well exactly, about half of the pixels clip (P(Poisson(5000) ≥ 5000) ≈ 0.5):
    // the highest DN is the clipped value and no pixel exceeds it.
    let mut s2 = s.clone();
    s2.noise = NoiseSwitches {
        shot: true,
        ..NoiseSwitches::none()
    };
    s2.dark_voltage_v_per_s = 0.0;
    let f = expose(
        &s2,
        &flat_rate(&s2, 5e4),
        &Shot::new(&s2, 0.1),
        &fixed_pattern(&s2, 2),
        1,
        &[1],
    );
    let clipped = f.dn.iter().filter(|&&d| d == 2112).count() as f64 / 2500.0;
    assert!(f.dn.iter().all(|&d| d <= 2112));
    // P(n ≥ 5000 | Poisson 5000) = 0.5038; the well DN bin also holds n in ~[4998.8, 5000).
    assert!((clipped - 0.51).abs() < 0.05, "clipped fraction {clipped}");
}

#[test]
fn flat_field_matches_expected_mean_and_model_variance() {
    // 1000 × 1000 flat field through electron_rate (single huge irradiance cell), every noise
    // source on plus column FPN and reset noise without CDS. Mean within 0.5 % of expected_dn,
    // spatial variance within 3 % of
    //   K_v² [g² (e + d + e² σ_P²) + σ_D² + σ_r² + σ_col² + σ_reset²] + 1/12,
    // K_v = gain/swing·(2^bits−1). (Standard error of the variance here ≈ 0.15 %.)
    let mut s = mono(1000, 1000);
    s.column_fpn = Some(ColumnFpn {
        offset_sigma_v: 0.5e-3,
    });
    s.reset_noise = Some(ResetNoise {
        sigma_v: 1e-3,
        cds: false,
    });
    let photons = 1e17 / 300.0; // photons/(s·m²·nm) flat over 400–700 nm
    let irr = SensorIrradiance {
        irradiance: SpectralImage::from_single_spectrum(
            1,
            1,
            Spectrum::sampled(vec![400.0, 700.0], vec![1.0, 1.0]).unwrap(),
            vec![photons as f32],
        ),
        sample_pitch_m: 1.0,
    };
    let rate = electron_rate(&s, &irr);
    let r0 = 4e-12 * 1e17; // p² · ∫E = 4e5 e/s
    assert!((rate.electrons_per_s[0] as f64 / r0 - 1.0).abs() < 1e-6);
    let shot = Shot::new(&s, 0.005); // e = 2000, d = 0.05
    let fp = fixed_pattern(&s, 77);
    let f = expose(&s, &rate, &shot, &fp, 77, &[0, 0]);
    let exp = expected_dn(&s, &rate, &shot);
    let (m, v) = mean_var(f.dn.iter().map(|&d| d as f64));
    let em = exp.iter().map(|&x| x as f64).sum::<f64>() / exp.len() as f64;
    assert!((m / em - 1.0).abs() < 0.005, "mean {m} vs expected {em}");
    let (e, d, g) = (2000.0, 0.05, 1e-4);
    let kv = 4095.0;
    let var_v = g * g * (e + d + (e * 0.01f64).powi(2)) + 1e-6 + 1e-6 + 0.25e-6 + 1e-6;
    let model = kv * kv * var_v + 1.0 / 12.0;
    assert!((v / model - 1.0).abs() < 0.03, "var {v} vs model {model}");
    // Without the noise sources the variance would be far off (the test can fail):
    assert!((kv * kv * g * g * e + 1.0 / 12.0) / model < 0.8);
    // With CDS the reset noise cancels.
    let mut c = s.clone();
    c.reset_noise = Some(ResetNoise {
        sigma_v: 1e-3,
        cds: true,
    });
    let f2 = expose(&c, &rate, &shot, &fp, 77, &[0, 0]);
    let (_, v2) = mean_var(f2.dn.iter().map(|&d| d as f64));
    let model2 = model - kv * kv * 1e-6;
    assert!((v2 / model2 - 1.0).abs() < 0.03, "CDS var {v2} vs {model2}");
}

#[test]
fn frames_are_bit_identical_across_thread_counts() {
    let mut s = mono(301, 257);
    s.column_fpn = Some(ColumnFpn {
        offset_sigma_v: 1e-3,
    });
    s.reset_noise = Some(ResetNoise {
        sigma_v: 1e-3,
        cds: false,
    });
    let rate = ElectronRate {
        rows: 301,
        cols: 257,
        electrons_per_s: (0..301 * 257).map(|i| (i % 1000) as f32 * 500.0).collect(),
    };
    let shot = Shot::new(&s, 0.02);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let fp = fixed_pattern(&s, 42);
                let f = expose(&s, &rate, &shot, &fp, 42, &[3, 1]);
                (fp, f)
            })
    };
    let (fp1, f1) = run(1);
    let (fp2, f2) = run(2);
    assert_eq!(fp1, fp2);
    assert_eq!(f1, f2);
    // A different frame index gives a different frame, the same seed the same one.
    let f3 = expose(&s, &rate, &shot, &fp1, 42, &[3, 2]);
    assert_ne!(f1, f3);
    assert_eq!(f1, expose(&s, &rate, &shot, &fp1, 42, &[3, 1]));
}

#[test]
fn seeded_patterns_give_the_same_frames_as_the_maps() {
    // expose_with(PatternSource::Seeded(s)) draws the PRNU/DSNU rows inside the frame loop
    // from the streams of fixed_pattern(sensor, s): frames must be bit-identical to those made
    // with the maps, for every switch combination, at 1 and 2 threads, and another pattern
    // seed must give another frame.
    let mut s = mono(67, 129);
    s.column_fpn = Some(ColumnFpn {
        offset_sigma_v: 1e-3,
    });
    s.reset_noise = Some(ResetNoise {
        sigma_v: 1e-3,
        cds: false,
    });
    let rate = ElectronRate {
        rows: 67,
        cols: 129,
        electrons_per_s: (0..67 * 129).map(|i| (i % 300) as f32 * 700.0).collect(),
    };
    let shot = Shot::new(&s, 0.02);
    let fp = fixed_pattern(&s, 5);
    for bits in 0..32u32 {
        s.noise = NoiseSwitches {
            shot: bits & 1 != 0,
            dark: bits & 2 != 0,
            read: bits & 4 != 0,
            dsnu: bits & 8 != 0,
            prnu: bits & 16 != 0,
        };
        let maps = expose(&s, &rate, &shot, &fp, 9, &[0, 1]);
        for threads in [1, 2] {
            let seeded = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| expose_with(&s, &rate, &shot, PatternSource::Seeded(5), 9, &[0, 1]));
            assert_eq!(seeded, maps, "switches {:?}, {threads} threads", s.noise);
        }
        if s.noise.dsnu || s.noise.prnu {
            let other = expose_with(&s, &rate, &shot, PatternSource::Seeded(6), 9, &[0, 1]);
            assert_ne!(other, maps, "switches {:?}", s.noise);
        }
    }
}

#[test]
#[ignore = "timing; run with --release -- --ignored --nocapture"]
fn timing_12_megapixel_frame() {
    let mut s = mono(3000, 4000);
    s.column_fpn = Some(ColumnFpn {
        offset_sigma_v: 1e-3,
    });
    let rate = ElectronRate {
        rows: 3000,
        cols: 4000,
        electrons_per_s: (0..12_000_000).map(|i| (i % 4093) as f32 * 50.0).collect(),
    };
    let shot = Shot::new(&s, 0.02);
    let fp = fixed_pattern(&s, 1);
    let _ = expose(&s, &rate, &shot, &fp, 1, &[0, 0]);
    let configs = [
        ("all noise", NoiseSwitches::default()),
        (
            "shot only",
            NoiseSwitches {
                shot: true,
                ..NoiseSwitches::none()
            },
        ),
        (
            "read only",
            NoiseSwitches {
                read: true,
                ..NoiseSwitches::none()
            },
        ),
        ("none", NoiseSwitches::none()),
    ];
    for (name, sw) in configs {
        s.noise = sw;
        let t0 = std::time::Instant::now();
        for i in 0..3 {
            std::hint::black_box(expose(&s, &rate, &shot, &fp, 1, &[0, i]));
        }
        let dt = t0.elapsed().as_secs_f64() / 3.0;
        println!(
            "12 MP frame, {name}: {dt:.3} s ({} threads)",
            rayon::current_num_threads()
        );
    }
}

#[test]
#[ignore = "timing; run with --release -- --ignored --nocapture"]
fn timing_poisson_sampler() {
    use rand::RngExt;
    let mut rng = camsim_core::rng::stream(1, &[]);
    for mean in [3.0, 30.0, 1000.0, 4000.0] {
        let t0 = std::time::Instant::now();
        let mut acc = 0.0;
        for _ in 0..2_000_000 {
            acc += sample_poisson(&mut rng, mean);
        }
        let dt = t0.elapsed().as_secs_f64() / 2e6 * 1e9;
        println!("poisson mean {mean}: {dt:.1} ns/draw ({acc})");
    }
    for mean in [30.0, 1000.0, 4000.0] {
        let t0 = std::time::Instant::now();
        let mut acc = 0.0;
        for i in 0..2_000_000 {
            let p = rand_distr::Poisson::new(mean + (i % 7) as f64).unwrap();
            acc += rng.sample::<f64, _>(p);
        }
        let dt = t0.elapsed().as_secs_f64() / 2e6 * 1e9;
        println!("rand_distr poisson mean {mean}: {dt:.1} ns/draw ({acc})");
    }
    let t0 = std::time::Instant::now();
    let mut acc = 0.0;
    for _ in 0..2_000_000 {
        acc += rng.random::<f64>();
    }
    println!(
        "uniform: {:.1} ns ({acc})",
        t0.elapsed().as_secs_f64() / 2e6 * 1e9
    );
    let t0 = std::time::Instant::now();
    let mut acc = 0.0;
    for _ in 0..2_000_000 {
        acc += rng.sample::<f64, _>(rand_distr::StandardNormal);
    }
    println!(
        "normal: {:.1} ns ({acc})",
        t0.elapsed().as_secs_f64() / 2e6 * 1e9
    );
}
