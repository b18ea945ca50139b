//! Steps 3–7 of the baseline forward model: electrons, noise, volts, ADC.
use crate::effects::{hot_row, HotPixel, Nonlinearity};
use crate::normal::Ziggurat;
use crate::pixel_rng::PixelRng;
use crate::poisson::PoissonSampler;
use crate::{ElectronRate, FixedPattern, SensorModel, Shot};
use camsim_core::rng::stream;
use camsim_core::RawFrame;
use rayon::prelude::*;

pub use crate::pixel_rng::FIXED_PATTERN_TAG;

/// Draws the fixed per-pixel patterns of a camera: `1 + P_i` with `P_i ~ N(0, prnu²)` (step 4),
/// `D_i ~ N(0, dsnu²)` (step 5) and, with column FPN, one N(0, σ²) offset per column. The
/// patterns depend only on `seed` and the sensor size (one stream per row), not on the thread
/// count; the noise switches are applied later, in [`expose`].
pub fn fixed_pattern(sensor: &SensorModel, seed: u64) -> FixedPattern {
    let (rows, cols) = (sensor.rows, sensor.cols);
    let per_row = |kind: u64, sigma: f64, base: f32| -> Vec<f32> {
        let mut out = vec![base; rows * cols];
        if sigma > 0.0 {
            out.par_chunks_mut(cols)
                .enumerate()
                .for_each(|(r, row)| pattern_row(seed, kind, r, sigma, base, row));
        }
        out
    };
    // Step 4: PRNU gain 1 + P_i, P_i ~ N(0, (prnu_percent/100)²).
    let prnu_gain = per_row(0, sensor.prnu_sigma_percent / 100.0, 1.0);
    // Step 5: DSNU offset D_i ~ N(0, dsnu²) volts.
    let dsnu_v = per_row(1, sensor.dsnu_sigma_v, 0.0);
    FixedPattern {
        prnu_gain,
        dsnu_v,
        column_offset_v: column_offsets(sensor, seed),
        hot_pixels: crate::effects::hot_pixel_map(sensor, seed),
    }
}

/// Per-shot constants of steps 3–7.
pub(crate) struct Chain {
    t: f64,
    dark_e: f64,
    well: f64,
    g: f64,
    gain: f64,
    offset: f64,
    swing: f64,
    dn_per_v: f64,
    black: f64,
    max_dn: f64,
    /// Optional pixel-voltage nonlinearity (effect block), step 5.
    nl: Option<Nonlinearity>,
}

impl Chain {
    pub(crate) fn new(sensor: &SensorModel, shot: &Shot) -> Self {
        Chain {
            t: shot.exposure_s,
            // Step 3: d = t · dark_voltage / conversion_gain.
            dark_e: shot.exposure_s * sensor.dark_voltage_v_per_s / sensor.conversion_gain_v_per_e,
            well: sensor.well_capacity_e,
            g: sensor.conversion_gain_v_per_e,
            gain: shot.analog_gain,
            offset: sensor.analog_offset_v,
            swing: sensor.voltage_swing_v,
            dn_per_v: sensor.dn_per_output_v(),
            black: sensor.black_level_dn,
            max_dn: sensor.max_dn(),
            nl: sensor.effects.nonlinearity,
        }
    }

    /// Step 6: u = gain · v + offset, clipped above at the swing.
    #[inline]
    fn output_v(&self, v: f64) -> f64 {
        (self.gain * v + self.offset).min(self.swing)
    }

    /// Step 7 without rounding: u / swing · (2^bits − 1) + black, clamped to [0, 2^bits − 1].
    #[inline]
    pub(crate) fn dn(&self, u: f64) -> f64 {
        (u * self.dn_per_v + self.black).clamp(0.0, self.max_dn)
    }

    /// Expected output voltage u of a pixel with electron rate `rate` (all random terms at
    /// their means).
    #[inline]
    pub(crate) fn expected_u(&self, rate: f64) -> f64 {
        // Steps 2–4: n = min(e + d, well); step 5: v = n·g (then the optional nonlinearity).
        let n = (rate * self.t + self.dark_e).min(self.well);
        let v = n * self.g;
        match &self.nl {
            None => self.output_v(v),
            Some(nl) => self.output_v(nl.apply(v)),
        }
    }
}

fn check_rate(sensor: &SensorModel, rate: &ElectronRate) {
    assert!(
        rate.rows == sensor.rows
            && rate.cols == sensor.cols
            && rate.electrons_per_s.len() == sensor.rows * sensor.cols,
        "electron rate is {}×{} but the sensor is {}×{}",
        rate.rows,
        rate.cols,
        sensor.rows,
        sensor.cols
    );
}

/// Expected output voltage u (step 6) of every pixel: P = D = r = 0, n = min(e + d, well).
pub fn expected_volts(sensor: &SensorModel, rate: &ElectronRate, shot: &Shot) -> Vec<f32> {
    check_rate(sensor, rate);
    let ch = Chain::new(sensor, shot);
    rate.electrons_per_s
        .par_iter()
        .map(|&r| ch.expected_u(r as f64) as f32)
        .collect()
}

/// The expected (noise-free) image of a shot in DN: steps 2–7 with every random term at its
/// mean (P = D = r = 0, n = min(e + d, well)) and no rounding; fixed patterns are left out.
pub fn expected_dn(sensor: &SensorModel, rate: &ElectronRate, shot: &Shot) -> Vec<f32> {
    check_rate(sensor, rate);
    let ch = Chain::new(sensor, shot);
    rate.electrons_per_s
        .par_iter()
        .map(|&r| ch.dn(ch.expected_u(r as f64)) as f32)
        .collect()
}

/// Where [`expose`] takes the fixed per-pixel patterns from.
#[derive(Debug, Clone, Copy)]
pub enum PatternSource<'a> {
    /// Precomputed maps ([`fixed_pattern`]).
    Maps(&'a FixedPattern),
    /// Drawn row by row, inside the frame loop, from the same per-row streams that
    /// [`fixed_pattern`]`(sensor, seed)` uses: bit-identical values without the full-size maps
    /// (cheaper for a frame or two; for many frames of one camera the maps are reused).
    Seeded(u64),
}

/// One row of PRNU gains `1 + P_i` or DSNU offsets `D_i` (kind 0 / 1), exactly as
/// [`fixed_pattern`] draws row `r`.
#[inline]
fn pattern_row(seed: u64, kind: u64, r: usize, sigma: f64, base: f32, row: &mut [f32]) {
    if sigma > 0.0 {
        let mut rng = PixelRng::from_stream(stream(seed, &[FIXED_PATTERN_TAG, kind, r as u64]));
        let zig = Ziggurat::new();
        for o in row.iter_mut() {
            *o = (base as f64 + sigma * zig.sample(&mut rng)) as f32;
        }
    } else {
        row.fill(base);
    }
}

/// Column offsets as [`fixed_pattern`] draws them (zeros without column FPN).
fn column_offsets(sensor: &SensorModel, seed: u64) -> Vec<f32> {
    let col_sigma = sensor.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
    if col_sigma > 0.0 {
        let mut rng = stream(seed, &[FIXED_PATTERN_TAG, 2]);
        (0..sensor.cols)
            .map(|_| (col_sigma * crate::normal::standard_normal(&mut rng)) as f32)
            .collect()
    } else {
        vec![0.0; sensor.cols]
    }
}

/// Simulates one frame of a shot (steps 3–7). Row `r` draws from
/// `stream(seed, &[stream…, r])`, so a frame is bit-identical whatever the thread count;
/// `stream` is `[shot index, frame index]`.
///
/// Per pixel: `n = min(Poisson(e(1+P) + d), well)` (a switched-off shot or dark term enters at
/// its mean), `v = n g + D + column offset + r (+ reset noise without CDS)`,
/// `u = min(gain · v + offset, swing)`, `DN = clamp(round(u/swing · (2^bits−1) + black))`.
pub fn expose(
    sensor: &SensorModel,
    rate: &ElectronRate,
    shot: &Shot,
    fixed: &FixedPattern,
    seed: u64,
    stream_ids: &[u64],
) -> RawFrame {
    expose_with(
        sensor,
        rate,
        shot,
        PatternSource::Maps(fixed),
        seed,
        stream_ids,
    )
}

/// [`expose`] with the fixed patterns from `pattern`: `PatternSource::Seeded(s)` gives the
/// same frame as `expose(…, &fixed_pattern(sensor, s), …)` without building the maps.
pub fn expose_with(
    sensor: &SensorModel,
    rate: &ElectronRate,
    shot: &Shot,
    pattern: PatternSource<'_>,
    seed: u64,
    stream_ids: &[u64],
) -> RawFrame {
    expose_frame(sensor, rate, shot, pattern, seed, stream_ids, 0)
}

/// [`expose_with`] for the frame with global index `frame_index` in its capture set (capture
/// order): the frame-dependent blocks of [`crate::line_noise`] use it — black-level drift
/// (`black + rate·frame_index`) and the RTN trap states (positions from the camera seed
/// `seed`); row noise draws one offset per row from `stream(seed, [ROW_NOISE_TAG,
/// stream…])`. Without those blocks the frame is [`expose_with`]'s, bit for bit.
pub fn expose_frame(
    sensor: &SensorModel,
    rate: &ElectronRate,
    shot: &Shot,
    pattern: PatternSource<'_>,
    seed: u64,
    stream_ids: &[u64],
    frame_index: u64,
) -> RawFrame {
    check_rate(sensor, rate);
    let row_off = crate::line_noise::row_offsets_v(sensor, seed, stream_ids);
    let rtn_on = crate::line_noise::rtn_offsets_v(sensor, seed, frame_index);
    let (rows, cols) = (sensor.rows, sensor.cols);
    let sw = sensor.noise;
    let seeded_cols;
    let seeded_hot;
    // Hot pixels (effect block): the fixed map, or drawn once per frame from the seed.
    let hot: &[HotPixel] = match pattern {
        PatternSource::Maps(fixed) => &fixed.hot_pixels,
        PatternSource::Seeded(s) => {
            seeded_hot = crate::effects::hot_pixel_map(sensor, s);
            &seeded_hot
        }
    };
    let col_off: &[f32] = match pattern {
        PatternSource::Maps(fixed) => {
            if sw.prnu {
                assert_eq!(fixed.prnu_gain.len(), rows * cols, "PRNU pattern size");
            }
            if sw.dsnu {
                assert_eq!(fixed.dsnu_v.len(), rows * cols, "DSNU pattern size");
            }
            &fixed.column_offset_v
        }
        PatternSource::Seeded(s) => {
            seeded_cols = column_offsets(sensor, s);
            &seeded_cols
        }
    };
    let zero_cols = vec![0f32; cols];
    let col_off: &[f32] = if sensor.column_fpn.is_some() && col_off.len() == cols {
        col_off
    } else {
        &zero_cols
    };
    let mut ch = Chain::new(sensor, shot);
    if let Some(d) = sensor.effects.black_level_drift {
        ch.black = d.black_level_dn(ch.black, frame_index);
    }
    let k = Kernel {
        ch,
        sw,
        read_sigma: if sw.read { sensor.read_noise_v } else { 0.0 },
        // Reset (kTC) noise: cancelled by CDS, else a new N(0, σ²) per pixel and frame (step 5).
        reset_sigma: sensor
            .reset_noise
            .filter(|r| !r.cds)
            .map_or(0.0, |r| r.sigma_v),
    };
    let prnu_sigma = sensor.prnu_sigma_percent / 100.0;
    let mut dn = vec![0u16; rows * cols];
    dn.par_chunks_mut(cols)
        .enumerate()
        .for_each_init(RowBuffers::default, |bufs, (r, out)| {
            let mut ids = Vec::with_capacity(stream_ids.len() + 1);
            ids.extend_from_slice(stream_ids);
            ids.push(r as u64);
            let mut rng = PixelRng::from_stream(stream(seed, &ids));
            let base = r * cols;
            let rates = &rate.electrons_per_s[base..base + cols];
            let RowBuffers {
                prnu: pbuf,
                dsnu: dbuf,
                electrons,
                volts,
            } = bufs;
            let (prnu, dsnu): (Option<&[f32]>, Option<&[f32]>) = match pattern {
                PatternSource::Maps(f) => (
                    sw.prnu.then(|| &f.prnu_gain[base..base + cols]),
                    sw.dsnu.then(|| &f.dsnu_v[base..base + cols]),
                ),
                PatternSource::Seeded(s) => {
                    if sw.prnu {
                        pbuf.resize(cols, 0.0);
                        pattern_row(s, 0, r, prnu_sigma, 1.0, pbuf);
                    }
                    if sw.dsnu {
                        dbuf.resize(cols, 0.0);
                        pattern_row(s, 1, r, sensor.dsnu_sigma_v, 0.0, dbuf);
                    }
                    (sw.prnu.then_some(&pbuf[..]), sw.dsnu.then_some(&dbuf[..]))
                }
            };
            electrons.resize(cols, 0.0);
            volts.resize(cols, 0.0);
            let hot = hot_row(hot, r);
            // Row noise and RTN (effect blocks): the row's offsets in volts on top of the
            // column offsets (a row-local copy; without the blocks the column offsets as they
            // are).
            let rtn_row: &[(usize, f64)] = {
                let a = rtn_on.partition_point(|x| x.0 < base);
                let b = rtn_on.partition_point(|x| x.0 < base + cols);
                &rtn_on[a..b]
            };
            let with_row: Vec<f32>;
            let col_off: &[f32] = if row_off.is_some() || !rtn_row.is_empty() {
                let dr = row_off.as_ref().map_or(0.0, |o| o[r]);
                let mut v: Vec<f32> = col_off.iter().map(|&c| (c as f64 + dr) as f32).collect();
                for &(i, a) in rtn_row {
                    v[i - base] = (v[i - base] as f64 + a) as f32;
                }
                with_row = v;
                &with_row
            } else {
                col_off
            };
            k.row(
                rates, prnu, dsnu, col_off, hot, &mut rng, electrons, volts, out,
            );
        });
    RawFrame {
        rows,
        cols,
        adc_bits: sensor.adc_bits,
        dn,
        layout: Some(sensor.raw_layout()),
    }
}

/// Per-thread row buffers of [`expose_with`].
#[derive(Default)]
struct RowBuffers {
    prnu: Vec<f32>,
    dsnu: Vec<f32>,
    electrons: Vec<f64>,
    volts: Vec<f64>,
}

/// Whether the CPU has AVX2 and BMI1/2 (checked once).
#[cfg(target_arch = "x86_64")]
fn avx2() -> bool {
    static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *HAS.get_or_init(|| {
        std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("bmi1")
            && std::is_x86_feature_detected!("bmi2")
    })
}

/// Per-frame constants of the pixel loop of [`expose`].
struct Kernel {
    ch: Chain,
    sw: crate::NoiseSwitches,
    read_sigma: f64,
    reset_sigma: f64,
}

impl Kernel {
    /// One row of DN from its electron rates, PRNU gains and DSNU offsets (None: switched off).
    ///
    /// The row is done in passes so that the random draws run in tight loops and the
    /// arithmetic vectorises: (1) mean electrons, (2) electrons n (all Poisson draws of the
    /// row, in column order), (3) temporal voltage noise (then all read-noise normals, each
    /// followed by its reset-noise normal), (4) volts → DN.
    #[allow(clippy::too_many_arguments)]
    fn row(
        &self,
        rates: &[f32],
        prnu: Option<&[f32]>,
        dsnu: Option<&[f32]>,
        col_off: &[f32],
        hot: &[HotPixel],
        rng: &mut PixelRng,
        n: &mut [f64],
        noise: &mut [f64],
        out: &mut [u16],
    ) {
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports the features the function is compiled for.
            unsafe { self.row_avx2(rates, prnu, dsnu, col_off, hot, rng, n, noise, out) };
            return;
        }
        self.row_impl(rates, prnu, dsnu, col_off, hot, rng, n, noise, out);
    }

    /// [`Kernel::row_impl`] compiled for AVX2/BMI2: wider vectors in the arithmetic passes
    /// and shorter generator code. IEEE arithmetic is the same with and without these
    /// instructions (no fused multiply-add is used), so the results are bit-identical.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,bmi1,bmi2")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn row_avx2(
        &self,
        rates: &[f32],
        prnu: Option<&[f32]>,
        dsnu: Option<&[f32]>,
        col_off: &[f32],
        hot: &[HotPixel],
        rng: &mut PixelRng,
        n: &mut [f64],
        noise: &mut [f64],
        out: &mut [u16],
    ) {
        self.row_impl(rates, prnu, dsnu, col_off, hot, rng, n, noise, out);
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn row_impl(
        &self,
        rates: &[f32],
        prnu: Option<&[f32]>,
        dsnu: Option<&[f32]>,
        col_off: &[f32],
        hot: &[HotPixel],
        rng: &mut PixelRng,
        n: &mut [f64],
        noise: &mut [f64],
        out: &mut [u16],
    ) {
        let (ch, sw) = (&self.ch, self.sw);
        // (1) Step 2: mean photo-electrons e = rate · t; step 4: PRNU scales the signal (never
        // negative).
        match prnu {
            Some(p) => n
                .iter_mut()
                .zip(rates)
                .zip(p)
                .for_each(|((e, &r), &g)| *e = mean_electrons(r as f64 * ch.t * g as f64)),
            None => n
                .iter_mut()
                .zip(rates)
                .for_each(|(e, &r)| *e = mean_electrons(r as f64 * ch.t)),
        }
        // (2) Step 4: n ~ Poisson(e(1+P) + d), a switched-off term at its mean; clipped at the
        // well capacity.
        let mut pois = PoissonSampler::default();
        let (d, well) = (ch.dark_e, ch.well);
        if !hot.is_empty() {
            // A row with hot pixels (effect block): per-pixel dark charge d + t·V_hot/g, drawn
            // like the dark charge.
            let mut next = hot.iter().peekable();
            for (c, e) in n.iter_mut().enumerate() {
                let mut dc = d;
                if let Some(h) = next.next_if(|h| h.col as usize == c) {
                    dc += ch.t * h.dark_voltage_v_per_s as f64 / ch.g;
                }
                let v = match (sw.shot, sw.dark) {
                    (true, true) => pois.sample_saturating(rng, *e + dc),
                    (true, false) => pois.sample_saturating(rng, *e) + dc,
                    (false, true) => *e + pois.sample_saturating(rng, dc),
                    (false, false) => *e + dc,
                };
                *e = v.min(well);
            }
        } else {
            match (sw.shot, sw.dark) {
                (true, true) => n
                    .iter_mut()
                    .for_each(|e| *e = pois.sample_saturating(rng, *e + d).min(well)),
                (true, false) => n
                    .iter_mut()
                    .for_each(|e| *e = (pois.sample_saturating(rng, *e) + d).min(well)),
                (false, true) => n
                    .iter_mut()
                    .for_each(|e| *e = (*e + pois.sample_saturating(rng, d)).min(well)),
                (false, false) => n.iter_mut().for_each(|e| *e = (*e + d).min(well)),
            }
        }
        // Step 5, effect block: the nonlinearity maps v = n·g (kept as n = v'/g).
        if let Some(nl) = &ch.nl {
            let g = ch.g;
            n.iter_mut().for_each(|e| *e = nl.apply(*e * g) / g);
        }
        // (3) Step 5: read noise r (+ reset noise without CDS), volts.
        let zig = Ziggurat::new();
        let standard_normal = |rng: &mut PixelRng| zig.sample(rng);
        match (self.read_sigma > 0.0, self.reset_sigma > 0.0) {
            (true, true) => noise.iter_mut().for_each(|v| {
                let r = self.read_sigma * standard_normal(rng);
                *v = r + self.reset_sigma * standard_normal(rng);
            }),
            (true, false) => noise
                .iter_mut()
                .for_each(|v| *v = self.read_sigma * standard_normal(rng)),
            (false, true) => noise
                .iter_mut()
                .for_each(|v| *v = self.reset_sigma * standard_normal(rng)),
            (false, false) => noise.fill(0.0),
        }
        // (4) Step 5: v = n·g + column offset + D + r; steps 6–7: output volts, rounding,
        // clamping. Clamp first, then round half up by truncation (non-negative, so this equals
        // round-half-away-from-zero; avoids a libm call per pixel).
        let quantise = |n: f64, col: f32, dsnu: f64, r: f64| -> u16 {
            let v = n * ch.g + col as f64 + dsnu + r;
            let u = ch.output_v(v);
            // In [0, 65535.5] after the clamp: `as i32` is exact and vectorises.
            ((u * ch.dn_per_v + ch.black).clamp(0.0, ch.max_dn) + 0.5) as i32 as u16
        };
        match dsnu {
            Some(ds) => {
                for c in 0..out.len() {
                    out[c] = quantise(n[c], col_off[c], ds[c] as f64, noise[c]);
                }
            }
            None => {
                for c in 0..out.len() {
                    out[c] = quantise(n[c], col_off[c], 0.0, noise[c]);
                }
            }
        }
    }
}

/// Exposure (s) at which the expected output voltage of the brightest pixel reaches
/// `target_fraction_of_swing · swing` (camera's analog gain and offset; dark current
/// included): `t = (f·swing − offset) / (gain · (g · rate_max + dark_voltage))`.
///
/// If the brightest pixel's well fills before that voltage is reached, the time at which it
/// fills is returned instead (longer exposures cannot raise it). Returns `f64::INFINITY` when
/// no signal accrues (dark field without dark current) and 0 when the offset alone already
/// reaches the target.
pub fn auto_exposure_s(
    sensor: &SensorModel,
    rate: &ElectronRate,
    target_fraction_of_swing: f64,
) -> f64 {
    check_rate(sensor, rate);
    let r_max = rate
        .electrons_per_s
        .iter()
        .fold(0f64, |m, &r| m.max(r as f64));
    let g = sensor.conversion_gain_v_per_e;
    // Electrons per second in the brightest pixel, photo + dark (steps 2–3).
    let e_per_s = r_max + sensor.dark_voltage_v_per_s / g;
    let need_v = target_fraction_of_swing * sensor.voltage_swing_v - sensor.analog_offset_v;
    if need_v <= 0.0 {
        return 0.0;
    }
    if e_per_s <= 0.0 {
        return f64::INFINITY;
    }
    // Step 5–6: u = gain · n · g + offset.
    let t = need_v / (sensor.analog_gain * g * e_per_s);
    let t_well = sensor.well_capacity_e / e_per_s;
    t.min(t_well)
}

/// The magnitude of `nonlinearity` (effects.md) for `sensor` at `analog_gain`:
/// `1 − S(n80) / L(n80)`, where `S(n)` is the expected signal (DN above the zero-signal DN) of
/// a pixel holding `n` photo-electrons (dark current excluded), `L(n) = S'(0)·n` the line
/// through the low-signal response, and `n80` the charge at which the line reaches 80 % of the
/// full scale `2^bits − 1 − DN(0)` (the DN range above the black level). Well capacity, swing
/// and ADC clipping are part of S, so a camera without the block can still have a
/// non-zero magnitude when it clips before 80 % of full scale.
pub fn nonlinearity_magnitude(sensor: &SensorModel, analog_gain: f64) -> f64 {
    let shot = crate::Shot {
        exposure_s: 1.0,
        analog_gain,
    };
    let mut s = sensor.clone();
    s.dark_voltage_v_per_s = 0.0;
    let chain = Chain::new(&s, &shot);
    // Expected DN of n photo-electrons (exposure 1 s, rate n).
    let dn = |n: f64| chain.dn(chain.expected_u(n));
    let dn0 = dn(0.0);
    let full_scale = sensor.max_dn() - dn0;
    if full_scale <= 0.0 {
        return 0.0;
    }
    // Low-signal slope S'(0) from a charge far below any compression (1e-6 of the
    // uncompressed full scale), DN per electron.
    let linear_dn_per_e = sensor.dn_per_e(analog_gain);
    let n_small = 1e-6 * full_scale / linear_dn_per_e;
    let slope = (dn(n_small) - dn0) / n_small;
    if slope <= 0.0 {
        return 0.0;
    }
    let n80 = 0.8 * full_scale / slope;
    1.0 - (dn(n80) - dn0) / (0.8 * full_scale)
}

/// Mean photo-electrons of a pixel from its rate × time (× PRNU gain): never negative. A NaN
/// (light that overflowed upstream, ∞·0 or ∞ − ∞ in a blur) stays NaN, and the kernel's draw
/// ([`PoissonSampler::sample_saturating`]) or, with shot noise off, the full-well clip
/// (`NaN.min(well) = well`) turns it into a full well — never black. Written as a compare
/// and select, not `f64::max` (which maps NaN to 0), so that it is one vector instruction.
#[inline(always)]
fn mean_electrons(x: f64) -> f64 {
    if x < 0.0 {
        0.0
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::mono;
    use crate::NoiseSwitches;
    use approx::assert_relative_eq;

    fn flat(s: &SensorModel, r: f32) -> ElectronRate {
        ElectronRate {
            rows: s.rows,
            cols: s.cols,
            electrons_per_s: vec![r; s.rows * s.cols],
        }
    }

    #[test]
    fn expected_dn_closed_form() {
        let s = mono(2, 3);
        let rate = flat(&s, 1e5);
        let shot = Shot {
            exposure_s: 0.01,
            analog_gain: 2.0,
        };
        // e = 1000, d = 0.01·1e-3/1e-4 = 0.1; u = 2·1000.1·1e-4 = 0.20002 V
        let want = 0.20002 * 4095.0 + 64.0;
        for v in expected_dn(&s, &rate, &shot) {
            assert_relative_eq!(v as f64, want, max_relative = 1e-6);
        }
        // Well clip: 1e9 e/s · 0.01 s ≫ well → n = 10000 → u = min(2·1, 1) = swing.
        let e = expected_dn(&s, &flat(&s, 1e9), &shot);
        assert_eq!(e[0], 4095.0);
        let shot1 = Shot {
            exposure_s: 0.01,
            analog_gain: 0.5,
        };
        let e = expected_dn(&s, &flat(&s, 1e9), &shot1);
        assert_relative_eq!(e[0] as f64, 0.5 * 1.0 * 4095.0 + 64.0, max_relative = 1e-6);
    }

    #[test]
    fn noiseless_frame_is_rounded_expected_image() {
        let mut s = mono(4, 5);
        s.noise = NoiseSwitches::none();
        let rate = ElectronRate {
            rows: 4,
            cols: 5,
            electrons_per_s: (0..20).map(|i| 1e4 * i as f32 + 3.3).collect(),
        };
        let shot = Shot::new(&s, 0.037);
        let fp = fixed_pattern(&s, 1);
        let f = expose(&s, &rate, &shot, &fp, 1, &[0, 0]);
        let e = expected_dn(&s, &rate, &shot);
        for (a, b) in f.dn.iter().zip(&e) {
            assert_eq!(*a as f32, b.round());
        }
    }

    #[test]
    fn overflowed_light_saturates_and_negative_light_is_dark() {
        // A NaN rate (∞·0 upstream) or +∞ reads like a huge finite rate (full well → clipped
        // DN) under every shot/dark/PRNU switch and with hot pixels; a negative rate like 0.
        let rates = [f32::NAN, f32::INFINITY, 1e30, -5.0, 0.0];
        for (shot_on, dark_on, prnu_on) in (0..8).map(|i| (i & 1 == 1, i & 2 == 2, i & 4 == 4)) {
            let mut s = mono(1, rates.len());
            s.noise = NoiseSwitches::none();
            s.noise.shot = shot_on;
            s.noise.dark = dark_on;
            s.noise.prnu = prnu_on;
            s.prnu_sigma_percent = 1.0;
            let rate = ElectronRate {
                rows: 1,
                cols: rates.len(),
                electrons_per_s: rates.to_vec(),
            };
            let shot = Shot::new(&s, 0.01);
            let fp = fixed_pattern(&s, 3);
            let f = expose(&s, &rate, &shot, &fp, 3, &[0, 0]);
            let tag = format!("shot {shot_on} dark {dark_on} prnu {prnu_on}");
            assert_eq!(f.dn[0], f.dn[2], "NaN vs huge rate, {tag}");
            assert_eq!(f.dn[1], f.dn[2], "+inf vs huge rate, {tag}");
            assert!(f.dn[2] > f.dn[4], "huge rate above dark, {tag}");
            if !dark_on {
                assert_eq!(f.dn[3], f.dn[4], "negative rate vs 0, {tag}");
            }
        }
    }

    #[test]
    fn auto_exposure_hits_target() {
        let s = mono(3, 3);
        let mut rate = flat(&s, 2e4);
        rate.electrons_per_s[4] = 5e4;
        let t = auto_exposure_s(&s, &rate, 0.5);
        let e = expected_volts(&s, &rate, &Shot::new(&s, t));
        assert_relative_eq!(e[4] as f64, 0.5, max_relative = 1e-6);
        // The well (10000 e ≈ 1 V at g = 1e-4) limits a 0.99 target: 0.99 V < 1 V still OK.
        let mut s2 = s.clone();
        s2.well_capacity_e = 3000.0;
        let t2 = auto_exposure_s(&s2, &rate, 0.9);
        assert_relative_eq!(t2, 3000.0 / (5e4 + 10.0), max_relative = 1e-12);
    }

    #[test]
    fn fixed_pattern_statistics_and_reproducibility() {
        let mut s = mono(200, 300);
        s.column_fpn = Some(crate::ColumnFpn {
            offset_sigma_v: 2e-3,
        });
        let a = fixed_pattern(&s, 5);
        let b = fixed_pattern(&s, 5);
        assert_eq!(a, b);
        assert_ne!(a, fixed_pattern(&s, 6));
        let n = a.prnu_gain.len() as f64;
        let m = a.prnu_gain.iter().map(|&x| x as f64).sum::<f64>() / n;
        let sd = (a
            .prnu_gain
            .iter()
            .map(|&x| (x as f64 - m).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        assert!((m - 1.0).abs() < 4.0 * 0.01 / n.sqrt());
        assert!((sd / 0.01 - 1.0).abs() < 4.0 * (0.5 / n).sqrt());
        let sd_d = (a.dsnu_v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>() / n).sqrt();
        assert!((sd_d / 1e-3 - 1.0).abs() < 4.0 * (0.5 / n).sqrt());
        assert_eq!(a.column_offset_v.len(), 300);
        assert!(a.column_offset_v.iter().any(|&x| x != 0.0));
    }
}
