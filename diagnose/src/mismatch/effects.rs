//! The effect ids of spec/effects.md: names, units, plain-words physics, and the pairs of
//! effects that look alike (with the evidence that separates them).

/// One effect id of effects.md.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// `exposure_scale`
    ExposureScale,
    /// `conversion_gain`
    ConversionGain,
    /// `black_level`
    BlackLevel,
    /// `dark_current`
    DarkCurrent,
    /// `read_noise`
    ReadNoise,
    /// `dsnu`
    Dsnu,
    /// `prnu`
    Prnu,
    /// `column_fpn`
    ColumnFpn,
    /// `hot_pixels`
    HotPixels,
    /// `nonlinearity`
    Nonlinearity,
    /// `full_well`
    FullWell,
    /// `relative_illumination`
    RelativeIllumination,
    /// `veiling_glare`
    VeilingGlare,
    /// `defocus`
    Defocus,
    /// `crosstalk`
    Crosstalk,
    /// `ir_leakage`
    IrLeakage,
    /// `qe_shift`
    QeShift,
    /// `distortion`
    Distortion,
    /// `lateral_color`
    LateralColor,
    /// `row_noise`
    RowNoise,
    /// `rtn`
    Rtn,
    /// `black_level_drift`
    BlackLevelDrift,
    /// `dark_temperature`
    DarkTemperature,
}

impl Effect {
    /// Every effect, in the order of effects.md.
    pub const ALL: [Effect; 23] = [
        Effect::ExposureScale,
        Effect::ConversionGain,
        Effect::BlackLevel,
        Effect::DarkCurrent,
        Effect::ReadNoise,
        Effect::Dsnu,
        Effect::Prnu,
        Effect::ColumnFpn,
        Effect::HotPixels,
        Effect::Nonlinearity,
        Effect::FullWell,
        Effect::RelativeIllumination,
        Effect::VeilingGlare,
        Effect::Defocus,
        Effect::Crosstalk,
        Effect::IrLeakage,
        Effect::QeShift,
        Effect::Distortion,
        Effect::LateralColor,
        Effect::RowNoise,
        Effect::Rtn,
        Effect::BlackLevelDrift,
        Effect::DarkTemperature,
    ];

    /// The id of effects.md.
    pub fn id(self) -> &'static str {
        match self {
            Effect::ExposureScale => "exposure_scale",
            Effect::ConversionGain => "conversion_gain",
            Effect::BlackLevel => "black_level",
            Effect::DarkCurrent => "dark_current",
            Effect::ReadNoise => "read_noise",
            Effect::Dsnu => "dsnu",
            Effect::Prnu => "prnu",
            Effect::ColumnFpn => "column_fpn",
            Effect::HotPixels => "hot_pixels",
            Effect::Nonlinearity => "nonlinearity",
            Effect::FullWell => "full_well",
            Effect::RelativeIllumination => "relative_illumination",
            Effect::VeilingGlare => "veiling_glare",
            Effect::Defocus => "defocus",
            Effect::Crosstalk => "crosstalk",
            Effect::IrLeakage => "ir_leakage",
            Effect::QeShift => "qe_shift",
            Effect::Distortion => "distortion",
            Effect::LateralColor => "lateral_color",
            Effect::RowNoise => "row_noise",
            Effect::Rtn => "rtn",
            Effect::BlackLevelDrift => "black_level_drift",
            Effect::DarkTemperature => "dark_temperature",
        }
    }

    /// Parse an id.
    pub fn from_id(id: &str) -> Option<Effect> {
        Effect::ALL.iter().copied().find(|e| e.id() == id)
    }

    /// Unit of the magnitude (effects.md).
    pub fn unit(self) -> &'static str {
        match self {
            Effect::ExposureScale | Effect::ConversionGain => "ratio",
            Effect::BlackLevel => "DN",
            Effect::DarkCurrent => "V/s",
            Effect::ReadNoise | Effect::Dsnu | Effect::ColumnFpn => "V",
            Effect::Prnu => "%",
            Effect::HotPixels => "fraction of pixels",
            Effect::Nonlinearity => "fraction",
            Effect::FullWell => "e-",
            Effect::RelativeIllumination => "fraction at h = 1",
            Effect::VeilingGlare => "fraction of mean irradiance",
            Effect::Defocus => "um",
            Effect::Crosstalk => "fraction",
            Effect::IrLeakage => "electrons/photon",
            Effect::QeShift => "nm",
            Effect::Distortion => "fraction of half-diagonal",
            Effect::LateralColor => "um",
            Effect::RowNoise => "V",
            Effect::Rtn => "fraction of pixels",
            Effect::BlackLevelDrift => "DN over the capture set",
            Effect::DarkTemperature => "degC (doubling temperature)",
        }
    }

    /// The physics left out, in plain words (effects.md).
    pub fn physics(self) -> &'static str {
        match self {
            Effect::ExposureScale => "the light reaching the sensor is a constant factor off (luminance, shutter time, aperture or lens transmittance)",
            Effect::ConversionGain => "the electrons-to-volts conversion gain is off: the mean and the photon-transfer slope change together",
            Effect::BlackLevel => "the constant DN pedestal differs",
            Effect::DarkCurrent => "the dark signal grows with exposure at another rate",
            Effect::ReadNoise => "the temporal noise floor differs",
            Effect::Dsnu => "fixed per-pixel offsets (dark signal non-uniformity)",
            Effect::Prnu => "fixed per-pixel gain differences (photo-response non-uniformity)",
            Effect::ColumnFpn => "fixed offsets shared by whole columns (column amplifiers)",
            Effect::HotPixels => "isolated pixels with dark current far above the rest",
            Effect::Nonlinearity => "the response compresses as the pixel fills",
            Effect::FullWell => "the pixels saturate at another charge",
            Effect::RelativeIllumination => "the irradiance falls off towards the corners differently from the model (vignetting, pupil aberration)",
            Effect::VeilingGlare => "stray light adds, evenly over the sensor, a fraction of the whole image's light",
            Effect::Defocus => "extra blur (focus error, aberrations)",
            Effect::Crosstalk => "photo-charge leaks into the 4 nearest neighbours",
            Effect::IrLeakage => "the IR-cut filter passes light beyond 700 nm that the channel curves omit",
            Effect::QeShift => "a channel's spectral sensitivity sits at other wavelengths",
            Effect::Distortion => "geometric distortion not in the model",
            Effect::LateralColor => "the magnification differs with wavelength (lateral chromatic aberration)",
            Effect::RowNoise => "every row gets a new offset each frame (row-wise temporal noise of the readout)",
            Effect::Rtn => "some pixels switch between two levels from frame to frame (random telegraph noise of a trap)",
            Effect::BlackLevelDrift => "the pedestal drifts with the frame order (capture time)",
            Effect::DarkTemperature => "the dark current changes with the sensor temperature (it doubles every few degrees)",
        }
    }
}

/// A pair of effects that can explain the same residuals, and what in a capture set tells
/// them apart.
#[derive(Debug, Clone, Copy)]
pub struct AlikePair {
    /// One effect.
    pub a: Effect,
    /// The other.
    pub b: Effect,
    /// The evidence that separates them.
    pub separated_by: &'static str,
}

/// The pairs the issue names, and a few more.
pub const ALIKE: &[AlikePair] = &[
    AlikePair {
        a: Effect::ExposureScale,
        b: Effect::ConversionGain,
        separated_by: "the photon-transfer slope (temporal variance against mean signal from repeated frames): a gain error changes it, an exposure error does not",
    },
    AlikePair {
        a: Effect::BlackLevel,
        b: Effect::DarkCurrent,
        separated_by: "dark shots at two or more exposure times: dark current grows with exposure, a pedestal does not",
    },
    AlikePair {
        a: Effect::Dsnu,
        b: Effect::BlackLevel,
        separated_by: "the spread between pixels of the frame-averaged dark image (DSNU) against its mean (pedestal)",
    },
    AlikePair {
        a: Effect::Dsnu,
        b: Effect::DarkCurrent,
        separated_by: "dark shots at several exposure times and several frames per shot",
    },
    AlikePair {
        a: Effect::Dsnu,
        b: Effect::ReadNoise,
        separated_by: "two or more frames per shot: read noise changes from frame to frame, DSNU does not",
    },
    AlikePair {
        a: Effect::Dsnu,
        b: Effect::ColumnFpn,
        separated_by: "enough rows to see whether the offsets are shared along columns",
    },
    AlikePair {
        a: Effect::Prnu,
        b: Effect::ConversionGain,
        separated_by: "repeated frames (shot noise is temporal, PRNU is fixed) or flats at several signal levels (PRNU variance grows with the signal squared, shot noise linearly)",
    },
    AlikePair {
        a: Effect::RelativeIllumination,
        b: Effect::ExposureScale,
        separated_by: "a uniform flat-field shot covering the corners",
    },
    AlikePair {
        a: Effect::VeilingGlare,
        b: Effect::ExposureScale,
        separated_by: "a target with dark and light regions: glare adds the same light to both, an exposure error scales them",
    },
    AlikePair {
        a: Effect::VeilingGlare,
        b: Effect::BlackLevel,
        separated_by: "dark shots and shots of different brightness: glare scales with the light, a pedestal does not",
    },
    AlikePair {
        a: Effect::Crosstalk,
        b: Effect::QeShift,
        separated_by: "shots under several illuminants or narrowband light: crosstalk mixes neighbouring channels, a QE error changes one channel's spectrum",
    },
    AlikePair {
        a: Effect::Crosstalk,
        b: Effect::IrLeakage,
        separated_by: "shots with and without light beyond 700 nm",
    },
    AlikePair {
        a: Effect::QeShift,
        b: Effect::IrLeakage,
        separated_by: "shots with and without light beyond 700 nm, or narrowband shots",
    },
    AlikePair {
        a: Effect::Crosstalk,
        b: Effect::Defocus,
        separated_by: "an edge target seen in one channel at a time, or flats (crosstalk mixes channels on a flat, blur does not)",
    },
    AlikePair {
        a: Effect::Nonlinearity,
        b: Effect::FullWell,
        separated_by: "exposure series that approach saturation slowly: compression bends the curve before it flattens",
    },
    AlikePair {
        a: Effect::Distortion,
        b: Effect::LateralColor,
        separated_by: "structure seen in more than one channel: lateral colour moves the channels apart, distortion moves them together",
    },
    AlikePair {
        a: Effect::RowNoise,
        b: Effect::ReadNoise,
        separated_by: "the variance of row means across frames: row noise moves whole rows together, read noise averages out over a row",
    },
    AlikePair {
        a: Effect::Rtn,
        b: Effect::HotPixels,
        separated_by: "darks at several exposure times: a hot pixel's excess grows with exposure, an RTN pixel's frame-to-frame jumps do not",
    },
    AlikePair {
        a: Effect::BlackLevelDrift,
        b: Effect::BlackLevel,
        separated_by: "several frames per shot in capture order: a drift moves the frame means along the frame index",
    },
    AlikePair {
        a: Effect::DarkTemperature,
        b: Effect::DarkCurrent,
        separated_by: "darks at two or more sensor temperatures (captures with temperature_c)",
    },
    AlikePair {
        a: Effect::ExposureScale,
        b: Effect::QeShift,
        separated_by: "shots under more than one illuminant, or all channels changing by the same factor",
    },
];

/// The alike pair of `a` and `b`, if they are one.
pub fn alike(a: Effect, b: Effect) -> Option<&'static AlikePair> {
    ALIKE
        .iter()
        .find(|p| (p.a == a && p.b == b) || (p.a == b && p.b == a))
}
