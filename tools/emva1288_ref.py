#!/usr/bin/env python3
"""Drive the EMVA 1288 reference implementation `emva1288` (PyPI 1.0.2, installed by
tools/emva1288_setup.sh) for camsim's cross-checks and benchmark.

  emva1288_ref.py analyse DESCRIPTOR            -> JSON {"seconds": .., "values": {name: value}}
  emva1288_ref.py simulate OUTDIR [options]     -> the peer's own simulated series
                                                   (OUTDIR/EMVA1288descriptor.txt + images)
                                                   and OUTDIR/truth.json (its input parameters
                                                   as EMVA 1288 would report them)

Run with the venv's python: .venv-emva1288/bin/python tools/emva1288_ref.py ...
"""
import argparse
import json
import logging
import math
import os
import sys
import time
import warnings

warnings.simplefilter("ignore")


def analyse(descriptor):
    from emva1288.process.parser import ParseEmvaDescriptorFile
    from emva1288.process.loader import LoadImageData
    from emva1288.process.data import Data1288
    from emva1288.process.results import Results1288

    t0 = time.perf_counter()
    parser = ParseEmvaDescriptorFile(descriptor, loglevel=logging.ERROR)
    loader = LoadImageData(parser.images, loglevel=logging.ERROR)
    data = Data1288(loader.data, loglevel=logging.ERROR)
    res = Results1288(data.data, loglevel=logging.ERROR)
    own = scalars(res)
    seconds = time.perf_counter() - t0
    # The same data with the saturation point forced to the standard's definition, the
    # maximum of the temporal variance (Results1288's own search walks down from the
    # brightest point and stops at the first local maximum, which on a noisy saturated
    # plateau is not the variance maximum).
    import numpy as np
    sat = int(np.argmax(data.data["temporal"]["s2_y"]))
    std = scalars(Results1288(data.data, index_u_ysat=sat, loglevel=logging.ERROR))
    return {"seconds": seconds, "values": own, "values_standard_saturation": std,
            "s2_y": [float(v) for v in data.data["temporal"]["s2_y"]]}


def scalars(res):
    """Every scalar of the datasheet (the report's values) of a Results1288."""
    values = {}
    for name, info in res.results.items():
        v = info.get("value")
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            values[name] = None if math.isnan(float(v)) else float(v)
    values["index_u_ysat"] = float(res.index_u_ysat)
    return values


def simulate(a):
    import numpy as np
    from emva1288.camera.dataset_generator import DatasetGenerator
    from emva1288.camera import routines

    rng = np.random.default_rng(a.seed)
    shape = (a.height, a.width)
    dsnu = rng.normal(0.0, a.dsnu_e, shape) if a.dsnu_e > 0 else np.zeros(shape)
    prnu = 1.0 + rng.normal(0.0, a.prnu_percent / 100.0, shape)
    qe = routines.Qe(qe=np.full((a.height, a.width, 1), a.qe), wavelength=np.array([a.wavelength_nm]),
                     width=a.width, height=a.height)
    os.makedirs(a.outdir, exist_ok=True)
    gen = DatasetGenerator(steps=a.steps, L=a.L, outdir=a.outdir, width=a.width, height=a.height,
                           bit_depth=a.bits, K=a.K, qe=qe, u_esat=a.u_esat,
                           dark_current_ref=a.dark_current, temperature=30, temperature_ref=30,
                           dark_signal_0=a.dark_signal_e, sigma2_dark_0=a.sigma2_dark_e2,
                           blackoffset=a.blackoffset, dsnu=dsnu, prnu=prnu,
                           exposure_min=a.exposure_min_ns, exposure_max=a.exposure_max_ns,
                           seed=a.seed)
    k = float(gen.cam.K)
    # The simulator dithers by U(-1/2, 1/2) DN before rounding: 1/12 DN² more than the
    # standard's quantisation term, i.e. 1/(12 K²) e⁻² of apparent dark noise.
    truth = {
        "K": k,
        "QE": 100.0 * a.qe,
        "sigma_d": math.sqrt(a.sigma2_dark_e2 + 1.0 / (12.0 * k * k)),
        "u_e_sat": a.u_esat,
        "u_I_mean": a.dark_current,
        "u_I_var": a.dark_current,
        "DSNU1288": float(np.std(dsnu, ddof=1)),
        "PRNU1288": float(100.0 * np.std(prnu, ddof=1)),
        "descriptor": gen.descriptor_path,
    }
    with open(os.path.join(a.outdir, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)
    return truth


def main():
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    an = sub.add_parser("analyse")
    an.add_argument("descriptor")
    si = sub.add_parser("simulate")
    si.add_argument("outdir")
    si.add_argument("--seed", type=int, default=1)
    si.add_argument("--width", type=int, default=64)
    si.add_argument("--height", type=int, default=48)
    si.add_argument("--steps", type=int, default=60)
    si.add_argument("--L", type=int, default=8)
    si.add_argument("--bits", type=int, default=12)
    si.add_argument("--K", type=float, default=0.2)
    si.add_argument("--qe", type=float, default=0.5)
    si.add_argument("--wavelength-nm", type=float, default=550.0)
    si.add_argument("--u-esat", type=float, default=15000.0)
    si.add_argument("--dark-current", type=float, default=3000.0)
    si.add_argument("--dark-signal-e", type=float, default=60.0)  # no clipping at 0 e⁻
    si.add_argument("--sigma2-dark-e2", type=float, default=30.0)
    si.add_argument("--blackoffset", type=float, default=50.0)
    si.add_argument("--dsnu-e", type=float, default=5.0)
    si.add_argument("--prnu-percent", type=float, default=1.0)
    si.add_argument("--exposure-min-ns", type=float, default=500000.0)
    si.add_argument("--exposure-max-ns", type=float, default=20000000.0)
    a = p.parse_args()
    if a.cmd == "analyse":
        out = analyse(a.descriptor)
    else:
        out = simulate(a)
    json.dump(out, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
