//! `camsim metric scielab` (issue 17 §4): S-CIELAB on any picture pair shown on a display. A
//! uniform difference is unchanged by the S-CIELAB filters (they sum to 1), so the mean ΔE*ab
//! of two uniform pictures equals plain CIELAB ΔE*ab of the display colours, computed here
//! from the display model; hostile input gives one error line.
use crate::util::camsim;
use camsim_core::colorimetry::{delta_e_76, xyz_to_lab, Xyz};
use camsim_display::DisplayModel;
use std::path::Path;

fn write_rgb8(path: &Path, rows: u32, cols: u32, rgb: [u8; 3]) {
    let f = std::fs::File::create(path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(f), cols, rows);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().unwrap();
    let data: Vec<u8> = (0..rows * cols).flat_map(|_| rgb).collect();
    w.write_image_data(&data).unwrap();
}

fn display_xyz(d: &DisplayModel, rgb: [u8; 3]) -> Xyz {
    let prim = d.primaries_xyz();
    let mut out = Xyz {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    };
    for p in 0..3 {
        let l = d.linear_from_digital(p, rgb[p] as u32, 8).unwrap();
        out.x += l * prim[p].x;
        out.y += l * prim[p].y;
        out.z += l * prim[p].z;
    }
    out
}

fn mean_delta_e(stdout: &str) -> f64 {
    let t = stdout
        .split("mean ΔE ")
        .nth(1)
        .expect("a mean ΔE in the summary");
    t.split(',').next().unwrap().trim().parse().unwrap()
}

#[test]
fn scielab_of_uniform_pictures_is_plain_cielab_and_hostile_input_is_one_line() {
    let dir = std::env::temp_dir().join(format!("camsim_metric_cli_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (a, b, c) = (dir.join("a.png"), dir.join("b.png"), dir.join("c.png"));
    let (ca, cb) = ([120u8, 130, 110], [126u8, 128, 117]);
    write_rgb8(&a, 24, 32, ca);
    write_rgb8(&b, 24, 32, cb);
    write_rgb8(&c, 20, 32, cb);
    let d = DisplayModel::load("lcdExample").unwrap();
    let white = d.white_xyz();
    let expect = delta_e_76(
        xyz_to_lab(display_xyz(&d, ca), white),
        xyz_to_lab(display_xyz(&d, cb), white),
    );
    assert!(expect > 1.0, "{expect}");
    let run = |args: &[&str]| {
        let o = camsim().args(args).output().unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stdout).to_string(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (sa, sb, sc) = (
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        c.to_str().unwrap(),
    );
    let (ok, out, err) = run(&["metric", "scielab", sa, sb, "--viewing-distance-m", "0.5"]);
    assert!(ok, "{err}");
    let m = mean_delta_e(&out);
    assert!(
        (m - expect).abs() < 2e-4 * expect.max(1.0),
        "{m} vs {expect}: {out}"
    );
    let (ok, out, _) = run(&["metric", "scielab", sa, sa, "--viewing-distance-m", "0.5"]);
    assert!(ok && mean_delta_e(&out) == 0.0, "{out}");
    // ISETCam parameters: CIEDE2000 of the uniform colours (10° matrix inverts exactly); the
    // even 24×32 picture is cut to 23×31.
    let (ok, out, err) = run(&[
        "metric",
        "scielab",
        sa,
        sb,
        "--viewing-distance-m",
        "0.5",
        "--parameters",
        "isetcam",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("23×31 px"), "{out}");
    let de00 = camsim_metrics::delta_e_2000(
        xyz_to_lab(display_xyz(&d, ca), white),
        xyz_to_lab(display_xyz(&d, cb), white),
    );
    let m = mean_delta_e(&out);
    assert!(
        (m - de00).abs() < 2e-4 * de00.max(1.0),
        "{m} vs {de00}: {out}"
    );
    // Hostile input: one line naming the file or flag.
    for (args, needle) in [
        (
            vec!["metric", "scielab", sa, sc, "--viewing-distance-m", "0.5"],
            "c.png",
        ),
        (
            vec![
                "metric",
                "scielab",
                sa,
                "/nonexistent/x.png",
                "--viewing-distance-m",
                "0.5",
            ],
            "x.png",
        ),
        (
            vec!["metric", "scielab", sa, sb, "--viewing-distance-m=-1"],
            "--viewing-distance-m",
        ),
        (
            vec![
                "metric",
                "scielab",
                sa,
                sb,
                "--viewing-distance-m",
                "0.5",
                "--parameters",
                "x",
            ],
            "--parameters",
        ),
        (
            vec![
                "metric",
                "scielab",
                sa,
                sb,
                "--viewing-distance-m",
                "0.5",
                "--display",
                "nope",
            ],
            "--display",
        ),
    ] {
        let (ok, _, err) = run(&args);
        assert!(!ok, "{args:?} must fail");
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
