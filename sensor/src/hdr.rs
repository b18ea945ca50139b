//! High-dynamic-range pixels: several charge packets per pixel, each read out at one or more
//! conversion gains. One description covers the three architectures in use:
//!
//! * **split pixel** (Sony IMX490 style; Willassen et al., "A 1280×1080 4.2 µm split-diode
//!   pixel HDR sensor in 110 nm BSI CMOS process", IISW 2015; Iida et al., "A 0.68e-rms random
//!   noise 121 dB dynamic range sub-pixel architecture CMOS image sensor with LED flicker
//!   mitigation", IEDM 2018): a large (LPD) and a small (SPD) photodiode under one colour
//!   filter, each read at high and low conversion gain: four readouts LPD-HCG, LPD-LCG,
//!   SPD-HCG, SPD-LCG;
//! * **dual conversion gain** (DCG; Solhusvik et al., "A comparison of high dynamic range CIS
//!   technologies for automotive applications", IISW 2019): one photodiode, its charge read
//!   at two gains;
//! * **multi-exposure bracketing** (Debevec & Malik, SIGGRAPH 1997): the same photodiode
//!   exposed several times with different exposure times (independent charge packets of a
//!   static scene).
//!
//! A charge packet `p` collects `s_p · H + d_p` mean electrons, where `H` is the exposure in
//! photo-electrons of the camera's own pixel (the sensor's [`crate::electron_rate`] × exposure
//! time) and `s_p` = sensitivity × exposure ratio (the photodiode's share of the pixel's
//! light, times its exposure time relative to the shot's); `d_p` = dark electrons
//! `s_p · t · dark_voltage / g` (dark current scales with the photodiode area and time like
//! the signal). The packet holds `N_p = min(Poisson(s_p H + d_p), well_p)` electrons; readout
//! `i` of packet `p` adds its own read noise and goes through the camera's analog gain and
//! ADC exactly as the baseline chain (steps 5–7 of `spec/capture-format.md`):
//! `v = N_p g_i + r_i`, `r_i ~ N(0, σ_i²)`, `u = min(a·v + offset, swing)`,
//! `DN = clamp(round(u/swing·(2^bits − 1) + black), 0, 2^bits − 1)`. Readouts of one packet
//! share its shot noise; their read noises are independent. Fixed patterns (PRNU, DSNU,
//! column offsets, effect blocks) are not applied to the readouts.
//!
//! The noise model of one readout ([`HdrReadoutModel`]) — its estimate of `H`,
//! `x_i = (DN − zero)/(k_i s_i) − d_p/s_i` with `k_i` DN per electron, has variance
//! `(s_i H + d_p + σ_e,i²)/s_i²` with `σ_e,i² = (σ_i/g_i)² + 1/(12 k_i²)` (read noise and
//! uniform quantisation in electrons) — is the shot-plus-read model of EMVA 1288 (release
//! 4.0, eq. 9) per readout; the ISP merge and the SNR metrics use it.
use crate::normal::Ziggurat;
use crate::pixel_rng::PixelRng;
use crate::poisson::PoissonSampler;
use crate::{ElectronRate, SensorError, SensorModel, Shot};
use camsim_core::rng::stream;
use camsim_core::RawFrame;
use rayon::prelude::*;

/// Stream tag of the HDR readout draws: `stream(seed, &[HDR_TAG, stream…, row])`.
pub const HDR_TAG: u64 = 0x4844_525F_5245_4144; // "HDR_READ"

/// One charge packet of an HDR pixel: a photodiode (split pixel) or one exposure of it
/// (bracketing).
#[derive(Debug, Clone, PartialEq)]
pub struct ChargePacket {
    /// Name (`lpd`, `spd`, `long`, …).
    pub name: String,
    /// Electrons collected per photo-electron of the camera's pixel (the photodiode's share of
    /// the light: area × microlens efficiency), > 0.
    pub sensitivity: f64,
    /// Exposure time of this packet relative to the shot's (bracketing), > 0; 1 for a split
    /// pixel or DCG.
    pub exposure_ratio: f64,
    /// Full-well capacity of the photodiode (electrons).
    pub well_capacity_e: f64,
}

impl ChargePacket {
    /// `s_p` = sensitivity × exposure ratio: mean electrons of the packet per photo-electron of
    /// the camera's pixel.
    pub fn gain_over_pixel(&self) -> f64 {
        self.sensitivity * self.exposure_ratio
    }
}

/// One readout of a charge packet at one conversion gain.
#[derive(Debug, Clone, PartialEq)]
pub struct HdrReadout {
    /// Name (`lpd_hcg`, …).
    pub name: String,
    /// Index of the packet it reads in [`HdrModel::packets`].
    pub packet: usize,
    /// Conversion gain g_i (V per electron).
    pub conversion_gain_v_per_e: f64,
    /// Read noise σ_i (V).
    pub read_noise_v: f64,
}

/// An HDR pixel: charge packets and their readouts (camera file `sensor.hdr`).
#[derive(Debug, Clone, PartialEq)]
pub struct HdrModel {
    /// Charge packets.
    pub packets: Vec<ChargePacket>,
    /// Readouts (each of one packet).
    pub readouts: Vec<HdrReadout>,
}

pub use camsim_core::hdr::{HdrFrame, HdrReadoutModel, USABLE_FRACTION};

fn bad(field: String, value: impl std::fmt::Display, reason: &str) -> SensorError {
    SensorError::InvalidField {
        field,
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

impl HdrModel {
    /// The camera's own pixel as a one-packet, one-readout model (sensitivity 1, its well,
    /// conversion gain and read noise): merged, it gives the baseline chain's signal.
    pub fn standard(sensor: &SensorModel) -> HdrModel {
        HdrModel {
            packets: vec![ChargePacket {
                name: "pd".into(),
                sensitivity: 1.0,
                exposure_ratio: 1.0,
                well_capacity_e: sensor.well_capacity_e,
            }],
            readouts: vec![HdrReadout {
                name: "pd".into(),
                packet: 0,
                conversion_gain_v_per_e: sensor.conversion_gain_v_per_e,
                read_noise_v: sensor.read_noise_v,
            }],
        }
    }

    /// A split pixel for [`SensorModel::mono_test`] (the tests' fixture): LPD of sensitivity
    /// 0.9 and a 40 000 e⁻ well, SPD of sensitivity 0.009 (ratio 100) and a 20 000 e⁻ well;
    /// high conversion gain 200 µV/e⁻ with 0.2 mV read noise (1 e⁻), low conversion gain
    /// 25 µV/e⁻ with 0.1 mV (4 e⁻); readouts in the order LPD-HCG, LPD-LCG, SPD-HCG, SPD-LCG.
    pub fn split_pixel_test() -> HdrModel {
        let packet = |name: &str, sensitivity: f64, well: f64| ChargePacket {
            name: name.into(),
            sensitivity,
            exposure_ratio: 1.0,
            well_capacity_e: well,
        };
        let readout = |name: &str, packet: usize, g: f64, read: f64| HdrReadout {
            name: name.into(),
            packet,
            conversion_gain_v_per_e: g,
            read_noise_v: read,
        };
        HdrModel {
            packets: vec![packet("lpd", 0.9, 40000.0), packet("spd", 0.009, 20000.0)],
            readouts: vec![
                readout("lpd_hcg", 0, 2e-4, 2e-4),
                readout("lpd_lcg", 0, 2.5e-5, 1e-4),
                readout("spd_hcg", 1, 2e-4, 2e-4),
                readout("spd_lcg", 1, 2.5e-5, 1e-4),
            ],
        }
    }

    /// Checks every field; the error names the first bad one (`hdr.photodiodes[1].sensitivity`).
    pub fn validate(&self) -> Result<(), SensorError> {
        let pos = |f: String, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(f, v, "must be a positive finite number"))
            }
        };
        if self.packets.is_empty() {
            return Err(bad(
                "hdr.photodiodes".into(),
                "[]",
                "at least one is required",
            ));
        }
        if self.readouts.is_empty() {
            return Err(bad("hdr.readouts".into(), "[]", "at least one is required"));
        }
        for (i, p) in self.packets.iter().enumerate() {
            pos(format!("hdr.photodiodes[{i}].sensitivity"), p.sensitivity)?;
            pos(
                format!("hdr.photodiodes[{i}].exposure_ratio"),
                p.exposure_ratio,
            )?;
            pos(
                format!("hdr.photodiodes[{i}].well_capacity_e"),
                p.well_capacity_e,
            )?;
        }
        for (i, r) in self.readouts.iter().enumerate() {
            if r.packet >= self.packets.len() {
                return Err(bad(
                    format!("hdr.readouts[{i}].photodiode"),
                    r.packet,
                    &format!("must index one of the {} photodiodes", self.packets.len()),
                ));
            }
            pos(
                format!("hdr.readouts[{i}].conversion_gain_v_per_e"),
                r.conversion_gain_v_per_e,
            )?;
            let s = r.read_noise_v;
            if !(s.is_finite() && s >= 0.0) {
                return Err(bad(
                    format!("hdr.readouts[{i}].read_noise_v"),
                    s,
                    "must be a finite number ≥ 0",
                ));
            }
        }
        Ok(())
    }

    /// The noise model of every readout for `shot` on `sensor` (its analog gain, offset,
    /// swing, ADC, black level and dark voltage).
    pub fn readout_models(&self, sensor: &SensorModel, shot: &Shot) -> Vec<HdrReadoutModel> {
        let dn_per_v = sensor.dn_per_output_v();
        let a = shot.analog_gain;
        let off = sensor.analog_offset_v;
        self.readouts
            .iter()
            .map(|r| {
                let p = &self.packets[r.packet];
                let s = p.gain_over_pixel();
                let g = r.conversion_gain_v_per_e;
                let k = a * g * dn_per_v;
                let zero_dn = sensor.black_level_dn + off * dn_per_v;
                // Clipping: the well, the output swing (u ≤ swing), the ADC full scale.
                let swing_e = (sensor.voltage_swing_v - off) / (a * g);
                let adc_e = (sensor.max_dn() - zero_dn) / k;
                HdrReadoutModel {
                    name: r.name.clone(),
                    packet: r.packet,
                    gain_over_pixel: s,
                    // Dark electrons scale with the photodiode's share and time like the signal.
                    dark_e: s * shot.exposure_s * sensor.dark_voltage_v_per_s
                        / sensor.conversion_gain_v_per_e,
                    dn_per_e: k,
                    zero_dn,
                    read_variance_e2: (r.read_noise_v / g).powi(2) + 1.0 / (12.0 * k * k),
                    saturation_e: p.well_capacity_e.min(swing_e).min(adc_e),
                }
            })
            .collect()
    }
}

/// Simulates the readouts of one HDR shot: per pixel and packet
/// `N_p = min(Poisson(s_p · rate · t + d_p), well_p)`, then per readout of the packet
/// `DN = clamp(round(min(a (N_p g_i + r_i) + offset, swing) · (2^bits−1)/swing + black))`.
/// Row `r` draws from `stream(seed, &[HDR_TAG, stream…, r])`: the same frames whatever the
/// thread count. The sensor's noise switches apply (shot and dark Poisson, read).
pub fn expose_hdr(
    sensor: &SensorModel,
    hdr: &HdrModel,
    rate: &ElectronRate,
    shot: &Shot,
    seed: u64,
    stream_ids: &[u64],
) -> HdrFrame {
    assert!(
        rate.rows == sensor.rows && rate.cols == sensor.cols,
        "electron rate is {}×{} but the sensor is {}×{}",
        rate.rows,
        rate.cols,
        sensor.rows,
        sensor.cols
    );
    let (rows, cols) = (sensor.rows, sensor.cols);
    let models = hdr.readout_models(sensor, shot);
    let sw = sensor.noise;
    let n_read = hdr.readouts.len();
    let dn_per_v = sensor.dn_per_output_v();
    let (a, off, swing, black, max_dn) = (
        shot.analog_gain,
        sensor.analog_offset_v,
        sensor.voltage_swing_v,
        sensor.black_level_dn,
        sensor.max_dn(),
    );
    // Per row: readout-major DN values.
    let rows_dn: Vec<Vec<u16>> = (0..rows)
        .into_par_iter()
        .map(|r| {
            let mut ids = Vec::with_capacity(stream_ids.len() + 2);
            ids.push(HDR_TAG);
            ids.extend_from_slice(stream_ids);
            ids.push(r as u64);
            let mut rng = PixelRng::from_stream(stream(seed, &ids));
            let mut poisson = PoissonSampler::default();
            let zig = Ziggurat::new();
            let mut out = vec![0u16; n_read * cols];
            let mut packet_e = vec![0.0f64; hdr.packets.len()];
            for c in 0..cols {
                let e = rate.electrons_per_s[r * cols + c] as f64 * shot.exposure_s;
                for (pi, p) in hdr.packets.iter().enumerate() {
                    let s = p.gain_over_pixel();
                    let photo = s * e;
                    let dark = models
                        .iter()
                        .find(|m| m.packet == pi)
                        .map_or(0.0, |m| m.dark_e);
                    let n = match (sw.shot, sw.dark) {
                        (true, true) => poisson.sample(&mut rng, photo + dark),
                        (true, false) => poisson.sample(&mut rng, photo) + dark,
                        (false, true) => photo + poisson.sample(&mut rng, dark),
                        (false, false) => photo + dark,
                    };
                    packet_e[pi] = n.min(p.well_capacity_e);
                }
                for (ri, ro) in hdr.readouts.iter().enumerate() {
                    let g = ro.conversion_gain_v_per_e;
                    let read = if sw.read {
                        ro.read_noise_v * zig.sample(&mut rng)
                    } else {
                        0.0
                    };
                    let v = packet_e[ro.packet] * g + read;
                    let u = (a * v + off).min(swing);
                    let dn = (u * dn_per_v + black).round().clamp(0.0, max_dn);
                    out[ri * cols + c] = dn as u16;
                }
            }
            out
        })
        .collect();
    let readouts = (0..n_read)
        .map(|ri| {
            let mut dn = Vec::with_capacity(rows * cols);
            for row in &rows_dn {
                dn.extend_from_slice(&row[ri * cols..(ri + 1) * cols]);
            }
            RawFrame {
                rows,
                cols,
                adc_bits: sensor.adc_bits,
                dn,
                layout: Some(sensor.raw_layout()),
            }
        })
        .collect();
    HdrFrame {
        names: hdr.readouts.iter().map(|r| r.name.clone()).collect(),
        readouts,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_model_matches_the_baseline_constants() {
        let s = SensorModel::mono_test(2, 2);
        let shot = Shot::new(&s, 0.01);
        let m = &HdrModel::standard(&s).readout_models(&s, &shot)[0];
        assert!((m.dn_per_e - s.dn_per_e(1.0)).abs() < 1e-12);
        // Dark electrons: t · dark_voltage / g = 0.01 · 1e-3 / 1e-4 = 0.1.
        assert!((m.dark_e - 0.1).abs() < 1e-12);
        // The well (1e4) clips before the swing (1 V / 1e-4 = 1e4) and the ADC
        // ((4095 − 64)/0.4095 ≈ 9844 e): the ADC limits.
        assert!((m.saturation_e - (4095.0 - 64.0) / 0.4095).abs() < 1e-9);
    }

    #[test]
    fn validate_names_the_field() {
        let s = SensorModel::mono_test(2, 2);
        let mut h = HdrModel::standard(&s);
        h.packets[0].sensitivity = -1.0;
        let e = h.validate().unwrap_err().to_string();
        assert!(
            e.contains("hdr.photodiodes[0].sensitivity") && e.contains("-1"),
            "{e}"
        );
        let mut h = HdrModel::standard(&s);
        h.readouts[0].packet = 3;
        let e = h.validate().unwrap_err().to_string();
        assert!(e.contains("hdr.readouts[0].photodiode"), "{e}");
    }
}
