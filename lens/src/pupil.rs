//! Tracing from the sensor and sampling the exit pupil, for cameras that generate rays at the
//! film (the path tracer's real-lens and light-field cameras).
//!
//! The idea follows pbrt-v4's `RealisticCamera` (Pharr, Jakob & Humphreys, *Physically Based
//! Rendering*, 4th ed., §5.3: `TraceLensesFromFilm`, `BoundExitPupil`, `SampleExitPupil` and
//! its `ExitPupilSample` record), re-derived here for the lens crate's prescriptions:
//!
//! * **Sensor-side lens** ([`SensorSideLens`]): the prescription mirrored about the image plane,
//!   z' = z_img − z (sensor at z' = 0, the surfaces in reverse order with negated curvature and
//!   aspheric coefficients, each followed by the medium in front of it in the lens frame). Every
//!   step of a sensor-side trace is then a forward step of the crate's one surface step
//!   ([`crate::trace::surface_step`]: intersection, clear-aperture test, vector Snell law).
//!   Refractive indices come from a 1-nm table per medium, linearly interpolated, since the
//!   path tracer evaluates them once per surface per camera ray.
//! * **Exit-pupil bounds** ([`ExitPupilTable`]): for film radii in `bins` intervals of
//!   [0, r_max], the axis-aligned box on the rear-vertex plane that holds every point through
//!   which a ray from the film point (on +x) gets through the lens, found on a coarse-then-fine
//!   grid at the shortest, primary and longest wavelength, at both ends and the middle of the
//!   interval, widened by one fine cell. A film point at azimuth φ samples the box of its
//!   interval uniformly and rotates the point by φ (rotational symmetry).
//! * **Sample** ([`ExitPupilSample`]): the rear-plane point and its pdf with respect to area on
//!   the rear plane, 1 / box area.
//! * **Chief rays**: the rear-plane aim point of the ray through the stop centre, solved by
//!   secant steps at the interval ends and interpolated in between (the depth channel's centre
//!   ray).
use crate::error::LensError;
use crate::prescription::{LensPrescription, Medium, Surface};
use crate::trace::{intersect, secant_root, surface_step, Clipping, Ray, Vec3};
use rayon::prelude::*;

/// Axis-aligned box on the rear-vertex plane (mm, film point on +x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PupilBounds {
    /// Lower x.
    pub x0_mm: f64,
    /// Upper x.
    pub x1_mm: f64,
    /// Lower y.
    pub y0_mm: f64,
    /// Upper y.
    pub y1_mm: f64,
}

impl PupilBounds {
    /// Area (mm²).
    pub fn area_mm2(&self) -> f64 {
        (self.x1_mm - self.x0_mm) * (self.y1_mm - self.y0_mm)
    }

    fn include(b: &mut Option<PupilBounds>, x: f64, y: f64) {
        match b {
            None => {
                *b = Some(PupilBounds {
                    x0_mm: x,
                    x1_mm: x,
                    y0_mm: y,
                    y1_mm: y,
                })
            }
            Some(b) => {
                b.x0_mm = b.x0_mm.min(x);
                b.x1_mm = b.x1_mm.max(x);
                b.y0_mm = b.y0_mm.min(y);
                b.y1_mm = b.y1_mm.max(y);
            }
        }
    }

    fn union(a: Option<PupilBounds>, b: Option<PupilBounds>) -> Option<PupilBounds> {
        match (a, b) {
            (None, x) | (x, None) => x,
            (Some(a), Some(b)) => Some(PupilBounds {
                x0_mm: a.x0_mm.min(b.x0_mm),
                x1_mm: a.x1_mm.max(b.x1_mm),
                y0_mm: a.y0_mm.min(b.y0_mm),
                y1_mm: a.y1_mm.max(b.y1_mm),
            }),
        }
    }

    fn widened(self, d_mm: f64) -> PupilBounds {
        PupilBounds {
            x0_mm: self.x0_mm - d_mm,
            x1_mm: self.x1_mm + d_mm,
            y0_mm: self.y0_mm - d_mm,
            y1_mm: self.y1_mm + d_mm,
        }
    }
}

/// n(λ) of each medium on a 1-nm grid (linear interpolation, clamped at the ends).
#[derive(Debug, Clone)]
struct IndexTable {
    lo_nm: f64,
    n_per_row: usize,
    values: Vec<f64>,
}

impl IndexTable {
    const LO_NM: f64 = 250.0;
    const HI_NM: f64 = 1300.0;

    fn new(media: &[Medium]) -> Self {
        let n_per_row = (Self::HI_NM - Self::LO_NM) as usize + 1;
        let mut values = Vec::with_capacity(media.len() * n_per_row);
        for m in media {
            for i in 0..n_per_row {
                values.push(m.index(Self::LO_NM + i as f64));
            }
        }
        IndexTable {
            lo_nm: Self::LO_NM,
            n_per_row,
            values,
        }
    }

    #[inline]
    fn index(&self, row: usize, wavelength_nm: f64) -> f64 {
        let x = (wavelength_nm - self.lo_nm).clamp(0.0, (self.n_per_row - 1) as f64);
        let i = (x as usize).min(self.n_per_row - 2);
        let t = x - i as f64;
        let r = &self.values[row * self.n_per_row..(row + 1) * self.n_per_row];
        r[i] * (1.0 - t) + r[i + 1] * t
    }
}

/// A ray that left the front of the lens, traced from the sensor (mirrored frame, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorExit {
    /// Point on the front surface (mirrored frame: x, y, z').
    pub origin_mm: Vec3,
    /// Unit direction (mirrored frame, +z' = towards the object).
    pub direction: Vec3,
    /// Where the ray crossed the aperture stop (x, y mm).
    pub stop_mm: [f64; 2],
}

/// One surface of the mirrored lens.
#[derive(Debug, Clone)]
struct MirroredSurface {
    surface: Surface,
    /// Vertex z' (mm) in the mirrored frame.
    z_mm: f64,
    /// Row of the index table of the medium after this surface (towards the object).
    medium_after: usize,
}

/// A coaxial prescription seen from its image plane (see the module docs).
#[derive(Debug, Clone)]
pub struct SensorSideLens {
    surfaces: Vec<MirroredSurface>,
    stop_index: usize,
    index: IndexTable,
    rear_plane_mm: f64,
    image_z_mm: f64,
}

impl SensorSideLens {
    /// Mirror `lens` about its image plane (last vertex + last thickness). Refuses lenses with
    /// mirrors or coordinate breaks, and an image space that is not air.
    pub fn new(lens: &LensPrescription) -> Result<Self, LensError> {
        if lens.has_folds() {
            return Err(LensError::Prescription(format!(
                "lens '{}': mirrors and coordinate breaks cannot be traced from the sensor",
                lens.name
            )));
        }
        let ns = lens.surfaces.len();
        if ns == 0 || !matches!(lens.surfaces[ns - 1].medium, Medium::Air) {
            return Err(LensError::Prescription(format!(
                "lens '{}': the image space (medium after the last surface) must be air",
                lens.name
            )));
        }
        let z = lens.vertex_z_mm();
        let image_z_mm = z[ns];
        let mut media = vec![Medium::Air];
        let mut surfaces = Vec::with_capacity(ns);
        for i in 0..ns {
            let j = ns - 1 - i;
            let s = &lens.surfaces[j];
            media.push(if j == 0 {
                Medium::Air
            } else {
                lens.surfaces[j - 1].medium.clone()
            });
            let mut m = s.clone();
            m.curvature_per_mm = -s.curvature_per_mm;
            m.aspheric_coeffs = s.aspheric_coeffs.iter().map(|a| -a).collect();
            m.odd_aspheric_coeffs = s.odd_aspheric_coeffs.iter().map(|b| -b).collect();
            surfaces.push(MirroredSurface {
                surface: m,
                z_mm: image_z_mm - z[j],
                medium_after: i + 1,
            });
        }
        let rear_plane_mm = surfaces[0].z_mm;
        if !(rear_plane_mm > 0.0) {
            return Err(LensError::Prescription(format!(
                "lens '{}': the image plane is not behind the last surface (distance \
                 {rear_plane_mm} mm)",
                lens.name
            )));
        }
        Ok(SensorSideLens {
            surfaces,
            stop_index: ns - 1 - lens.stop_index,
            index: IndexTable::new(&media),
            rear_plane_mm,
            image_z_mm,
        })
    }

    /// Image plane → rear vertex distance (mm): where the rear plane of the pupil table lies.
    pub fn rear_plane_mm(&self) -> f64 {
        self.rear_plane_mm
    }

    /// z of the image plane in the lens frame (mm from the first vertex).
    pub fn image_z_mm(&self) -> f64 {
        self.image_z_mm
    }

    /// Trace a ray from the sensor side (mirrored frame) through the lens at `wavelength_nm`.
    /// `None` if it misses a surface or is totally reflected, and with
    /// [`Clipping::SemiDiameters`] also if it is vignetted or steps backwards.
    pub fn trace(
        &self,
        origin_mm: Vec3,
        direction: Vec3,
        wavelength_nm: f64,
        clipping: Clipping,
    ) -> Option<SensorExit> {
        let mut r = Ray {
            origin_mm,
            direction,
            opl_mm: 0.0,
        };
        let mut n1 = 1.0;
        let mut stop = [f64::NAN; 2];
        for (i, s) in self.surfaces.iter().enumerate() {
            let (t, q) = intersect(&s.surface, s.z_mm, &r)?;
            let n2 = self.index.index(s.medium_after, wavelength_nm);
            let local = [q[0], q[1], q[2] - s.z_mm];
            // The trace starts at the sensor, so a backwards step at any surface (index ≥ 1
            // for the shared step) is a ray lost at an element edge.
            let d = surface_step(&s.surface, i + 1, t, local, r.direction, n1, n2, clipping)?;
            if i == self.stop_index {
                stop = [q[0], q[1]];
            }
            r = Ray {
                origin_mm: q,
                direction: d,
                opl_mm: 0.0,
            };
            n1 = n2;
        }
        Some(SensorExit {
            origin_mm: r.origin_mm,
            direction: r.direction,
            stop_mm: stop,
        })
    }

    /// Trace from sensor point `p` (mm) towards rear-plane point `q` (mm).
    pub fn trace_through(
        &self,
        p: [f64; 2],
        q: [f64; 2],
        wavelength_nm: f64,
        clipping: Clipping,
    ) -> Option<SensorExit> {
        self.trace(
            [p[0], p[1], 0.0],
            self.direction_to(p, q),
            wavelength_nm,
            clipping,
        )
    }

    /// Unit direction from sensor point `p` to rear-plane point `q` (mm).
    pub fn direction_to(&self, p: [f64; 2], q: [f64; 2]) -> Vec3 {
        let d = [q[0] - p[0], q[1] - p[1], self.rear_plane_mm];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        [d[0] / l, d[1] / l, d[2] / l]
    }

    /// Film irradiance per unit scene radiance (sr) at the centre of the film, at
    /// `wavelength_nm`: [`SensorSideLens::irradiance_per_radiance_sr`] at film radius 0 (the
    /// real lens's camera-equation factor). For an aplanatic lens whose film lies at the
    /// paraxial image it is the paraxial camera equation π/(4N_w²) (paper Eq. 1); a real lens
    /// departs from it by its pupil's spherical aberration, the pupil's change with wavelength,
    /// and a film moved to the best focus.
    pub fn axial_irradiance_per_radiance_sr(&self, wavelength_nm: f64, grid: usize) -> f64 {
        self.irradiance_per_radiance_sr(0.0, wavelength_nm, grid)
    }

    /// Coarse scan ([`Self::scan`], `coarse`² points, from the film point at `film_radius_mm`)
    /// over a centred square of half-width `half_width_mm` on the rear plane, doubled (at most
    /// `tries` − 1 times) while the bundle found touches the square's edge: the bounds and the
    /// final half-width; `None` when no ray gets through.
    fn scan_growing(
        &self,
        film_radius_mm: f64,
        half_width_mm: f64,
        coarse: usize,
        wavelengths_nm: &[f64],
        tries: usize,
    ) -> Option<(PupilBounds, f64)> {
        let mut e = half_width_mm;
        let mut found = None;
        for _ in 0..tries {
            let sq = PupilBounds {
                x0_mm: -e,
                x1_mm: e,
                y0_mm: -e,
                y1_mm: e,
            };
            found = self.scan(film_radius_mm, sq, coarse, wavelengths_nm);
            let cell = 2.0 * e / coarse as f64;
            match found {
                Some(b)
                    if b.x0_mm < -e + cell
                        || b.x1_mm > e - cell
                        || b.y0_mm < -e + cell
                        || b.y1_mm > e - cell =>
                {
                    e *= 2.0
                }
                _ => break,
            }
        }
        found.map(|b| (b, e))
    }

    /// Film irradiance per unit scene radiance (sr) at the film point at radius
    /// `film_radius_mm` from the axis, at `wavelength_nm`, for a scene of uniform radiance in
    /// every direction the lens sees:
    ///
    ///   E/L = ∫ cos⁴θ / d² dA
    ///
    /// over the rear-plane points q through which a ray from the film point gets through the
    /// lens (θ the ray's angle to the axis, d the film-to-rear-plane distance; radiance is
    /// conserved along the ray, T = 1). This is the integral the real-lens camera's estimator
    /// samples (module docs; pbrt-v4 §5.3.3, `RealisticCamera`'s weight cos⁴θ·A/d²), here by
    /// the midpoint rule: the bundle's bounds on a coarse grid (`grid` clamped to 16–48 per
    /// side) over the rear surface's clear aperture (the square doubled while the bundle
    /// touches its edge), widened by one cell, then `grid`² points over them. Off the axis its
    /// ratio to the axial value is the lens's relative illumination
    /// ([`film_relative_illumination`]): vignetting, the cos⁴ fall-off and the pupil's
    /// aberrations at once. 0 when no ray gets through.
    pub fn irradiance_per_radiance_sr(
        &self,
        film_radius_mm: f64,
        wavelength_nm: f64,
        grid: usize,
    ) -> f64 {
        let r = film_radius_mm;
        let mut h = self.surfaces[0]
            .surface
            .semi_diameter_mm
            .unwrap_or(self.rear_plane_mm)
            .max(1e-9);
        let coarse = grid.clamp(16, 48);
        let Some((b, grown)) = self.scan_growing(r, h, coarse, &[wavelength_nm], 4) else {
            return 0.0;
        };
        h = grown;
        let cell = 2.0 * h / coarse as f64;
        let b = PupilBounds {
            x0_mm: b.x0_mm - cell,
            x1_mm: b.x1_mm + cell,
            y0_mm: b.y0_mm - cell,
            y1_mm: b.y1_mm + cell,
        };
        let n = grid.max(8);
        let (wx, wy) = (
            (b.x1_mm - b.x0_mm) / n as f64,
            (b.y1_mm - b.y0_mm) / n as f64,
        );
        let d2 = self.rear_plane_mm * self.rear_plane_mm;
        // per-row sums, added in row order (the same bits at any thread count)
        let rows: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|iy| {
                let y = b.y0_mm + wy * (iy as f64 + 0.5);
                (0..n)
                    .map(|ix| {
                        let q = [b.x0_mm + wx * (ix as f64 + 0.5), y];
                        let dir = self.direction_to([r, 0.0], q);
                        match self.trace([r, 0.0, 0.0], dir, wavelength_nm, Clipping::SemiDiameters)
                        {
                            Some(_) => dir[2].powi(4) / d2,
                            None => 0.0,
                        }
                    })
                    .sum::<f64>()
            })
            .collect();
        rows.iter().sum::<f64>() * wx * wy
    }

    /// Bounds of the rear-plane points through which rays from (r, 0) get through, at the
    /// given wavelengths, on a `g`×`g` grid over `b`; `None` when none gets through.
    fn scan(&self, r: f64, b: PupilBounds, g: usize, wls: &[f64]) -> Option<PupilBounds> {
        let mut out = None;
        for iy in 0..g {
            let y = b.y0_mm + (b.y1_mm - b.y0_mm) * (iy as f64 + 0.5) / g as f64;
            for ix in 0..g {
                let x = b.x0_mm + (b.x1_mm - b.x0_mm) * (ix as f64 + 0.5) / g as f64;
                if wls.iter().any(|&w| {
                    self.trace_through([r, 0.0], [x, y], w, Clipping::SemiDiameters)
                        .is_some()
                }) {
                    PupilBounds::include(&mut out, x, y);
                }
            }
        }
        out
    }

    /// Rear-plane x of the chief ray (through the stop centre) from (r, 0), by secant steps
    /// ([`crate::trace::secant_root`]) to a stop height below 1e-10 mm.
    fn solve_chief(&self, r: f64, guess: f64, wavelength_nm: f64) -> Option<f64> {
        let f = |a: f64| {
            self.trace_through([r, 0.0], [a, 0.0], wavelength_nm, Clipping::None)
                .map(|e| e.stop_mm[0])
        };
        let f0 = f(guess)?;
        secant_root(&f, guess, f0, 1e-3 * (1.0 + guess.abs()), 1e-10)
    }
}

/// Options of [`ExitPupilTable::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitPupilOptions {
    /// Film-radius intervals of the table.
    pub bins: usize,
    /// Fine grid per side (the coarse grid is half of it, at least 8).
    pub grid: usize,
    /// Wavelengths the bounds must cover (nm): shortest, primary, longest.
    pub wavelengths_nm: [f64; 3],
    /// Half-width (mm) of the first coarse search square (doubled until the pupil is inside).
    pub search_half_width_mm: f64,
    /// Paraxial exit pupil → image plane distance (mm): the chief-ray solver's first guess.
    pub exit_pupil_to_image_mm: f64,
}

/// One draw from the exit pupil, in the manner of pbrt-v4's `ExitPupilSample`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitPupilSample {
    /// The point on the rear-vertex plane (mm), rotated to the film point's azimuth.
    pub rear_point_mm: [f64; 2],
    /// Its density with respect to area on the rear plane (1/mm²): 1 / box area.
    pub pdf_per_mm2: f64,
    /// The area of the box it was drawn from (mm²), 1 / `pdf_per_mm2` without the rounding of
    /// a second division.
    pub box_area_mm2: f64,
}

/// Exit-pupil bounds and chief rays by film radius (see the module docs).
#[derive(Debug, Clone)]
pub struct ExitPupilTable {
    r_max_mm: f64,
    bins: Vec<Option<PupilBounds>>,
    /// Chief-ray rear-plane x (mm) at the interval ends k·Δ, k = 0..=bins.
    chief_x_mm: Vec<Option<f64>>,
}

impl ExitPupilTable {
    /// Bound the exit pupil of `lens` for film radii up to `r_max_mm` and solve its chief rays
    /// at the primary wavelength (`opts.wavelengths_nm[1]`).
    pub fn new(
        lens: &SensorSideLens,
        r_max_mm: f64,
        opts: &ExitPupilOptions,
    ) -> Result<Self, LensError> {
        if opts.bins == 0 || opts.grid < 8 || !(r_max_mm > 0.0 && r_max_mm.is_finite()) {
            return Err(LensError::Prescription(format!(
                "exit-pupil table: bins = {} must be ≥ 1, grid = {} ≥ 8 and film radius {} mm \
                 > 0",
                opts.bins, opts.grid, r_max_mm
            )));
        }
        let nb = opts.bins;
        let dr = r_max_mm / nb as f64;
        let wls = opts.wavelengths_nm;
        let fine = opts.grid;
        let coarse = (fine / 2).max(8);
        // Bounds at the interval ends and middles r_i = i·Δ/2 (shared by neighbouring
        // intervals), then interval k = union of r_2k, r_2k+1, r_2k+2.
        let at_radius: Vec<Option<PupilBounds>> = (0..=2 * nb)
            .into_par_iter()
            .map(|i| {
                let r = i as f64 * 0.5 * dr;
                // Coarse scan over a square that grows until the pupil is inside it.
                let (b, e) = lens.scan_growing(r, opts.search_half_width_mm, coarse, &wls, 6)?;
                // Fine scan of the coarse box widened by one coarse cell, widened in turn by
                // one fine cell.
                let wide = b.widened(2.0 * e / coarse as f64);
                let c = (wide.x1_mm - wide.x0_mm).max(wide.y1_mm - wide.y0_mm) / fine as f64;
                lens.scan(r, wide, fine, &wls).map(|f| f.widened(c))
            })
            .collect();
        let bins: Vec<Option<PupilBounds>> = (0..nb)
            .map(|k| {
                PupilBounds::union(
                    PupilBounds::union(at_radius[2 * k], at_radius[2 * k + 1]),
                    at_radius[2 * k + 2],
                )
            })
            .collect();
        // Chief rays; first guess: the line from the film point to the paraxial exit-pupil
        // centre.
        let xp = opts.exit_pupil_to_image_mm;
        let rear = lens.rear_plane_mm();
        let chief_x_mm = (0..=nb)
            .into_par_iter()
            .map(|k| {
                let r = k as f64 * dr;
                if k == 0 {
                    return Some(0.0);
                }
                let guess = if xp.abs() > 1e-9 {
                    r * (1.0 - rear / xp)
                } else {
                    0.0
                };
                lens.solve_chief(r, guess, wls[1]).or_else(|| {
                    let b = bins[k.min(nb - 1)]?;
                    Some(0.5 * (b.x0_mm + b.x1_mm))
                })
            })
            .collect();
        Ok(ExitPupilTable {
            r_max_mm,
            bins,
            chief_x_mm,
        })
    }

    /// The film-radius interval width (mm) and the bounds per interval (`None` = no ray gets
    /// through).
    pub fn bounds(&self) -> (f64, &[Option<PupilBounds>]) {
        (self.r_max_mm / self.bins.len() as f64, &self.bins)
    }

    /// Rotation (cos φ, sin φ) of a sensor point and its radius.
    #[inline]
    fn polar(p: [f64; 2]) -> (f64, f64, f64) {
        let r = p[0].hypot(p[1]);
        if r > 0.0 {
            (r, p[0] / r, p[1] / r)
        } else {
            (0.0, 1.0, 0.0)
        }
    }

    /// Sample the exit pupil for sensor point `p` (mm) with `u` ∈ [0,1)²: uniform on the box
    /// of its film radius, rotated to its azimuth. `None` beyond the table's film radius or
    /// where the pupil is empty.
    pub fn sample(&self, p: [f64; 2], u: [f64; 2]) -> Option<ExitPupilSample> {
        let (r, c, s) = Self::polar(p);
        let nb = self.bins.len();
        let k = ((r / self.r_max_mm) * nb as f64) as usize;
        let b = (*self.bins.get(k)?)?;
        let x = b.x0_mm + u[0] * (b.x1_mm - b.x0_mm);
        let y = b.y0_mm + u[1] * (b.y1_mm - b.y0_mm);
        Some(ExitPupilSample {
            rear_point_mm: [c * x - s * y, s * x + c * y],
            pdf_per_mm2: 1.0 / b.area_mm2(),
            box_area_mm2: b.area_mm2(),
        })
    }

    /// The rear-plane aim point (mm) of the chief ray from sensor point `p` (interpolated
    /// between the solved interval ends). `None` beyond the table.
    pub fn chief_aim(&self, p: [f64; 2]) -> Option<[f64; 2]> {
        let (r, c, s) = Self::polar(p);
        let nb = self.bins.len();
        let x = r / self.r_max_mm * nb as f64;
        let k = (x as usize).min(nb - 1);
        let t = x - k as f64;
        let a = match (self.chief_x_mm.get(k)?, self.chief_x_mm.get(k + 1)?) {
            (Some(a0), Some(a1)) => a0 * (1.0 - t) + a1 * t,
            (Some(a), None) | (None, Some(a)) => *a,
            (None, None) => return None,
        };
        Some([c * a, s * a])
    }
}

/// Rear-plane grid per side of [`axial_irradiance_per_radiance_sr`].
pub const AXIAL_IRRADIANCE_GRID: usize = 384;

/// [`SensorSideLens::axial_irradiance_per_radiance_sr`] of `lens` as focused (its image plane
/// is the film), with the aperture stop's clear radius set to the paraxial value the aperture
/// implies ([`LensPrescription::with_aperture_stop_clear`], as the real-lens camera does), at
/// each of `wavelengths_nm`.
pub fn axial_irradiance_per_radiance_sr(
    lens: &LensPrescription,
    wavelengths_nm: &[f64],
) -> Result<Vec<f64>, LensError> {
    let side = SensorSideLens::new(&lens.with_aperture_stop_clear()?)?;
    Ok(wavelengths_nm
        .iter()
        .map(|w| side.axial_irradiance_per_radiance_sr(*w, AXIAL_IRRADIANCE_GRID))
        .collect())
}

/// Relative illumination of `lens` as focused (its image plane is the film; the aperture
/// stop's clear radius set as by [`axial_irradiance_per_radiance_sr`]) at each film point
/// `(film radius mm, wavelength nm)` of `points`: [`SensorSideLens::relative_illumination`].
/// Errors for lenses that cannot be traced from the sensor (mirrors), and when no ray from the
/// film centre is found to get through at one of the wavelengths (the ratio is undefined;
/// callers fall back to the entrance-pupil estimate).
pub fn film_relative_illumination(
    lens: &LensPrescription,
    points: &[(f64, f64)],
    grid: usize,
) -> Result<Vec<f64>, LensError> {
    let side = SensorSideLens::new(&lens.with_aperture_stop_clear()?)?;
    side.relative_illumination(points, grid).ok_or_else(|| {
        LensError::Prescription(format!(
            "lens '{}': no ray from the film centre gets through at one of the wavelengths \
             (film-side relative illumination undefined)",
            lens.name
        ))
    })
}

impl SensorSideLens {
    /// Relative illumination at each film point `(film radius mm, wavelength nm)` of `points`:
    /// the film irradiance of a uniform-radiance scene there over that on the axis at the same
    /// wavelength, E(r, λ)/E(0, λ), both by [`SensorSideLens::irradiance_per_radiance_sr`]
    /// with the rear-plane grid `grid` per side (the same quadrature on and off the axis). It
    /// contains what the entrance-pupil estimate [`LensPrescription::relative_illumination`]
    /// (vignetting fraction × cos⁴ of the chief ray) leaves out: the pupil's aberrations and
    /// their change with wavelength, and the cos⁴ of every ray rather than the chief ray's.
    /// `None` when the axial integral is 0 at one of the wavelengths (no ray found).
    pub fn relative_illumination(&self, points: &[(f64, f64)], grid: usize) -> Option<Vec<f64>> {
        let mut wls: Vec<f64> = points.iter().map(|p| p.1).collect();
        wls.sort_by(|a, b| a.total_cmp(b));
        wls.dedup();
        let axial: Vec<f64> = wls
            .par_iter()
            .map(|w| self.irradiance_per_radiance_sr(0.0, *w, grid))
            .collect();
        if axial.iter().any(|e| !(*e > 0.0)) {
            return None;
        }
        Some(
            points
                .par_iter()
                .map(|&(r, w)| {
                    self.irradiance_per_radiance_sr(r.abs(), w, grid)
                        / axial[wls.partition_point(|x| *x < w)]
                })
                .collect(),
        )
    }
}
