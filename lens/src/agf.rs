//! Zemax `.agf` glass catalogues.
//!
//! An AGF file is line-oriented; the records used here are `NM name formula MIL nd vd …` (one
//! glass), `CD c1 c2 …` (its dispersion coefficients) and `LD λmin λmax` (its wavelength range,
//! µm). Wavelengths are in µm and indices relative to air, as in the refractiveindex.info
//! formulas, so each Zemax formula is written as the equivalent refractiveindex.info formula
//! of [`crate::glass::Dispersion`] (Zemax OpticStudio manual, "Glass catalogs: dispersion
//! formulas"):
//!
//! | Zemax | law | refractiveindex.info form |
//! |---|---|---|
//! | 1 Schott | n² = a0 + a1λ² + a2λ⁻² + a3λ⁻⁴ + a4λ⁻⁶ + a5λ⁻⁸ | 3 |
//! | 2 Sellmeier 1 | n² − 1 = Σ₃ Kᵢλ²/(λ² − Lᵢ) | 2 |
//! | 4 Sellmeier 2 | n² − 1 = A + B1λ²/(λ² − λ1²) + B2/(λ² − λ2²) | 4 |
//! | 5 Conrady | n = n0 + A/λ + B/λ^3.5 | 5 |
//! | 6 Sellmeier 3 | n² − 1 = Σ₄ Kᵢλ²/(λ² − Lᵢ) | 2 |
//! | 7 Handbook of Optics 1 | n² = A + B/(λ² − C) − Dλ² | 4 |
//! | 8 Handbook of Optics 2 | n² = A + Bλ²/(λ² − C) − Dλ² | 4 |
//! | 9 Sellmeier 4 | n² = A + Bλ²/(λ² − C) + Dλ²/(λ² − E) | 2 |
//! | 10 Extended | n² = a0 + a1λ² + a2λ⁻² + … + a7λ⁻¹² | 3 |
//! | 11 Sellmeier 5 | n² − 1 = Σ₅ Kᵢλ²/(λ² − Lᵢ) | 2 |
//! | 12 Extended 2 | n² = a0 + a1λ² + a2λ⁻² + a3λ⁻⁴ + a4λ⁻⁶ + a5λ⁻⁸ + a6λ⁴ + a7λ⁶ | 3 |
//! | 13 Extended 3 | n² = a0 + a1λ² + a2λ⁴ + a3λ⁻² + a4λ⁻⁴ + … + a8λ⁻¹² | 3 |
//!
//! Herzberger (3) has no such form; a glass using it is an error naming it.
use crate::error::LensError;
use crate::glass::{Dispersion, Glass};
use crate::readers::decode_text;

/// The refractiveindex.info dispersion equivalent to Zemax formula `formula` with AGF `CD`
/// coefficients `c` (missing ones are 0). `None` for Herzberger and unknown numbers.
pub fn zemax_dispersion(formula: u32, c: &[f64]) -> Option<Dispersion> {
    let a = |i: usize| c.get(i).copied().unwrap_or(0.0);
    let f = |number: u8, coefficients: Vec<f64>| {
        Some(Dispersion::Formula {
            number,
            coefficients,
        })
    };
    // n² = Σ aᵢ λ^eᵢ (refractiveindex.info formula 3: C1 + Σ C(2i) λ^C(2i+1)).
    let power = |exps: &[f64]| -> Option<Dispersion> {
        let mut v = vec![0.0];
        for (i, &e) in exps.iter().enumerate() {
            if e == 0.0 {
                v[0] += a(i);
            } else {
                v.push(a(i));
                v.push(e);
            }
        }
        f(3, v)
    };
    let sellmeier = |terms: usize| -> Option<Dispersion> {
        let mut v = vec![0.0];
        for i in 0..terms {
            v.push(a(2 * i));
            v.push(a(2 * i + 1));
        }
        f(2, v)
    };
    match formula {
        1 => power(&[0.0, 2.0, -2.0, -4.0, -6.0, -8.0]),
        2 => sellmeier(3),
        4 => f(
            4,
            vec![1.0 + a(0), a(1), 2.0, a(2), 2.0, a(3), 0.0, a(4), 2.0],
        ),
        5 => f(5, vec![a(0), a(1), -1.0, a(2), -3.5]),
        6 => sellmeier(4),
        7 => f(
            4,
            vec![a(0), a(1), 0.0, a(2), 1.0, 0.0, 0.0, 0.0, 1.0, -a(3), 2.0],
        ),
        8 => f(
            4,
            vec![a(0), a(1), 2.0, a(2), 1.0, 0.0, 0.0, 0.0, 1.0, -a(3), 2.0],
        ),
        9 => f(2, vec![a(0) - 1.0, a(1), a(2), a(3), a(4)]),
        10 => power(&[0.0, 2.0, -2.0, -4.0, -6.0, -8.0, -10.0, -12.0]),
        11 => sellmeier(5),
        12 => power(&[0.0, 2.0, -2.0, -4.0, -6.0, -8.0, 4.0, 6.0]),
        13 => power(&[0.0, 2.0, 4.0, -2.0, -4.0, -6.0, -8.0, -10.0, -12.0]),
        _ => None,
    }
}

/// Parse an `.agf` catalogue (bytes in any encoding [`decode_text`] handles) named `catalog`.
/// Every `NM` record becomes a [`Glass`] with the catalogue's n_d, V_d and `LD` range.
pub fn read_agf(bytes: &[u8], catalog: &str) -> Result<Vec<Glass>, LensError> {
    let text = decode_text(bytes);
    let err = |line: usize, msg: String| LensError::Reader {
        format: "Zemax .agf",
        line,
        msg,
    };
    struct Pending {
        line: usize,
        name: String,
        formula: u32,
        nd: Option<f64>,
        vd: Option<f64>,
        cd: Option<Vec<f64>>,
        ld: Option<(f64, f64)>,
    }
    let finish = |p: Pending| -> Result<Glass, LensError> {
        let cd = p.cd.ok_or_else(|| {
            err(
                p.line,
                format!("glass {}: no CD (coefficients) record", p.name),
            )
        })?;
        let dispersion = zemax_dispersion(p.formula, &cd).ok_or_else(|| {
            err(
                p.line,
                format!(
                    "glass {}: dispersion formula {} is not supported (1, 2, 4–13 are)",
                    p.name, p.formula
                ),
            )
        })?;
        Ok(Glass {
            name: p.name,
            catalog: catalog.to_string(),
            dispersion,
            range_um: p.ld,
            catalog_nd: p.nd,
            catalog_vd: p.vd,
        })
    };
    let mut out = Vec::new();
    let mut cur: Option<Pending> = None;
    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let mut w = raw.split_whitespace();
        let Some(key) = w.next() else { continue };
        let nums = |w: std::str::SplitWhitespace| -> Result<Vec<f64>, LensError> {
            w.map(|s| {
                s.parse::<f64>()
                    .map_err(|_| err(ln, format!("{key}: '{s}' is not a number")))
            })
            .collect()
        };
        match key {
            "NM" => {
                if let Some(p) = cur.take() {
                    out.push(finish(p)?);
                }
                let name = w
                    .next()
                    .ok_or_else(|| err(ln, "NM without a glass name".into()))?;
                let rest: Vec<&str> = w.collect();
                let formula = rest
                    .first()
                    .and_then(|s| s.parse::<f64>().ok())
                    .ok_or_else(|| err(ln, format!("glass {name}: NM without a formula number")))?
                    as u32;
                let num = |k: usize| rest.get(k).and_then(|s| s.parse::<f64>().ok());
                cur = Some(Pending {
                    line: ln,
                    name: name.to_string(),
                    formula,
                    nd: num(2),
                    vd: num(3),
                    cd: None,
                    ld: None,
                });
            }
            "CD" => {
                let v = nums(w)?;
                match cur.as_mut() {
                    Some(p) => p.cd = Some(v),
                    None => return Err(err(ln, "CD before any NM".into())),
                }
            }
            "LD" => {
                let v = nums(w)?;
                if let (Some(p), [a, b, ..]) = (cur.as_mut(), v.as_slice()) {
                    p.ld = Some((*a, *b));
                }
            }
            _ => {}
        }
    }
    if let Some(p) = cur.take() {
        out.push(finish(p)?);
    }
    if out.is_empty() {
        return Err(err(0, "no glass (NM record)".into()));
    }
    Ok(out)
}
