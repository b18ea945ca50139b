//! Every dispersion formula the bundled glass tables use (refractiveindex.info formulas 1, 2,
//! 3 and tabulated n) evaluated for every bundled glass against the closed forms written out
//! here from the refractiveindex.info "Dispersion formulas" document (λ in µm):
//! formula 1 n² = 1 + C1 + Σ C(2i)λ²/(λ² − C(2i+1)²); formula 2 n² = 1 + C1 +
//! Σ C(2i)λ²/(λ² − C(2i+1)); formula 3 n² = C1 + Σ C(2i)λ^C(2i+1); tabulated n: the straight
//! line through the two bracketing rows.
use camsim_lens::glass::{Dispersion, GlassCatalog};
use std::collections::BTreeMap;

fn closed_form(d: &Dispersion, l: f64) -> f64 {
    match d {
        Dispersion::Formula {
            number,
            coefficients: c,
        } => {
            let pairs = c[1..].chunks(2).filter(|p| p.len() == 2);
            match number {
                1 => (1.0
                    + c[0]
                    + pairs
                        .map(|p| p[0] * l * l / (l * l - p[1] * p[1]))
                        .sum::<f64>())
                .sqrt(),
                2 => {
                    (1.0 + c[0] + pairs.map(|p| p[0] * l * l / (l * l - p[1])).sum::<f64>()).sqrt()
                }
                3 => (c[0] + pairs.map(|p| p[0] * l.powf(p[1])).sum::<f64>()).sqrt(),
                k => panic!("formula {k} is not used by the bundled tables"),
            }
        }
        Dispersion::Tabulated { wavelength_um, n } => {
            let k = (0..wavelength_um.len() - 1)
                .find(|&k| wavelength_um[k] <= l && l <= wavelength_um[k + 1])
                .expect("inside the table");
            let (x0, x1, y0, y1) = (wavelength_um[k], wavelength_um[k + 1], n[k], n[k + 1]);
            y0 + (y1 - y0) * (l - x0) / (x1 - x0)
        }
        other => panic!("unexpected dispersion in a bundled table: {other:?}"),
    }
}

#[test]
fn every_bundled_formula_type_matches_its_closed_form() {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for g in GlassCatalog::bundled().all() {
        let kind = match &g.dispersion {
            Dispersion::Formula { number, .. } => format!("formula {number}"),
            Dispersion::Tabulated { .. } => "tabulated".to_string(),
            _ => "other".to_string(),
        };
        let (lo, hi) = g.range_um.unwrap_or((0.4, 0.7));
        for t in [0.1, 0.37, 0.5, 0.83] {
            let l = lo + t * (hi - lo);
            let want = closed_form(&g.dispersion, l);
            let got = g.index(l * 1e3);
            assert!(
                (got - want).abs() < 1e-12 * want,
                "{}/{} ({kind}) at {l} µm: {got} vs {want}",
                g.catalog,
                g.name
            );
        }
        *seen.entry(kind).or_insert(0) += 1;
    }
    let kinds: Vec<&str> = seen.keys().map(String::as_str).collect();
    assert_eq!(
        kinds,
        ["formula 1", "formula 2", "formula 3", "tabulated"],
        "{seen:?}"
    );
    assert!(
        seen["formula 2"] > 600 && seen["formula 3"] > 900,
        "{seen:?}"
    );
}
