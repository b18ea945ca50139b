#!/usr/bin/env python3
"""Combine K independent Mitsuba renders (different seeds) of one scene into a reference EXR
with the mean and the variance of that mean per pixel and band.

  pack_refs.py OUT.exr SEED0.exr SEED1.exr ... [--meta OUT.json --meta-json '{...}']

Output channels (float32, one layer; read by render/tests/mitsuba.rs):
  band_LLLL_HHHH        mean over the K seeds of the band-averaged radiance (W m^-2 sr^-1 nm^-1)
  var.band_LLLL_HHHH    variance of that mean, s^2 / K with s^2 the unbiased sample variance of
                        the K renders (K - 1 degrees of freedom per pixel)
  depth_center.T        Euclidean distance camera centre -> first hit of the pixel-centre ray
                        (deterministic; identical in every seed, checked here), 0 = escaped
  depth.T               box-filtered jittered hit distance, mean over seeds
Needs numpy and mitsuba (only to read/write EXR).
"""
import argparse
import json
import sys

import numpy as np


def read(path):
    import mitsuba as mi
    bmp = mi.Bitmap(path)
    names = [bmp.struct_()[i].name for i in range(bmp.channel_count())]
    return names, np.array(bmp, copy=True).astype(np.float64)


def round_mantissa(x, bits):
    """Round float32 values to `bits` explicit mantissa bits (round half up on the bit pattern)."""
    u = np.ascontiguousarray(x, dtype=np.float32).view(np.uint32)
    drop = 23 - bits
    u = ((u + np.uint32(1 << (drop - 1))) >> np.uint32(drop)) << np.uint32(drop)
    return u.view(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--meta", default=None, help="also write this JSON sidecar")
    ap.add_argument("--meta-json", default="{}", help="extra fields for the sidecar (JSON object)")
    a = ap.parse_args()
    if len(a.inputs) < 2:
        sys.exit("pack_refs.py: need at least 2 seeds for a variance")
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    names0, _ = read(a.inputs[0])
    stacks = []
    for p in a.inputs:
        names, arr = read(p)
        if names != names0:
            sys.exit(f"pack_refs.py: {p} has channels {names}, expected {names0}")
        stacks.append(arr)
    x = np.stack(stacks)  # K, H, W, C
    k = x.shape[0]
    bands = [i for i, n in enumerate(names0) if n.startswith("band_")]
    dc = names0.index("depth_center.T")
    if np.max(np.abs(x[:, :, :, dc] - x[0, :, :, dc])) > 1e-6:
        sys.exit("pack_refs.py: depth_center.T differs between seeds (it must be deterministic)")
    out_names, planes = [], []
    mean = x.mean(axis=0)
    var_of_mean = x.var(axis=0, ddof=1) / k
    for i in bands:
        out_names.append(names0[i])
        planes.append(mean[..., i])
    for i in bands:
        out_names.append("var." + names0[i])
        planes.append(var_of_mean[..., i])
    out_names += ["depth_center.T", "depth.T"]
    planes += [x[0, :, :, dc], mean[..., names0.index("depth.T")]]
    data = np.ascontiguousarray(np.stack(planes, axis=-1).astype(np.float32))
    # Keep 14 mantissa bits of the means (relative precision 6e-5, far below the noise) and
    # 10 of the variances: the zeroed low bits make the EXR compress about twice as well.
    nb = len(bands)
    data[..., :nb] = round_mantissa(data[..., :nb], 14)
    data[..., nb:2 * nb] = round_mantissa(data[..., nb:2 * nb], 10)
    mi.Bitmap(data, mi.Bitmap.PixelFormat.MultiChannel, out_names).write(a.out)
    if a.meta:
        meta = json.loads(a.meta_json)
        h, w = data.shape[:2]
        band_means = {names0[i]: float(mean[..., i].mean()) for i in bands}
        meta.update(seeds=k, width=int(w), height=int(h), band_means=band_means,
                    mean_rel_noise=float(np.mean([np.sqrt(var_of_mean[..., i].mean()) /
                                                  max(mean[..., i].mean(), 1e-30) for i in bands])))
        with open(a.meta, "w") as f:
            json.dump(meta, f, indent=1)
            f.write("\n")
    print(f"wrote {a.out}: {len(bands)} bands, {k} seeds")


if __name__ == "__main__":
    main()
