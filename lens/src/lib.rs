//! # camsim-lens
//!
//! A sequential, rotationally symmetric lens-prescription ray tracer with dispersion:
//!
//! * [`prescription`]: the JSON prescription format (below) and the validated
//!   [`LensPrescription`];
//! * [`glass`]: n(λ) from the refractiveindex.info catalogue formulas (Sellmeier etc.) and the
//!   (n_d, V_d) model;
//! * [`paraxial`]: y–nu trace (Smith, "Modern Optical Engineering"): EFL, BFL, FFL, principal
//!   planes, pupils, F/#, working F/#, focusing;
//! * [`trace`]: exact rays in f64 through spheres, conics, even and odd aspheres, vector Snell law,
//!   TIR, vignetting, optical path length, chief-ray aiming at the stop centre;
//! * [`batch`]: the same exact trace for many rays at once (structure of arrays, vectorised,
//!   rayon), used by the analyses and the field model;
//! * [`analysis`]: spot diagrams and RMS radii, distortion, lateral colour, relative
//!   illumination, geometric PSF, FFT wave PSF and MTF;
//! * [`huygens`]: wave-optics PSF by Huygens–Fresnel integration over the reference sphere
//!   (any sample pitch and window);
//! * [`field_curvature`]: sagittal and tangential foci by field (Coddington's equations along
//!   the real chief ray, and independently from traced ray pairs);
//! * [`field_model`]: the ISET-style field model (PSF, distortion, relative illumination over
//!   image height × wavelength × object distance, interpolation, PSF rotation, JSON
//!   save/load);
//! * [`readers`]: Zemax `.zmx`, ISET/pbrt `.dat` and ISET lens JSON readers;
//! * [`agf`]: Zemax `.agf` glass catalogues;
//! * [`fold`]: mirrors and coordinate breaks (decentres, tilts) in sequential tracing,
//!   Zemax conventions, results in unfolded image-space coordinates;
//! * [`focus`]: pupil sampling set by the OPD slope for FFT PSFs and MTFs, and the MTF best
//!   focus;
//! * [`focus_model`]: the focus model every consumer uses: focus distance, criterion (best
//!   polychromatic MTF or paraxial), unit or group motion ([`FocusSpec`] → [`FocusedLens`]).
//!
//! ## Prescription file format (`lenses/*.json`)
//!
//! ```json
//! {
//!   "name": "Double Gauss 50 mm f/2",
//!   "units": "mm",
//!   "surfaces": [
//!     {"radius_mm": 28.10119, "thickness_mm": 4.375,
//!      "material": {"glass": "N-SSK2", "catalog": "schott"}, "semi_diameter_mm": 14.086},
//!     {"radius_mm": null, "thickness_mm": 6.87, "material": "air", "stop": true},
//!     {"radius_mm": -39.7, "thickness_mm": 30.74, "material": {"nd": 1.62, "vd": 53.3},
//!      "conic": -1.0, "aspheric_coeffs": [1e-6, -2e-9]}
//!   ],
//!   "object_distance_mm": null,
//!   "fields_deg": [0, 10, 20],
//!   "wavelengths_nm": [486.1, 587.6, 656.3],
//!   "primary_nm": 587.6,
//!   "aperture": {"epd_mm": 25.0},
//!   "provenance": "where the numbers come from"
//! }
//! ```
//!
//! * Surfaces are listed from the object side, light travels towards +z; `radius_mm` > 0 when
//!   the centre of curvature is on the image side; `null` = flat (0 is rejected).
//! * `thickness_mm` is the axial distance to the next vertex; that of the **last** surface is
//!   the distance to the (flat) image plane.
//! * `material` is the medium *after* the surface: `"air"`, a catalogue glass
//!   `{"glass", "catalog"?}` (looked up in the bundled table `lenses/glass/<catalog>.tsv`, all vendors when
//!   `catalog` is absent), or `{"nd", "vd"}` (two-term Cauchy model, see [`glass`]).
//!   Object space is air; catalogue indices are relative to air.
//! * `semi_diameter_mm` (optional) is the clear semi-aperture, used for vignetting when tracing
//!   with [`trace::Clipping::SemiDiameters`].
//! * `conic` (k, default 0) and `aspheric_coeffs` (A4, A6, …, default none) give the even
//!   asphere sag z = c r²/(1 + √(1 − (1+k)c²r²)) + A4 r⁴ + A6 r⁶ + …; `odd_aspheric_coeffs`
//!   (β1, β2, β3, …, default none) add the Zemax odd-asphere terms β1 r + β2 r² + β3 r³ + …
//!   (`TYPE ODDASPHE` in a `.zmx`).
//! * `"material": "mirror"` makes a surface a mirror (light goes back towards −z, so the
//!   following thicknesses are negative); `"coordinate_breaks": [{"surface": j,
//!   "decenter_y_mm": …, "tilt_x_deg": …}]` makes flat surface j a decentre/tilt of the local
//!   frame (see [`fold`] for the conventions).
//! * Exactly one surface has `"stop": true`.
//! * `object_distance_mm`: distance from the object to the first vertex; `null` = infinity.
//! * `fields_deg`: object-space chief-ray angles; `wavelengths_nm`; `primary_nm` (default the
//!   middle wavelength).
//! * `aperture`: `{"epd_mm": d}` or `{"f_number": N}` (infinite-conjugate EFL/EPD at the primary
//!   wavelength). The optics_ref form `{"type": "EPD", "value_mm": d}` / `{"type": "FNO",
//!   "value": N}` is accepted too, so the optics_ref input files load unchanged.
//! * Unknown keys are ignored.
#![deny(missing_docs)]

pub mod agf;
pub mod analysis;
pub mod batch;
pub mod error;
pub mod field_curvature;
pub mod field_model;
pub mod focus;
pub mod focus_model;
pub mod fold;
pub mod glass;
pub mod huygens;
pub mod paraxial;
pub mod prescription;
pub mod pupil;
pub mod readers;
pub mod trace;

pub use batch::{RayBatch, TraceSystem};
pub use error::LensError;
pub use field_model::{
    geometric_pupil_half_psfs, FieldModel, FieldModelOptions, FieldTable, Focus, PsfKind,
    PupilHalfPsfs,
};
pub use focus_model::{FocusCriterion, FocusMethod, FocusMotion, FocusSpec, FocusedLens};
pub use glass::{Glass, GlassCatalog, NearGlass};
pub use paraxial::FirstOrder;
pub use prescription::{LensPrescription, PrescriptionFile};
pub use trace::{Clipping, Ray, TracedRay};
