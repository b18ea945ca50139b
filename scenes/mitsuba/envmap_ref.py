#!/usr/bin/env python3
"""Mitsuba 3 render of a glTF scene lit by an environment map named in the scene's extras
(camsim's convention: extras.camsim_environment_exr, camsim_environment_strength,
camsim_environment_rotation_deg about +y): the shared harness's gltf_to_mitsuba.py, used in
place, with an `envmap` emitter added to the scene it builds.

  envmap_ref.py --harness DIR SCENE.gltf -o OUT.exr [--variant V --spp N --seed S --width W
                --height H --bands LO:HI:STEP --preview PNG]

Orientation: camsim maps a direction d (in the map frame) to u = atan2(d.x, -d.z)/2pi,
v = acos(d.y)/pi, Mitsuba's `envmap` convention, so the emitter's to_world is just the
rotation about +y (docs/render.md).
"""
import argparse
import json
import os
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--harness", required=True, help="folder of gltf_to_mitsuba.py")
    ap.add_argument("gltf")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--variant", default="scalar_spectral")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=None)
    ap.add_argument("--bands", default="400:700:20")
    ap.add_argument("--preview", default=None)
    a = ap.parse_args()
    sys.path.insert(0, a.harness)
    import gltf_to_mitsuba as g2m

    with open(a.gltf) as f:
        doc = json.load(f)
    extras = doc["scenes"][doc.get("scene", 0)].get("extras", {}) or {}
    if "camsim_environment_exr" not in extras:
        sys.exit(f"envmap_ref.py: {a.gltf}: the scene has no extras.camsim_environment_exr")
    exr = os.path.join(os.path.dirname(os.path.abspath(a.gltf)), extras["camsim_environment_exr"])
    strength = float(extras.get("camsim_environment_strength", 1.0))
    rot_deg = float(extras.get("camsim_environment_rotation_deg", 0.0))
    build = g2m.build_scene_dict

    def with_envmap(*args, **kw):
        sd = build(*args, **kw)
        import mitsuba as mi
        sd["environment"] = {"type": "envmap", "filename": exr, "scale": strength,
                             "to_world": mi.ScalarTransform4f().rotate([0.0, 1.0, 0.0], rot_deg)}
        return sd

    g2m.build_scene_dict = with_envmap
    g2m.render(a.gltf, a.out, a.variant, a.spp, a.seed, a.width, a.height, a.bands, -1,
               False, a.preview, None, 16, False)


if __name__ == "__main__":
    main()
