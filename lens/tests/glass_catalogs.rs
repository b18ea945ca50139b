//! The bundled glass tables against their source files, Zemax .agf catalogues against the
//! Zemax dispersion formulas written out here, and the glass-map search.
use camsim_lens::agf::{read_agf, zemax_dispersion};
use camsim_lens::glass::{Glass, GlassCatalog, LAMBDA_D_NM};
use std::path::Path;

const LAMBDAS_NM: [f64; 5] = [404.7, 486.1, 587.6, 656.3, 852.1];

/// Every Schott/Ohara/Hoya/CDGM file of the shared refractiveindex.info copy is in the bundled
/// table, with the same n(λ) (the table is generated from these files by tools/glass_tables.py).
#[test]
fn bundled_tables_reproduce_the_shared_refractiveindex_files() {
    let root =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real/lens/glass_catalogs");
    assert!(root.is_dir(), "{} missing (link ../shared)", root.display());
    let cat = GlassCatalog::bundled();
    let mut checked = 0;
    for vendor in ["schott", "ohara", "hoya", "cdgm"] {
        let mut stack = vec![root.join(vendor)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                    continue;
                }
                let Some(stem) = p.file_stem().and_then(|s| s.to_str()) else {
                    continue;
                };
                if p.extension().and_then(|x| x.to_str()) != Some("yml") {
                    continue;
                }
                let text = std::fs::read_to_string(&p).unwrap();
                let Ok(src) = Glass::from_refractiveindex_yaml(stem, vendor, &text) else {
                    continue;
                };
                // left out by the generator: data that do not reach the d line (IR glasses)
                if src
                    .range_um
                    .is_some_and(|(lo, hi)| lo > 0.5876 || hi < 0.5876)
                {
                    assert!(cat.find(stem, Some(vendor)).unwrap().is_none(), "{stem}");
                    continue;
                }
                let g = cat
                    .find(stem, Some(vendor))
                    .unwrap()
                    .unwrap_or_else(|| panic!("{vendor}/{stem} not in the bundled table"));
                for l in LAMBDAS_NM {
                    assert_eq!(g.index(l), src.index(l), "{vendor}/{stem} at {l} nm");
                }
                assert_eq!(
                    (g.catalog_nd, g.catalog_vd),
                    (src.catalog_nd, src.catalog_vd)
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 1050, "only {checked} files");
}

/// The glasses real .zmx files ask for (issue 17) resolve, each in its vendor's table.
#[test]
fn glasses_of_real_zmx_files_are_bundled() {
    let cat = GlassCatalog::bundled();
    for (name, vendor, nd) in [
        ("S-BSM15", "ohara", 1.62299),
        ("S-BAL12", "ohara", 1.53996),
        ("J-LAK14", "hikari", 1.6968),
        ("J-LAK02", "hikari", 1.67),
        ("E-LAFH3", "hikari", 1.79504),
        ("K-SSK1", "sumita", 1.6172),
        ("K-FK5", "sumita", 1.48749),
        ("K-SFLD6", "sumita", 1.80518),
        ("H-ZLAF52", "cdgm", 1.8061),
        ("L-TIM28", "ohara", 1.68948),
        ("SILICA", "misc", 1.458464),
        ("PMMA", "misc", 1.4914),
        ("POLYCARB", "misc", 1.5855),
    ] {
        let g = cat.glass(name, None).unwrap();
        assert_eq!(g.catalog, vendor, "{name}");
        assert!((g.nd() - nd).abs() < 2e-3, "{name}: n_d {} vs {nd}", g.nd());
    }
    // Malitson's fused silica: n = 1.458464 at the d line (Malitson 1965, Table 1 fit).
    let s = cat.glass("SILICA", Some("misc")).unwrap();
    assert!(
        (s.index(LAMBDA_D_NM) - 1.458464).abs() < 5e-6,
        "{}",
        s.index(LAMBDA_D_NM)
    );
}

#[test]
fn unknown_glass_names_similar_catalogue_glasses() {
    let e = GlassCatalog::bundled()
        .glass("X-LAK14", None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("X-LAK14") && e.contains("similar names"), "{e}");
    assert!(e.contains("hikari/J-LAK14"), "{e}");
}

#[test]
fn nearest_glasses_on_the_glass_map() {
    let cat = GlassCatalog::bundled();
    let n = cat.nearest(1.5168, 64.17, 5);
    assert_eq!(n.len(), 5);
    assert!(n.windows(2).all(|w| w[0].distance <= w[1].distance));
    assert!(n[0].distance < 0.05, "{:?}", n[0]);
    assert!(n.iter().any(|g| g.name == "N-BK7"), "{n:?}");
    // brute force: nothing in the catalogue is nearer than the fifth
    let d5 = n[4].distance;
    let closer = cat
        .all()
        .into_iter()
        .filter(|g| {
            let (nd, vd) = (
                g.catalog_nd.unwrap_or(g.nd()),
                g.catalog_vd.unwrap_or(g.vd()),
            );
            (((nd - 1.5168) / 0.01).powi(2) + (vd - 64.17).powi(2)).sqrt() < d5
        })
        .count();
    assert!(closer <= 4, "{closer}");
}

/// The Zemax formulas written out as in the OpticStudio manual, λ in µm.
fn zemax_closed_form(formula: u32, c: &[f64], l: f64) -> f64 {
    let a = |i: usize| c.get(i).copied().unwrap_or(0.0);
    let l2 = l * l;
    let sell = |k: usize| -> f64 {
        1.0 + (0..k)
            .map(|i| a(2 * i) * l2 / (l2 - a(2 * i + 1)))
            .sum::<f64>()
    };
    let n2 = match formula {
        1 => {
            a(0) + a(1) * l2 + a(2) / l2 + a(3) / l2.powi(2) + a(4) / l2.powi(3) + a(5) / l2.powi(4)
        }
        2 => sell(3),
        4 => 1.0 + a(0) + a(1) * l2 / (l2 - a(2) * a(2)) + a(3) / (l2 - a(4) * a(4)),
        5 => return a(0) + a(1) / l + a(2) / l.powf(3.5),
        6 => sell(4),
        7 => a(0) + a(1) / (l2 - a(2)) - a(3) * l2,
        8 => a(0) + a(1) * l2 / (l2 - a(2)) - a(3) * l2,
        9 => a(0) + a(1) * l2 / (l2 - a(2)) + a(3) * l2 / (l2 - a(4)),
        10 => (0..8)
            .map(|i| {
                a(i) * if i == 0 {
                    1.0
                } else if i == 1 {
                    l2
                } else {
                    l2.powi(1 - i as i32)
                }
            })
            .sum(),
        11 => sell(5),
        12 => {
            a(0) + a(1) * l2
                + a(2) / l2
                + a(3) / l2.powi(2)
                + a(4) / l2.powi(3)
                + a(5) / l2.powi(4)
                + a(6) * l2 * l2
                + a(7) * l2.powi(3)
        }
        13 => {
            a(0) + a(1) * l2
                + a(2) * l2 * l2
                + (3..9).map(|i| a(i) * l2.powi(2 - i as i32)).sum::<f64>()
        }
        _ => unreachable!(),
    };
    n2.sqrt()
}

#[test]
fn agf_formulas_match_the_zemax_definitions() {
    // Coefficient sets of the right magnitude for each law (a glass near n = 1.6).
    let cases: Vec<(u32, Vec<f64>)> = vec![
        (1, vec![2.55, -0.0101, 0.0162, 4.3e-4, -1.6e-5, 9.3e-7]),
        (
            2,
            vec![
                1.03961212,
                0.00600069867,
                0.231792344,
                0.0200179144,
                1.01046945,
                103.560653,
            ],
        ),
        (4, vec![0.1, 1.2, 0.09, 0.002, 0.15]),
        (5, vec![1.58, 0.008, 0.0003]),
        (6, vec![1.0, 0.006, 0.2, 0.02, 0.3, 80.0, 0.05, 150.0]),
        (7, vec![2.5, 0.018, 0.02, 0.01]),
        (8, vec![1.6, 0.95, 0.012, 0.008]),
        (9, vec![1.2, 1.3, 0.011, 0.6, 95.0]),
        (
            10,
            vec![2.55, -0.0101, 0.0162, 4.3e-4, -1.6e-5, 9.3e-7, 1e-8, 2e-9],
        ),
        (
            11,
            vec![1.0, 0.006, 0.2, 0.02, 0.3, 80.0, 0.05, 150.0, 0.01, 200.0],
        ),
        (
            12,
            vec![2.55, -0.0101, 0.0162, 4.3e-4, -1.6e-5, 9.3e-7, 1e-4, -2e-5],
        ),
        (
            13,
            vec![
                2.55, -0.0101, 1e-4, 0.0162, 4.3e-4, -1.6e-5, 9.3e-7, 1e-8, 2e-9,
            ],
        ),
    ];
    for (f, c) in &cases {
        let d = zemax_dispersion(*f, c).unwrap();
        for l in LAMBDAS_NM {
            let want = zemax_closed_form(*f, c, l * 1e-3);
            let got = d.index(l);
            assert!(
                (got - want).abs() < 1e-13,
                "formula {f} at {l} nm: {got} vs {want}"
            );
        }
    }
    assert!(
        zemax_dispersion(3, &[1.0]).is_none(),
        "Herzberger is refused"
    );
}

#[test]
fn agf_catalogue_reads_and_resolves_before_the_bundled_tables() {
    let agf = "CC test catalogue\r\nNM MYBK7 2 517642 1.5168 64.17 0 0 0\r\nGC made up\r\n\
               CD 1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653 0 0 0 0\r\n\
               LD 0.3 2.5\r\nNM TAF3COPY 1 804465 1.8042 46.5 0 0 0\r\n\
               CD 3.1743707 -0.014110466 0.028862637 3.355949e-05 8.0422109e-05 -2.8956744e-06 0 0 0 0\r\n";
    let g = read_agf(agf.as_bytes(), "test").unwrap();
    assert_eq!(g.len(), 2);
    assert_eq!(g[0].range_um, Some((0.3, 2.5)));
    let bk7 = GlassCatalog::bundled()
        .glass("N-BK7", Some("schott"))
        .unwrap();
    for l in LAMBDAS_NM {
        assert!((g[0].index(l) - bk7.index(l)).abs() < 1e-15);
    }
    // the Schott power series against Hoya's formula-3 TAF3 (same six coefficients)
    let taf3 = GlassCatalog::bundled().glass("TAF3", Some("hoya")).unwrap();
    assert!(
        (g[1].nd() - taf3.nd()).abs() < 1e-15,
        "{} {}",
        g[1].nd(),
        taf3.nd()
    );
    // a catalogue file: searched first, by its stem
    let dir = std::env::temp_dir().join(format!("camsim_agf_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("ACME.agf");
    std::fs::write(&p, agf).unwrap();
    let cat = GlassCatalog::bundled().with_agf(&p).unwrap();
    assert_eq!(cat.glass("mybk7", None).unwrap().catalog, "ACME");
    assert_eq!(cat.glass("MYBK7", Some("acme")).unwrap().name, "MYBK7");
    assert_eq!(cat.glass("N-BK7", None).unwrap().catalog, "schott");
    // hostile input: one clear error naming the file and line
    std::fs::write(&p, "NM BAD 2 0 1.5 60\nCD 1 x 3\n").unwrap();
    let e = GlassCatalog::bundled()
        .with_agf(&p)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ACME.agf") && e.contains("line 2") && e.contains("'x'"),
        "{e}"
    );
    std::fs::write(&p, "NM OLD 3 0 1.5 60\nCD 1 2 3\n").unwrap();
    let e = GlassCatalog::bundled()
        .with_agf(&p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("formula 3"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
