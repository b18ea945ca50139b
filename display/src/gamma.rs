//! The display gamma: digital value ↔ linear primary intensity through a lookup table.
//!
//! The table has `levels` entries per primary (ISETCam `gamma`, levels × primaries), giving the
//! relative linear intensity (0–1 of the full-drive SPD) for DAC level `k = 0 … levels − 1`.
//!
//! **Bit depth.** A digital value `d` of bit depth `b` sits at the table position
//! `t = d · (levels − 1) / (2^b − 1)` (proportional mapping, so 0 → first entry and the top
//! code → last entry), and the table is linearly interpolated there. When `2^b = levels` the
//! position is `d` itself and the table entry is used as it is.
//!
//! **Inverse.** [`GammaTable::digital_from_linear`] returns the code whose intensity is nearest
//! to the requested one (the table is non-decreasing, so this is a monotone inverse). Values
//! below the first entry give code 0 and values above the last entry give the top of the
//! table. **Flat segments**: where several codes give the same intensity (CRT-HP has runs of
//! equal entries; the fourth OLED-Samsung primary is constant), the *lowest* of those codes is
//! returned, and ties between two neighbouring intensities also go to the lower code. Hence
//!
//! * `digital → linear → digital` is exact for every code whose intensity is unique, i.e.
//!   wherever the table is strictly increasing around it;
//! * `linear → digital → linear` is exact (at the native bit depth) for every table value,
//!   flat segments included.
use crate::error::DisplayError;

/// Per-primary lookup tables from DAC level to relative linear intensity.
#[derive(Debug, Clone, PartialEq)]
pub struct GammaTable {
    /// `linear[primary][level]`: relative linear intensity, non-decreasing in `level`.
    linear: Vec<Vec<f64>>,
}

impl GammaTable {
    /// A validated table from `linear[primary][level]`: at least two levels, the same number of
    /// levels for every primary, finite and non-decreasing values.
    pub fn new(linear: Vec<Vec<f64>>) -> Result<Self, DisplayError> {
        let bad = |field: String, message: String| DisplayError::InvalidData { field, message };
        if linear.is_empty() {
            return Err(bad("gamma".into(), "no primaries".into()));
        }
        let levels = linear[0].len();
        if levels < 2 {
            return Err(bad(
                "gamma".into(),
                format!("{levels} levels; need at least 2"),
            ));
        }
        for (p, t) in linear.iter().enumerate() {
            if t.len() != levels {
                return Err(bad(
                    "gamma".into(),
                    format!("primary {p} has {} levels, primary 0 has {levels}", t.len()),
                ));
            }
            if let Some(k) = t.iter().position(|v| !v.is_finite()) {
                return Err(bad(
                    format!("gamma[{k}][{p}]"),
                    format!("{} is not finite", t[k]),
                ));
            }
            if let Some(k) = t.windows(2).position(|w| w[1] < w[0]) {
                return Err(bad(
                    format!("gamma[{}][{p}]", k + 1),
                    format!(
                        "the table must be non-decreasing, but level {} gives {} after {} at level {k}",
                        k + 1,
                        t[k + 1],
                        t[k]
                    ),
                ));
            }
        }
        Ok(GammaTable { linear })
    }

    /// Number of table entries per primary.
    pub fn levels(&self) -> usize {
        self.linear[0].len()
    }

    /// Number of primaries.
    pub fn n_primaries(&self) -> usize {
        self.linear.len()
    }

    /// The bit depth whose codes index the table directly (`log2(levels)`), when `levels` is a
    /// power of two no larger than 2^16.
    pub fn native_bits(&self) -> Option<u32> {
        let l = self.levels();
        (l.is_power_of_two() && l <= 1 << 16).then(|| l.trailing_zeros())
    }

    /// The table of one primary, `levels` entries.
    pub fn table(&self, primary: usize) -> Result<&[f64], DisplayError> {
        self.linear
            .get(primary)
            .map(|t| t.as_slice())
            .ok_or(DisplayError::PrimaryOutOfRange {
                primary,
                n_primaries: self.n_primaries(),
            })
    }

    /// The first entry of every primary (the intensity at digital 0, the display's black level).
    pub fn black_level(&self) -> Vec<f64> {
        self.linear.iter().map(|t| t[0]).collect()
    }

    /// The last entry of every primary (intensity at the top code).
    pub fn top_level(&self) -> Vec<f64> {
        self.linear.iter().map(|t| t[t.len() - 1]).collect()
    }

    fn check_bits(bits: u32) -> Result<u32, DisplayError> {
        if (1..=16).contains(&bits) {
            Ok((1u32 << bits) - 1)
        } else {
            Err(DisplayError::BadBitDepth { bits })
        }
    }

    /// Table position of code `d` at a depth whose top code is `max`.
    fn position(&self, d: u32, max: u32) -> f64 {
        let top = (self.levels() - 1) as f64;
        if max as usize == self.levels() - 1 {
            d as f64
        } else {
            d as f64 * top / max as f64
        }
    }

    /// Table value at a (fractional) position, by linear interpolation.
    fn at_position(t: &[f64], pos: f64) -> f64 {
        let i = pos.floor() as usize;
        if i + 1 >= t.len() {
            return t[t.len() - 1];
        }
        let f = pos - i as f64;
        if f == 0.0 {
            t[i]
        } else {
            t[i] + f * (t[i + 1] - t[i])
        }
    }

    /// Relative linear intensity of `primary` driven at `digital` (bit depth `bits`).
    pub fn linear_from_digital(
        &self,
        primary: usize,
        digital: u32,
        bits: u32,
    ) -> Result<f64, DisplayError> {
        let t = self.table(primary)?;
        let max = Self::check_bits(bits)?;
        if digital > max {
            return Err(DisplayError::DigitalOutOfRange {
                value: digital,
                bits,
                max,
            });
        }
        Ok(Self::at_position(t, self.position(digital, max)))
    }

    /// The whole forward table of `primary` at bit depth `bits` (2^bits entries).
    pub fn lut_for_bits(&self, primary: usize, bits: u32) -> Result<Vec<f64>, DisplayError> {
        let t = self.table(primary)?;
        let max = Self::check_bits(bits)?;
        Ok((0..=max)
            .map(|d| Self::at_position(t, self.position(d, max)))
            .collect())
    }

    /// The code of bit depth `bits` whose intensity is nearest to `linear` (see the module
    /// documentation for clamping and flat segments).
    pub fn digital_from_linear(
        &self,
        primary: usize,
        linear: f64,
        bits: u32,
    ) -> Result<u16, DisplayError> {
        let t = self.table(primary)?;
        let max = Self::check_bits(bits)?;
        if !linear.is_finite() {
            return Err(DisplayError::NonFiniteLinear { value: linear });
        }
        let n = t.len();
        let v = linear.clamp(t[0], t[n - 1]);
        // first entry ≥ v (exists after clamping): the lowest level of a flat run equal to v
        let i = t.partition_point(|x| *x < v);
        let pos = if t[i] == v || i == 0 {
            i as f64
        } else {
            let (a, b) = (t[i - 1], t[i]);
            (i - 1) as f64 + (v - a) / (b - a)
        };
        let top = (n - 1) as f64;
        let q = if max as usize == n - 1 {
            pos
        } else {
            pos * max as f64 / top
        };
        let lo = (q.floor().max(0.0) as u32).min(max);
        let hi = (q.ceil().max(0.0) as u32).min(max);
        if lo == hi {
            return Ok(lo as u16);
        }
        let f = |d: u32| Self::at_position(t, self.position(d, max));
        let (dl, dh) = ((f(lo) - linear).abs(), (f(hi) - linear).abs());
        Ok(if dh < dl { hi } else { lo } as u16)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_levels_for_other_bit_depths() {
        let g = GammaTable::new(vec![vec![0.0, 0.25, 1.0]]).unwrap();
        // 3 levels, 1-bit: code 1 → last entry
        assert_eq!(g.linear_from_digital(0, 1, 1).unwrap(), 1.0);
        // 2-bit: code 1 → position 2/3 → 0.25·2/3
        let v = g.linear_from_digital(0, 1, 2).unwrap();
        assert!((v - 0.25 * 2.0 / 3.0).abs() < 1e-15);
        assert_eq!(g.digital_from_linear(0, v, 2).unwrap(), 1);
        assert!(g.linear_from_digital(0, 4, 2).is_err());
        assert!(g.linear_from_digital(1, 0, 2).is_err());
        assert!(g.linear_from_digital(0, 0, 0).is_err());
        assert!(g.digital_from_linear(0, f64::NAN, 2).is_err());
    }

    #[test]
    fn flat_runs_map_to_their_lowest_level_and_clamp() {
        let g = GammaTable::new(vec![vec![0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0]]).unwrap();
        assert_eq!(g.native_bits(), Some(3));
        assert_eq!(g.digital_from_linear(0, 0.0, 3).unwrap(), 0);
        assert_eq!(g.digital_from_linear(0, 0.5, 3).unwrap(), 3);
        assert_eq!(g.digital_from_linear(0, 1.0, 3).unwrap(), 5);
        assert_eq!(g.digital_from_linear(0, 7.0, 3).unwrap(), 5);
        assert_eq!(g.digital_from_linear(0, -1.0, 3).unwrap(), 0);
        // 0.3 is nearer 0.5 (level 3) than 0.0 (level 2); 0.25 is a tie → lower
        assert_eq!(g.digital_from_linear(0, 0.3, 3).unwrap(), 3);
        assert_eq!(g.digital_from_linear(0, 0.25, 3).unwrap(), 2);
    }

    #[test]
    fn rejects_decreasing_tables_naming_the_level() {
        let e = GammaTable::new(vec![vec![0.0, 0.5, 0.4]])
            .unwrap_err()
            .to_string();
        assert!(e.contains("gamma[2][0]") && e.contains("0.4"), "{e}");
    }
}
