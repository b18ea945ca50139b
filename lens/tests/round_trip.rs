//! Reversibility of real rays (Helmholtz reciprocity of geometric optics): a ray traced forward
//! through a lens and then backward from its end point, with reversed direction, through the
//! reversed surface sequence, retraces its path and arrives where it started.
//!
//! The crate has no backward trace, so the reversed lens is built from the same surfaces:
//!
//! * frame: z' = z_last − z, where z_last is the vertex z of the last surface (so the reversed
//!   lens has its first vertex at z' = 0, as every `LensPrescription` does); the original
//!   image plane lies at z' = −t_last, in the reversed object space;
//! * order: reversed surface i is original surface N−1−i;
//! * shape: mirroring z negates the sag, so the curvature and every aspheric coefficient
//!   change sign; the conic constant stays;
//! * media: the medium *after* reversed surface i is the medium *before* original surface
//!   N−1−i, i.e. that of original surface N−2−i, and air after the last one (original object
//!   space). The reversed object space is the original image space, which must be air;
//! * thicknesses: reversed surface i gets the original thickness of surface N−2−i (the gap
//!   in front of original N−1−i); the last one (original surface 0) gets 0, so the reversed
//!   "image plane" is the plane of the original first vertex;
//! * ray: origin = image-plane point mapped to z' (x, y unchanged), direction (L, M, −N)
//!   mapped to z' then reversed, i.e. (−L, −M, N).
//!
//! The backward ray leaves the reversed lens in original object space (a straight line), so
//! its point on the original first surface is found by intersecting that line with surface 0
//! (`trace::intersect`), and compared with the forward ray's point on surface 0.
use camsim_lens::prescription::{Medium, Surface};
use camsim_lens::trace::{intersect, Ray};
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};

fn lens_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses")
        .join(name)
}

/// The reversed lens (see the module docs) and z_last (vertex z of the last original surface).
fn reversed(l: &LensPrescription) -> (LensPrescription, f64) {
    let n = l.surfaces.len();
    assert!(
        matches!(l.surfaces[n - 1].medium, Medium::Air),
        "image space must be air"
    );
    let z = l.vertex_z_mm();
    let z_last = z[n - 1];
    let mut surfaces = Vec::with_capacity(n);
    for i in 0..n {
        let j = n - 1 - i; // original index
        let s = &l.surfaces[j];
        let (medium, material, thickness_mm) = if j == 0 {
            (
                Medium::Air,
                camsim_lens::prescription::MaterialFile::Name("air".into()),
                0.0,
            )
        } else {
            let p = &l.surfaces[j - 1];
            (p.medium.clone(), p.material.clone(), p.thickness_mm)
        };
        surfaces.push(Surface {
            curvature_per_mm: -s.curvature_per_mm,
            thickness_mm,
            medium,
            material,
            semi_diameter_mm: s.semi_diameter_mm,
            conic: s.conic,
            aspheric_coeffs: s.aspheric_coeffs.iter().map(|a| -a).collect(),
            odd_aspheric_coeffs: s.odd_aspheric_coeffs.iter().map(|b| -b).collect(),
        });
    }
    let r = LensPrescription {
        name: format!("{} (reversed)", l.name),
        surfaces,
        stop_index: n - 1 - l.stop_index,
        object_distance_mm: None,
        fields_deg: vec![0.0],
        wavelengths_nm: l.wavelengths_nm.clone(),
        primary_nm: l.primary_nm,
        aperture: l.aperture,
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    (r, z_last)
}

fn check_round_trip(l: &LensPrescription, fields_deg: &[f64], wavelengths_nm: &[f64]) -> usize {
    let (rev, z_last) = reversed(l);
    // Sanity: the reversed vertex positions are the mirrored originals.
    let z = l.vertex_z_mm();
    let zr = rev.vertex_z_mm();
    let n = l.surfaces.len();
    for i in 0..n {
        assert!((zr[i] - (z_last - z[n - 1 - i])).abs() < 1e-9);
    }
    let fo = l.first_order(l.primary_nm).unwrap();
    let pupil = [
        [0.0, 0.0],
        [0.0, 0.7],
        [0.0, -0.7],
        [0.5, 0.3],
        [-0.4, -0.5],
        [0.65, 0.0],
    ];
    let mut checked = 0;
    for &f in fields_deg {
        let aim = l.aim_field(f, l.primary_nm, &fo).unwrap();
        for &[px, py] in &pupil {
            let ray = aim.ray(px, py);
            for &w in wavelengths_nm {
                // Forward, vignetted: only physical rays (no virtual back-steps).
                let Some(fwd) = l.trace(&ray, w, Clipping::SemiDiameters) else {
                    continue;
                };
                let (_, start) = intersect(&l.surfaces[0], 0.0, &ray).unwrap();
                let d = fwd.direction;
                let back = Ray {
                    origin_mm: [fwd.image_mm[0], fwd.image_mm[1], z_last - fwd.image_mm[2]],
                    direction: [-d[0], -d[1], d[2]],
                    opl_mm: 0.0,
                };
                let b = rev
                    .trace(&back, w, Clipping::SemiDiameters)
                    .unwrap_or_else(|| {
                        panic!("backward ray lost: field {f}, pupil ({px},{py}), {w} nm")
                    });
                // Back to the original frame: a ray leaving the lens towards −z.
                let bd = [b.direction[0], b.direction[1], -b.direction[2]];
                let bp = [b.image_mm[0], b.image_mm[1], z_last - b.image_mm[2]];
                // Its point on original surface 0 (intersect needs a +z-going ray: reverse it).
                let probe = Ray {
                    origin_mm: [
                        bp[0] - 1e3 * bd[0],
                        bp[1] - 1e3 * bd[1],
                        bp[2] - 1e3 * bd[2],
                    ],
                    direction: [-bd[0], -bd[1], -bd[2]],
                    opl_mm: 0.0,
                };
                let (_, end) = intersect(&l.surfaces[0], 0.0, &probe).unwrap();
                for k in 0..3 {
                    assert!(
                        (end[k] - start[k]).abs() < 1e-9,
                        "position {k}: {end:?} vs {start:?} (field {f}, pupil ({px},{py}), {w} nm)"
                    );
                    assert!(
                        (-bd[k] - ray.direction[k]).abs() < 1e-9,
                        "direction {k}: {:?} vs {:?} (field {f}, pupil ({px},{py}), {w} nm)",
                        [-bd[0], -bd[1], -bd[2]],
                        ray.direction
                    );
                }
                checked += 1;
            }
        }
    }
    checked
}

#[test]
fn double_gauss_rays_retrace_their_path() {
    let l = LensPrescription::from_json_file(
        lens_path("double_gauss_50mm_f2.json"),
        &GlassCatalog::bundled(),
    )
    .unwrap();
    let n = check_round_trip(&l, &[0.0, 7.0, 14.0, 20.0], &[486.1, 656.3]);
    assert!(n >= 30, "only {n} rays checked");
}

#[test]
fn aspheric_lens_rays_retrace_their_path() {
    // Even-asphere surfaces exercise the sign flip of the aspheric coefficients.
    let l = LensPrescription::from_json_file(
        lens_path("zmx_us8427765_aspheric.json"),
        &GlassCatalog::bundled(),
    )
    .unwrap();
    assert!(l.surfaces.iter().any(|s| !s.is_conic_only()));
    let w = &l.wavelengths_nm;
    let n = check_round_trip(&l, &[0.0, 10.0], &[w[0], w[w.len() - 1]]);
    assert!(n >= 10, "only {n} rays checked");
}
