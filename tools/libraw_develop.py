#!/usr/bin/env python3
"""Build a DNG from a headerless raw Bayer mosaic with pidng, and develop it with LibRaw
(rawpy) for the comparison in tests/develop_libraw.rs (docs/isp.md).

    python tools/libraw_develop.py RAW ROWS COLS BLACK WHITE CFA CM NEUTRAL OUT_DNG OUT_U16

CM: nine comma-separated XYZ->camera numbers (ColorMatrix1, calibration illuminant D65);
NEUTRAL: three comma-separated numbers (AsShotNeutral). OUT_U16 receives LibRaw's output:
ROWS x COLS x 3 little-endian uint16, linear sRGB (gamma 1, 16 bit), with the DNG's white
balance (use_camera_wb), its ColorMatrix, the bilinear ("LINEAR") demosaic, highlight clip,
no auto-brightening and no maximum adjustment. Run with tools/libraw_setup.sh's venv.
"""
import sys
from fractions import Fraction

import numpy as np
import rawpy
from pidng.core import RAW2DNG, DNGTags, Tag
from pidng.defs import CalibrationIlluminant, CFAPattern, DNGVersion, PhotometricInterpretation


def rational(x, signed=True):
    f = Fraction(x).limit_denominator(10000)
    return [f.numerator, f.denominator]


def main(argv):
    raw, rows, cols, black, white, cfa, cm, neutral, out_dng, out_u16 = argv[1:]
    rows, cols, black, white = int(rows), int(cols), int(black), int(white)
    cm = [float(v) for v in cm.split(",")]
    neutral = [float(v) for v in neutral.split(",")]
    data = np.fromfile(raw, dtype="<u2")
    if data.size != rows * cols:
        sys.exit(f"{raw}: {data.size} samples, expected {rows}x{cols}")
    data = data.reshape(rows, cols)
    t = DNGTags()
    t.set(Tag.ImageWidth, cols)
    t.set(Tag.ImageLength, rows)
    t.set(Tag.TileWidth, cols)
    t.set(Tag.TileLength, rows)
    t.set(Tag.Orientation, 1)
    t.set(Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array)
    t.set(Tag.SamplesPerPixel, 1)
    t.set(Tag.BitsPerSample, 16)
    t.set(Tag.CFARepeatPatternDim, [2, 2])
    t.set(Tag.CFAPattern, getattr(CFAPattern, cfa))
    t.set(Tag.BlackLevel, black)
    t.set(Tag.WhiteLevel, white)
    t.set(Tag.ColorMatrix1, [rational(v) for v in cm])
    t.set(Tag.CalibrationIlluminant1, CalibrationIlluminant.D65)
    t.set(Tag.AsShotNeutral, [rational(v) for v in neutral])
    t.set(Tag.BaselineExposure, [[0, 1]])
    t.set(Tag.Make, "camsim")
    t.set(Tag.Model, "libraw check")
    t.set(Tag.DNGVersion, DNGVersion.V1_4)
    t.set(Tag.DNGBackwardVersion, DNGVersion.V1_2)
    t.set(Tag.PreviewColorSpace, 2)
    w = RAW2DNG()
    w.options(t, path="", compress=False)
    buf = w.convert(data)
    with open(out_dng, "wb") as f:
        f.write(buf)
    with rawpy.imread(out_dng) as r:
        rgb = r.postprocess(
            demosaic_algorithm=rawpy.DemosaicAlgorithm.LINEAR,
            use_camera_wb=True,
            use_auto_wb=False,
            no_auto_bright=True,
            output_color=rawpy.ColorSpace.sRGB,
            gamma=(1, 1),
            output_bps=16,
            user_flip=0,
            highlight_mode=rawpy.HighlightMode.Clip,
            adjust_maximum_thr=0.0,
            half_size=False,
            four_color_rgb=False,
        )
    if rgb.shape != (rows, cols, 3):
        sys.exit(f"LibRaw returned {rgb.shape}, expected {(rows, cols, 3)}")
    rgb.astype("<u2").tofile(out_u16)


if __name__ == "__main__":
    main(sys.argv)
