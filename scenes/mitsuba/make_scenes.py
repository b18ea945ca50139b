#!/usr/bin/env python3
"""Write the glTF scenes of camsim's Mitsuba 3 reference set (scenes/mitsuba/*.gltf).

Every scene follows the conventions of the shared harness (<shared>/tools/mitsuba_ref/README.md):
metres, spectral extras (`spectral_reflectance`, `spectral_emission` in W m^-2 sr^-1 nm^-1),
one-sided area emitters (front = CCW face), flat faces only (per-face normals, so shading and
geometric normals agree and no renderer-specific normal interpolation enters the comparison).
The glTF writer, the box mesh and the Cornell spectra are imported from the harness's
make_cornell_gltf.py (called in place, not copied), so both renderers read identical files.

  thinlens  objects at 1.2 m, 2.5 m and 5 m in front of a thin-lens camera
            (extras.thinlens: aperture radius 30 mm, focus distance 2.5 m)
  metal     Cornell-like room with two rough conductors: gold (GGX alpha 0.15, eta/k of the
            Rakic 1998 Lorentz-Drude model given explicitly in extras.mitsuba_bsdf) and a
            spectral-reflectance conductor (material "none", GGX alpha 0.3)
  glass     Cornell-like room with a rough dielectric box (ior 1.5, GGX alpha 0.09 from
            roughnessFactor 0.3) in front of a white box

usage: make_scenes.py [--out DIR] [--shared DIR]
"""
import argparse
import math
import os
import sys

import numpy as np


def harness(shared):
    path = os.path.join(shared, "tools", "mitsuba_ref")
    if not os.path.isfile(os.path.join(path, "make_cornell_gltf.py")):
        sys.exit(f"make_scenes.py: harness not found in {path} (pass --shared or set CAMSIM_SHARED)")
    sys.path.insert(0, path)
    import make_cornell_gltf as mc
    return mc


# Lorentz-Drude parameters of gold, Rakic, Djurisic, Elazar & Majewski, Applied Optics 37(22),
# 5271 (1998), Table 1: plasma energy (eV), (f0, Gamma0), then (f_j, Gamma_j, omega_j) in eV.
RAKIC_AU = (9.03, (0.760, 0.053), [(0.024, 0.241, 0.415), (0.010, 0.345, 0.830), (0.071, 0.870, 2.969),
                                     (0.601, 2.494, 4.304), (4.384, 2.214, 13.32)])


def ld_index(params, wl_nm):
    """eta, k = sqrt(eps) of the Lorentz-Drude model
    eps(w) = 1 - f0 wp^2 / (w (w + i G0)) + sum_j f_j wp^2 / ((w_j^2 - w^2) - i w G_j), w = hc/lambda."""
    wp, (f0, g0), osc = params
    w = 1239.841984 / np.asarray(wl_nm, float)
    eps = 1.0 - f0 * wp * wp / (w * (w + 1j * g0))
    for f, gam, wj in osc:
        eps = eps + f * wp * wp / ((wj * wj - w * w) - 1j * w * gam)
    s = np.sqrt(eps)
    return s.real, np.abs(s.imag)


def room(mc, g, light_half_m, wall_mats):
    """Cornell-like room x in [-1,1], y in [0,2], z in [-1,1] (open towards +z) with a square
    light of half-size `light_half_m` 2 cm below the ceiling facing down."""
    m_white, m_red, m_green, m_light = wall_mats
    h = light_half_m
    walls = {
        "floor": (mc.quad([-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1]), m_white),
        "ceiling": (mc.quad([-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]), m_white),
        "back": (mc.quad([-1, 0, -1], [1, 0, -1], [1, 2, -1], [-1, 2, -1]), m_white),
        "left_red": (mc.quad([-1, 0, -1], [-1, 2, -1], [-1, 2, 1], [-1, 0, 1]), m_red),
        "right_green": (mc.quad([1, 0, -1], [1, 0, 1], [1, 2, 1], [1, 2, -1]), m_green),
        "light": (mc.quad([-h, 1.98, -h], [h, 1.98, -h], [h, 1.98, h], [-h, 1.98, h]), m_light),
    }
    for name, ((p, n, i), m) in walls.items():
        g.node(name, mesh=g.mesh(name, p, n, i, m))


def cornell_materials(mc, g):
    white, red, green, emis = mc.spectra()
    return (g.material("white", mc.reflectance_to_rgb(white), white),
            g.material("red", mc.reflectance_to_rgb(red), red),
            g.material("green", mc.reflectance_to_rgb(green), green),
            g.material("light", [0.0, 0.0, 0.0], None, emission=emis, emission_rgb=mc.emission_to_rgb(emis)))


def camera(mc, g, translation, thinlens=None):
    cam = g.camera("camera", math.radians(40.0), 1.0, znear=0.01)
    g.node("camera", camera=cam, translation=translation)
    if thinlens:
        g.doc["cameras"][cam]["extras"] = {"thinlens": thinlens}


def build_metal(mc, out_dir):
    g = mc.GltfBuilder()
    mats = cornell_materials(mc, g)
    room(mc, g, 0.25, mats)
    # Gold, GGX alpha 0.15, with its complex index eta + i k written out as spectra (the
    # Lorentz-Drude model of Rakic et al. 1998, the data behind camsim's named metal "Au"), so
    # both renderers use the same optical constants: Mitsuba's own "Au" preset is a different
    # measurement (normal-incidence reflectance up to 12 % higher at 550 nm).
    # metallicFactor/roughnessFactor (alpha = roughness^2) are the plain-glTF fallback.
    gold = g.material("gold", [1.0, 0.78, 0.34], None)
    m = g.doc["materials"][gold]
    m["pbrMetallicRoughness"].update(metallicFactor=1.0, roughnessFactor=math.sqrt(0.15))
    wl_au = np.arange(360.0, 830.0 + 1e-9, 5.0)
    eta, k = ld_index(RAKIC_AU, wl_au)
    m["extras"]["mitsuba_bsdf"] = {
        "type": "roughconductor", "alpha": 0.15, "distribution": "ggx",
        "eta": {"type": "spectrum", "value": [[float(w), round(float(v), 6)] for w, v in zip(wl_au, eta)]},
        "k": {"type": "spectrum", "value": [[float(w), round(float(v), 6)] for w, v in zip(wl_au, k)]},
    }
    m["extras"]["metal"] = "Au (Rakic et al. 1998 Lorentz-Drude)"
    # Conductor given by its spectral specular reflectance (Mitsuba material "none" = R 1
    # times specular_reflectance), a copper-like rising curve, GGX alpha 0.3.
    wl = mc.WL
    copper = 0.25 + 0.65 * mc.sigmoid((wl - 580.0) / 25.0)
    cu = g.material("copper_like", mc.reflectance_to_rgb(copper), copper)
    g.doc["materials"][cu]["pbrMetallicRoughness"].update(metallicFactor=1.0,
                                                          roughnessFactor=math.sqrt(0.3))
    cp, cn, ci = mc.unit_cube()
    g.node("gold_box", mesh=g.mesh("gold_box", cp, cn, ci, gold), translation=[0.35, 0.3, 0.3],
           rotation=mc.quat_from_euler_deg(-30.0, 0, 0), scale=[0.6, 0.6, 0.6])
    g.node("copper_box", mesh=g.mesh("copper_box", cp, cn, ci, cu), translation=[-0.35, 0.6, -0.3],
           rotation=mc.quat_from_euler_deg(25.0, 0, 0), scale=[0.6, 1.2, 0.6])
    camera(mc, g, [0.0, 1.0, 3.9])
    path = os.path.join(out_dir, "metal.gltf")
    g.write(path)
    return path


def build_glass(mc, out_dir):
    g = mc.GltfBuilder()
    mats = cornell_materials(mc, g)
    room(mc, g, 0.4, mats)  # larger light: less caustic noise through the glass
    glass = g.material("rough_glass", [1.0, 1.0, 1.0], None)
    m = g.doc["materials"][glass]
    m["pbrMetallicRoughness"].update(metallicFactor=0.0, roughnessFactor=0.3)
    m["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                       "KHR_materials_ior": {"ior": 1.5}}
    g.doc["extensionsUsed"] = sorted(set(g.doc["extensionsUsed"]) |
                                     {"KHR_materials_transmission", "KHR_materials_ior"})
    cp, cn, ci = mc.unit_cube()
    g.node("glass_box", mesh=g.mesh("glass_box", cp, cn, ci, glass), translation=[0.25, 0.352, 0.35],  # 2 mm above the floor: no coplanar faces
           rotation=mc.quat_from_euler_deg(-25.0, 0, 0), scale=[0.7, 0.7, 0.7])
    g.node("white_box", mesh=g.mesh("white_box", cp, cn, ci, mats[0]), translation=[-0.4, 0.6, -0.4],
           rotation=mc.quat_from_euler_deg(18.0, 0, 0), scale=[0.5, 1.2, 0.5])
    camera(mc, g, [0.0, 1.0, 3.9])
    path = os.path.join(out_dir, "glass.gltf")
    g.write(path)
    return path


def build_thinlens(mc, out_dir):
    """Floor and back wall, a large overhead light, and three boxes at 1.2, 2.5 and 5 m from
    the camera (at the origin, 0.5 m above the floor, looking down -z). Focus at 2.5 m."""
    white, red, green, emis = mc.spectra()
    g = mc.GltfBuilder()
    m_white = g.material("white", mc.reflectance_to_rgb(white), white)
    m_red = g.material("red", mc.reflectance_to_rgb(red), red)
    m_green = g.material("green", mc.reflectance_to_rgb(green), green)
    m_light = g.material("light", [0.0, 0.0, 0.0], None, emission=emis * 0.5,
                         emission_rgb=mc.emission_to_rgb(emis * 0.5))
    y0 = -0.5
    parts = {
        "floor": (mc.quad([-3, y0, -7], [-3, y0, 1], [3, y0, 1], [3, y0, -7]), m_white),
        "back": (mc.quad([-3, y0, -7], [3, y0, -7], [3, 3, -7], [-3, 3, -7]), m_white),
        "light": (mc.quad([-1.5, 2.5, -5], [1.5, 2.5, -5], [1.5, 2.5, -1], [-1.5, 2.5, -1]), m_light),
    }
    for name, ((p, n, i), m) in parts.items():
        g.node(name, mesh=g.mesh(name, p, n, i, m))
    cp, cn, ci = mc.unit_cube()
    for name, mat, pos, s, yaw in (("near_red", m_red, [-0.25, y0 + 0.15, -1.2], 0.3, 30.0),
                                   ("mid_white", m_white, [0.1, y0 + 0.3, -2.5], 0.6, -20.0),
                                   ("far_green", m_green, [0.9, y0 + 0.6, -5.0], 1.2, 40.0)):
        g.node(name, mesh=g.mesh(name, cp, cn, ci, mat), translation=pos,
               rotation=mc.quat_from_euler_deg(yaw, 0, 0), scale=[s, s, s])
    camera(mc, g, [0.0, 0.0, 0.0], thinlens={"aperture_radius": 0.03, "focus_distance": 2.5})
    path = os.path.join(out_dir, "thinlens.gltf")
    g.write(path)
    return path


BUILDERS = {"thinlens": build_thinlens, "metal": build_metal, "glass": build_glass}

if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    default_shared = os.environ.get("CAMSIM_SHARED") or os.path.join(here, "..", "..", "..", "shared")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=here)
    ap.add_argument("--shared", default=default_shared)
    ap.add_argument("scenes", nargs="*", default=list(BUILDERS))
    a = ap.parse_args()
    mc = harness(a.shared)
    np.seterr(all="raise")
    for s in a.scenes:
        if s not in BUILDERS:
            sys.exit(f"make_scenes.py: unknown scene '{s}' (expected one of {list(BUILDERS)})")
        print("wrote", BUILDERS[s](mc, a.out))
