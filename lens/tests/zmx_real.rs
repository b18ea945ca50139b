//! Every refractive .zmx in ../shared/data/real/lens/prescriptions loads with the bundled
//! glass tables alone (no substitutions) and traces on axis and at its largest field
//! (issue 17 §3 / acceptance 2), the two reflective ones (GLAS MIRROR, COORDBRK) included.
use camsim_lens::readers::{read_zmx_file, zmx_glass_catalog, ZmxOptions};
use camsim_lens::{Clipping, LensPrescription};
use std::path::Path;

#[test]
fn real_zmx_files_load_without_substitutions_and_trace() {
    let dir =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real/lens/prescriptions");
    assert!(dir.is_dir(), "{} missing (link ../shared)", dir.display());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    let (mut traced, mut reflective) = (Vec::new(), Vec::new());
    for p in files {
        if !p.extension().is_some_and(|x| x.eq_ignore_ascii_case("zmx")) {
            continue;
        }
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let opts = ZmxOptions::default();
        let f = read_zmx_file(&p, &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
        let bytes = std::fs::read(&p).unwrap();
        let cat = zmx_glass_catalog(&bytes, &opts).unwrap();
        let lens = LensPrescription::from_file_form(&f, &cat).unwrap();
        let lens = lens.focused(lens.primary_nm).unwrap();
        let wl = lens.primary_nm;
        let fo = lens.first_order(wl).unwrap();
        let full = lens.fields_deg.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        for th in [0.0, full] {
            let aim = lens
                .aim_field(th, wl, &fo)
                .unwrap_or_else(|e| panic!("{name} {th}°: {e}"));
            assert!(
                lens.trace(&aim.ray(0.0, 0.0), wl, Clipping::None).is_some(),
                "{name} {th}°: chief ray lost"
            );
            let fan = lens
                .ray_fan(
                    th,
                    wl,
                    wl,
                    &camsim_lens::analysis::pupil_grid(9),
                    Clipping::None,
                )
                .unwrap();
            assert!(
                fan.rays.iter().all(Option::is_some),
                "{name} {th}°: rays lost"
            );
        }
        if lens.has_folds() {
            reflective.push(name.clone());
        }
        traced.push(name);
    }
    // three refractive files (Schott; SILICA; Hikari J-LAK14 + Ohara L-TIM28_MOLD + Hoya) and
    // two with mirrors (Hikari, Ohara, Sumita glasses; a coordinate break)
    assert_eq!(traced.len(), 5, "{traced:?}");
    assert_eq!(reflective.len(), 2, "{reflective:?}");
}

#[test]
fn mold_glass_reads_as_its_base_glass_with_a_note() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/real/lens/prescriptions/rayoptics_US08427765-1.ZMX");
    let f = read_zmx_file(&p, &ZmxOptions::default()).unwrap();
    let note = f.provenance.unwrap_or_default();
    assert!(
        note.contains("L-TIM28_MOLD read as ohara/L-TIM28"),
        "{note}"
    );
}

fn tmp_dir(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("camsim_zmx_{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

const ZMX: &str = "MODE SEQ\nUNIT MM\nENPD 10\nGCAT ACME SCHOTT\nSURF 0\n  DISZ INFINITY\n\
SURF 1\n  STOP\n  CURV 0.02\n  DISZ 4\n  GLAS GLASSNAME 0 0 1.5168 64.17 0\n  DIAM 6\n\
SURF 2\n  CURV -0.01\n  DISZ 90\nSURF 3\n  DISZ 0\n";

#[test]
fn unknown_glass_names_the_nearest_catalogue_glasses() {
    let d = tmp_dir("unknown");
    let p = d.join("lens.zmx");
    std::fs::write(&p, ZMX.replace("GLASSNAME", "MYSTERY7")).unwrap();
    let e = read_zmx_file(&p, &ZmxOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("MYSTERY7") && e.contains("surface 1"), "{e}");
    assert!(e.contains("nearest by (nd 1.5168, Vd 64.17)"), "{e}");
    assert!(e.contains("schott/N-BK7"), "{e}");
    assert!(e.contains("ACME") && e.contains("no .agf"), "{e}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn gcat_agf_beside_the_zmx_is_read() {
    let d = tmp_dir("agf");
    let p = d.join("lens.zmx");
    std::fs::write(&p, ZMX.replace("GLASSNAME", "MYBK7")).unwrap();
    std::fs::write(
        d.join("acme.AGF"),
        "NM MYBK7 2 517642 1.5168 64.17 0 0 0\n\
         CD 1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653\nLD 0.3 2.5\n",
    )
    .unwrap();
    let opts = ZmxOptions::default();
    let f = read_zmx_file(&p, &opts).unwrap();
    let mut opts_dir = opts.clone();
    opts_dir.agf_dirs.push(d.clone());
    let cat = zmx_glass_catalog(&std::fs::read(&p).unwrap(), &opts_dir).unwrap();
    let lens = LensPrescription::from_file_form(&f, &cat).unwrap();
    // the same lens in Schott N-BK7 has the same EFL (identical coefficients)
    std::fs::write(&p, ZMX.replace("GLASSNAME", "N-BK7")).unwrap();
    let f2 = read_zmx_file(&p, &opts).unwrap();
    let l2 = LensPrescription::from_file_form(&f2, &cat).unwrap();
    let (a, b) = (
        lens.first_order(587.6).unwrap(),
        l2.first_order(587.6).unwrap(),
    );
    assert!(
        (a.efl_mm - b.efl_mm).abs() < 1e-12,
        "{} {}",
        a.efl_mm,
        b.efl_mm
    );
    std::fs::remove_dir_all(&d).ok();
}
