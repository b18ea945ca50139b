#!/usr/bin/env python3
"""Reference numbers that shared/tools/optics_ref/ref_lens.py does not produce, computed with the
same packages (Optiland, rayoptics) through their public APIs. ref_lens.py is imported in place
(not copied) for its prescription reader and lens builders. Run by tools/optics_ref_run.sh.

  optics_ref_extra.py field_curvature INPUT.json -o OUT.json
      Sagittal / tangential focus shifts from the paraxial image plane (object at infinity, image
      plane at the paraxial focus of the primary wavelength, as ref_lens.py) on 11 fields from 0
      to the largest of fields_deg, per wavelength:
        * optiland: optiland.analysis.FieldCurvature (parabasal ray pairs, Δp = 1e-5);
        * rayoptics: rayoptics.raytr.trace.trace_astigmatism_coddington_fan (Coddington along the
          chief ray, spherical surfaces only) and trace_astigmatism (ray pairs, Δp = 1e-3).

  optics_ref_extra.py finite INPUT.json -o OUT.json
      A finite-conjugate lens (INPUT has "object_distance_mm" and "object_heights_mm"; the glass
      of a monochromatic lens may be given as {"n": value}): first-order data (EFL, paraxial
      image distance, magnification), real chief-ray image heights (chief ray aimed at the stop
      centre) on the paraxial image plane and RMS spot radii there (33 x 33 grid clipped to the
      unit disc), from optiland (object-height fields, EPD aperture; spots with paraxial aiming,
      which samples the paraxial entrance pupil like camsim on axis) and rayoptics (object-height
      fields, EPD; aim point shifts the grid off axis, as camsim).
  optics_ref_extra.py asphere INPUT.json -o OUT.json [ref_lens.py arguments]
      ref_lens.py itself (same analyses, same output schema) for a lens with conic / even-asphere
      surfaces: INPUT's surfaces may carry "conic" and "aspheric_coeffs" ([A4, A6, ...], sag
      z = c r^2 / (1 + sqrt(1 - (1+k) c^2 r^2)) + A4 r^4 + A6 r^6 + ..., the camsim/Zemax
      EVENASPH convention), which ref_lens.py ignores. optiland's Optic is wrapped so that those
      surfaces are built as optiland "even_asphere" surfaces (coefficients [0, A4, A6, ...]: its
      list starts at r^2); optiland backend only (rayoptics is not patched). The output gains
      an "aspheres" entry listing what was applied.

  optics_ref_extra.py patched INPUT.json -o OUT.json [ref_lens.py arguments]
      ref_lens.py itself, both backends, with even aspheres built in optiland AND rayoptics, and
      the glasses listed in INPUT's "rayoptics_glass_from_optiland" (absent from opticalglass,
      where rayoptics would silently build air) given to rayoptics as optiland's material of
      that name; odd aspheres ("odd_aspheric_coeffs") in both; with "model_glass": "cauchy",
      camsim's (nd, Vd) Cauchy model glass in both. The output gains a "patches" entry listing
      what was applied.

  optics_ref_extra.py mtf INPUT.json -o OUT.json [--opd-grid 512] [--optiland-aiming paraxial]
      (an INPUT with "ref_lens_runner": "patched" gets the patches of `patched` first)
      On-axis diffraction MTF at the primary wavelength of a strongly aberrated lens from
      optiland's OPD map on an n x n pupil grid (default 512, fine enough for ~20 waves p-v),
      through ref_lens.py's mtf_from_opd, at three image planes: the paraxial focus, the RMS
      best focus (ref_lens.py's poly-RMS minimum on axis) and the MTF best focus (the shift
      maximising the mean over INPUT's "merit_freqs_lpmm" of (T+S)/2, scanned at 24 steps over
      the interval from the paraxial plane to the RMS best focus widened by 8 lambda N_w^2 on
      each side, then golden-section refined to 1e-4 of it; camsim_lens::focus does the same).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import warnings

import numpy as np

warnings.filterwarnings("ignore")
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "shared", "tools", "optics_ref"))
import ref_lens as R  # noqa: E402  (shared harness, called in place)


def version(pkg):
    from importlib.metadata import version as v
    return v(pkg)


# ----------------------------------------------------------------------------------------------
# field curvature
# ----------------------------------------------------------------------------------------------
def field_curvature(lens, n_points=11):
    out = {}
    fmax = max(lens["fields_deg"])
    fields = [fmax * k / (n_points - 1) for k in range(n_points)]
    # optiland
    from optiland.analysis import FieldCurvature
    ob = R.OptilandBackend(lens)
    fc = FieldCurvature(ob.op, wavelengths="all", num_points=n_points)
    out["optiland"] = {
        "version": version("optiland"),
        "method": "optiland.analysis.FieldCurvature (parabasal ray pairs)",
        "field_deg": [float(f) for f in np.linspace(0, 1, n_points) * ob.op.fields.max_field],
        "wavelengths_nm": [w["value"] if isinstance(w, dict) else float(w.value) * 1000.0
                           for w in fc.wavelengths],
        "tangential_mm": [[float(x) for x in np.asarray(d[0]).ravel()] for d in fc.data],
        "sagittal_mm": [[float(x) for x in np.asarray(d[1]).ravel()] for d in fc.data],
    }
    # rayoptics
    try:
        from rayoptics.raytr import trace as rt
        from rayoptics.raytr.opticalspec import Field
        rb = R.RayopticsBackend(lens)
        opm = rb.opm
        fov = opm["optical_spec"]["fov"]
        res = {"coddington": {"tangential_mm": [], "sagittal_mm": []},
               "ray_pairs": {"tangential_mm": [], "sagittal_mm": []}}
        for w in lens["wavelengths_nm"]:
            for key in res:
                res[key]["tangential_mm"].append([])
                res[key]["sagittal_mm"].append([])
            for f in fields:
                fld = Field(fov=fov)
                fld.y = f / fov.value if fov.is_relative else f
                fld.aim_info = rt.aim_chief_ray(opm, fld, lens["primary_nm"])
                s, t = rt.trace_astigmatism_coddington_fan(opm, fld, w, 0.0)
                res["coddington"]["sagittal_mm"][-1].append(float(s))
                res["coddington"]["tangential_mm"][-1].append(float(t))
                ref_sphere, cr_pkg = rt.setup_pupil_coords(opm, fld, w, 0.0)
                fld.chief_ray = cr_pkg
                fld.ref_sphere = ref_sphere
                s, t = rt.trace_astigmatism(opm, fld, w, 0.0)
                res["ray_pairs"]["sagittal_mm"][-1].append(float(s))
                res["ray_pairs"]["tangential_mm"][-1].append(float(t))
        out["rayoptics"] = {"version": version("rayoptics"), "field_deg": fields,
                            "wavelengths_nm": lens["wavelengths_nm"],
                            "chief_ray": "aimed at the stop centre at the primary wavelength",
                            **res}
    except ImportError as e:
        out["rayoptics"] = {"error": f"not importable: {e}"}
    except Exception as e:  # e.g. a V_d = 0 glass, which opticalglass cannot model
        out["rayoptics"] = {"error": f"rayoptics cannot build the lens: {e!r}"[:300]}
    return out


# ----------------------------------------------------------------------------------------------
# finite conjugate
# ----------------------------------------------------------------------------------------------
def finite_optiland(lens, aiming):
    from optiland import optic
    from optiland.materials import IdealMaterial
    op = optic.Optic()
    op.surfaces.add(index=0, radius=math.inf, thickness=lens["object_distance_mm"])
    for i, s in enumerate(lens["surfaces"], start=1):
        kw = dict(index=i, radius=s["radius_mm"], thickness=s["thickness_mm"],
                  is_stop=bool(s.get("stop", False)))
        m = s.get("material", "air")
        if isinstance(m, dict) and "glass" in m:
            kw["material"] = (m["glass"], m.get("catalog", "schott"))
        elif isinstance(m, dict) and "n" in m:
            kw["material"] = IdealMaterial(n=m["n"])
        op.surfaces.add(**kw)
    op.surfaces.add(index=len(lens["surfaces"]) + 1)
    op.set_aperture(aperture_type="EPD", value=lens["aperture"]["value_mm"])
    op.fields.set_type(field_type="object_height")
    hmax = max(lens["object_heights_mm"]) or 1.0
    for h in lens["object_heights_mm"]:
        op.fields.add(y=h)
    for w in lens["wavelengths_nm"]:
        op.wavelengths.add(value=w / 1000.0, is_primary=(w == lens["primary_nm"]))
    op.ray_tracer.set_aiming(aiming)
    op.updater.image_solve()
    nsurf = len(lens["surfaces"])
    p = op.paraxial
    fo = {"efl_mm": float(p.f2()), "image_distance_mm": float(op.surfaces[nsurf].thickness),
          "magnification": float(p.magnification()) if hasattr(p, "magnification") else None,
          "epd_mm": float(p.EPD()), "enp_from_s1_mm": float(p.EPL())}
    wp = lens["primary_nm"] / 1000.0
    px, py = R.pupil_grid(33)
    chief, spots = [], []
    for h in lens["object_heights_mm"]:
        hy = h / hmax
        r = op.trace_generic(Hx=0.0, Hy=hy, Px=0.0, Py=0.0, wavelength=wp)
        chief.append({"object_height_mm": h, "x_mm": float(np.ravel(r.x)[0]),
                      "y_mm": float(np.ravel(r.y)[0])})
        r = op.trace_generic(Hx=np.zeros_like(px), Hy=np.full_like(px, hy), Px=px, Py=py,
                             wavelength=wp)
        x, y = np.asarray(r.x, float).ravel(), np.asarray(r.y, float).ravel()
        ok = np.isfinite(x) & np.isfinite(y)
        spots.append({"object_height_mm": h,
                      "rms_um": 1000.0 * R.rms_about_centroid(x[ok], y[ok]),
                      "centroid_y_mm": float(np.mean(y[ok])), "rays": int(ok.sum())})
    return {"version": version("optiland"), "aiming": aiming, "first_order": fo,
            "chief": chief, "spots": spots}


def finite_rayoptics(lens):
    from rayoptics.environment import OpticalModel, PupilSpec, FieldSpec, WvlSpec
    from rayoptics.raytr import trace as rt
    opm = OpticalModel()
    sm, osp = opm["seq_model"], opm["optical_spec"]
    osp["pupil"] = PupilSpec(osp, key=["object", "epd"], value=lens["aperture"]["value_mm"])
    hs = lens["object_heights_mm"]
    hmax = max(hs) or 1.0
    osp["fov"] = FieldSpec(osp, key=["object", "height"], value=hmax,
                           flds=[h / hmax for h in hs], is_relative=True)
    wl = lens["wavelengths_nm"]
    osp["wvls"] = WvlSpec([(w, 1.0) for w in wl], ref_wl=wl.index(lens["primary_nm"]))
    opm.radius_mode = True
    sm.gaps[0].thi = lens["object_distance_mm"]
    for s in lens["surfaces"]:
        r = s["radius_mm"]
        r = 0.0 if r is None or math.isinf(r) else r
        m = s.get("material", "air")
        if isinstance(m, dict) and "n" in m:
            from opticalglass.opticalmedium import ConstantIndex
            args = [r, s["thickness_mm"], ConstantIndex(m["n"], f"n={m['n']}")]
        elif isinstance(m, dict):
            args = [r, s["thickness_mm"], m["glass"], m.get("catalog", "schott").capitalize()]
        else:
            args = [r, s["thickness_mm"]]
        sm.add_surface(args)
        if s.get("stop"):
            sm.set_stop()
    opm.update_model()
    fod = opm["analysis_results"]["parax_data"].fod
    sm.gaps[-1].thi = float(fod.img_dist)
    opm.update_model()
    fod = opm["analysis_results"]["parax_data"].fod
    w = lens["primary_nm"]
    px, py = R.pupil_grid(33)
    chief, spots = [], []
    for fld, h in zip(osp["fov"].fields, hs):
        fld.aim_info = rt.aim_chief_ray(opm, fld, w)
        pkg, _ = rt.trace_ray(opm, [0.0, 0.0], fld, w)
        p = pkg.ray[-1][0]
        chief.append({"object_height_mm": h, "x_mm": float(p[0]), "y_mm": float(p[1])})
        xs, ys = [], []
        for a, b in zip(px, py):
            try:
                rp = rt.trace_base(opm, [float(a), float(b)], fld, w, apply_vignetting=False)
                q = rp[0][-1][0]
                xs.append(q[0])
                ys.append(q[1])
            except Exception:
                pass
        xs, ys = np.array(xs), np.array(ys)
        spots.append({"object_height_mm": h, "rms_um": 1000.0 * R.rms_about_centroid(xs, ys),
                      "centroid_y_mm": float(ys.mean()), "rays": int(len(xs))})
    return {"version": version("rayoptics"),
            "first_order": {"efl_mm": float(fod.efl), "image_distance_mm": float(fod.img_dist),
                            "magnification": float(fod.m), "epd_mm": 2 * float(fod.enp_radius),
                            "enp_from_s1_mm": float(fod.enp_dist)},
            "chief": chief, "spots": spots}


def finite(lens):
    out = {"optiland": finite_optiland(lens, "iterative"),
           "optiland_paraxial_aiming": finite_optiland(lens, "paraxial")}
    try:
        out["rayoptics"] = finite_rayoptics(lens)
    except ImportError as e:
        out["rayoptics"] = {"error": f"not importable: {e}"}
    return out


# ----------------------------------------------------------------------------------------------
# conic / even-asphere lenses through ref_lens.py (optiland only)
# ----------------------------------------------------------------------------------------------
def asphere(lens_json, out, extra_args):
    """Run ref_lens.py's main on LENS_JSON with optiland surfaces made even aspheres."""
    import optiland.optic as optic_mod
    with open(lens_json) as f:
        lens = json.load(f)
    asph = {}
    for i, s in enumerate(lens["surfaces"], start=1):  # optiland index 0 is the object
        k = float(s.get("conic", 0.0))
        a = [float(x) for x in s.get("aspheric_coeffs", [])]
        if k != 0.0 or any(x != 0.0 for x in a):
            asph[i] = (k, a)
    if not asph:
        raise SystemExit(f"{lens_json}: no surface has a conic or aspheric_coeffs")
    base = optic_mod.Optic

    class AsphericOptic(base):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            add = self.surfaces.add

            def add_asph(*a, index=None, **k):
                if index in asph:
                    conic, coeffs = asph[index]
                    k.update(surface_type="even_asphere", conic=conic,
                             coefficients=[0.0] + coeffs)
                return add(*a, index=index, **k)
            self.surfaces.add = add_asph

    optic_mod.Optic = AsphericOptic
    try:
        argv = sys.argv
        sys.argv = ["ref_lens.py", lens_json, "-o", out, "--backends", "optiland"] + extra_args
        import contextlib
        import io
        with contextlib.redirect_stdout(io.StringIO()):
            R.main()
    finally:
        sys.argv = argv
        optic_mod.Optic = base
    with open(out) as f:
        doc = json.load(f)
    doc["aspheres"] = {"runner": "tools/optics_ref_extra.py asphere",
                       "surfaces": [{"surface": i, "conic": k, "aspheric_coeffs": a}
                                    for i, (k, a) in sorted(asph.items())]}
    with open(out, "w") as f:
        f.write(json.dumps(doc, indent=1) + "\n")


def cauchy_nd_vd(nd, vd):
    """(A, B) of n(lambda) = A + B / lambda^2 (lambda in um) with n(d) = nd and
    n(F) - n(C) = (nd - 1) / vd: camsim's (nd, Vd) model glass (camsim_lens::glass)."""
    lf, ld, lc = 0.4861327, 0.5875618, 0.6562725
    b = (nd - 1.0) / vd / (1.0 / lf**2 - 1.0 / lc**2)
    return nd - b / ld**2, b


def install_patches(lens):
    """Patch optiland's Optic and ref_lens.py's RayopticsBackend for LENS (see `patched`);
    returns (undo, record)."""
    asph = {}
    for i, s in enumerate(lens["surfaces"], start=1):
        k = float(s.get("conic", 0.0))
        a = [float(x) for x in s.get("aspheric_coeffs", [])]
        b = [float(x) for x in s.get("odd_aspheric_coeffs", [])]
        if b:
            # one r^1, r^2, ... list: the odd-asphere terms plus any even A4, A6, ... (r^(2m+4))
            n = max(len(b), 2 * len(a) + 2)
            full = b + [0.0] * (n - len(b))
            for m, x in enumerate(a):
                full[2 * m + 3] += x
            asph[i] = ("odd", k, full)
        elif k != 0.0 or any(x != 0.0 for x in a):
            asph[i] = ("even", k, a)
    ro_glass = set(lens.get("rayoptics_glass_from_optiland", []))
    cauchy = {}
    if lens.get("model_glass") == "cauchy":
        for i, s in enumerate(lens["surfaces"], start=1):
            m = s.get("material", "air")
            if isinstance(m, dict) and "vd" in m and "glass" not in m:
                cauchy[i] = (float(m["nd"]), float(m["vd"]))
    import optiland.optic as optic_mod
    import optiland.backend as obe
    from optiland.materials import IdealMaterial
    base_optic = optic_mod.Optic
    base_ro = R.RayopticsBackend

    class CauchyMaterial(IdealMaterial):
        """optiland material n = A + B / lambda^2 (lambda in um), k = 0."""
        def __init__(self, nd, vd):
            super().__init__(n=nd)
            self.cauchy = cauchy_nd_vd(nd, vd)

        def _cache_state(self):
            return self._state_key((obe.array(list(self.cauchy)),))

        def _calculate_n(self, wavelength, **kwargs):
            a, b = self.cauchy
            return a + b / obe.asarray(wavelength) ** 2

    class AsphericOptic(base_optic):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            add = self.surfaces.add

            def add_asph(*a, index=None, **k):
                if index in asph:
                    kind, conic, coeffs = asph[index]
                    if kind == "odd":
                        k.update(surface_type="odd_asphere", conic=conic, coefficients=coeffs)
                    else:
                        k.update(surface_type="even_asphere", conic=conic,
                                 coefficients=[0.0] + coeffs)
                if index in cauchy:
                    k["material"] = CauchyMaterial(*cauchy[index])
                return add(*a, index=index, **k)
            self.surfaces.add = add_asph

    class OptilandMedium:
        """A rayoptics medium with optiland's n(lambda) for glass NAME of CATALOG."""
        def __init__(self, name, catalog):
            from optiland.materials import Material
            self.label = name
            self.mat = Material(name, catalog)

        def name(self):
            return self.label

        def catalog_name(self):
            return "optiland"

        def rindex(self, wv_nm):
            return float(np.squeeze(self.mat.n(float(wv_nm) / 1000.0)))

        def meas_rindex(self, wv_nm):
            return self.rindex(wv_nm)

    class CauchyMedium:
        """A rayoptics medium n = A + B / lambda^2 (lambda in um) from (nd, vd)."""
        def __init__(self, nd, vd):
            self.label = f"{nd}:{vd} cauchy"
            self.cauchy = cauchy_nd_vd(nd, vd)

        def name(self):
            return self.label

        def catalog_name(self):
            return "cauchy"

        def rindex(self, wv_nm):
            a, b = self.cauchy
            return a + b / (float(wv_nm) / 1000.0) ** 2

        def meas_rindex(self, wv_nm):
            return self.rindex(wv_nm)

    class PatchedRayoptics(base_ro):
        def __init__(self, lens, clip=False):
            super().__init__(lens, clip)
            from rayoptics.elem.profiles import EvenPolynomial, RadialPolynomial
            sm = self.opm["seq_model"]
            for i, s in enumerate(lens["surfaces"], start=1):
                m = s.get("material", "air")
                if isinstance(m, dict) and m.get("glass") in ro_glass:
                    sm.gaps[i].medium = OptilandMedium(m["glass"],
                                                       m.get("catalog", "schott").split("/")[0])
                if i in cauchy:
                    sm.gaps[i].medium = CauchyMedium(*cauchy[i])
            for i, (kind, k, a) in asph.items():
                ifc = sm.ifcs[i]
                if kind == "odd":
                    ifc.profile = RadialPolynomial(c=ifc.profile.cv, cc=k, coefs=list(a))
                else:
                    ifc.profile = EvenPolynomial(c=ifc.profile.cv, cc=k, coefs=[0.0] + a)
            self.opm.update_model()
            self.solve_paraxial_focus()

    optic_mod.Optic = AsphericOptic
    R.RayopticsBackend = PatchedRayoptics

    def undo():
        optic_mod.Optic = base_optic
        R.RayopticsBackend = base_ro
    record = {"aspheres": [{"surface": i, "kind": kind, "conic": k,
                            ("odd_aspheric_coeffs" if kind == "odd" else "aspheric_coeffs"): a}
                           for i, (kind, k, a) in sorted(asph.items())],
              "rayoptics_glass_from_optiland": sorted(ro_glass)}
    if cauchy:
        record["model_glass_cauchy"] = [
            {"surface": i, "nd": nd, "vd": vd, "A": cauchy_nd_vd(nd, vd)[0],
             "B_um2": cauchy_nd_vd(nd, vd)[1]} for i, (nd, vd) in sorted(cauchy.items())]
    return undo, record


def patched(lens_json, out, extra_args):
    """ref_lens.py's main on LENS_JSON, both backends, with what ref_lens.py cannot express
    patched into the lenses it builds (after each backend's constructor, before any analysis):
      * surfaces with "conic" / "aspheric_coeffs": optiland "even_asphere" surfaces (as
        `asphere`) and rayoptics EvenPolynomial profiles (coefs [0, A4, A6, ...]: its list
        starts at r^2, like optiland's);
      * surfaces with "odd_aspheric_coeffs" ([b1, b2, ...], sag terms b_i r^i, the Zemax
        ODDASPHE convention): optiland "odd_asphere" surfaces (coefficients[0] is r^1) and
        rayoptics RadialPolynomial profiles (coefs from r^1, cc = conic);
      * glasses named in the input's "rayoptics_glass_from_optiland" (absent from rayoptics'
        opticalglass catalogue, which then silently builds AIR): rayoptics gets a medium whose
        n(lambda) is optiland's material of that name (the refractiveindex.info data that camsim
        embeds), so both backends trace the same glass;
      * with "model_glass": "cauchy", every {"nd", "vd"} material is camsim's model glass
        n = A + B / lambda^2 with n(d) = nd, n(F) - n(C) = (nd - 1)/vd in both backends
        (ref_lens.py alone would build optiland's AbbeMaterial and opticalglass' ModelGlass,
        two other dispersion models).
    Neither patch changes the paraxial data of a lens with no r^2 term, but each backend
    re-solves its paraxial focus afterwards."""
    with open(lens_json) as f:
        lens = json.load(f)
    undo, record = install_patches(lens)
    try:
        argv = sys.argv
        sys.argv = ["ref_lens.py", lens_json, "-o", out] + extra_args
        import contextlib
        import io
        with contextlib.redirect_stdout(io.StringIO()):
            R.main()
    finally:
        sys.argv = argv
        undo()
    with open(out) as f:
        doc = json.load(f)
    doc["patches"] = {"runner": "tools/optics_ref_extra.py patched", **record}
    with open(out, "w") as f:
        f.write(json.dumps(doc, indent=1) + "\n")


def mtf_focus(lens, n, aiming="iterative"):
    be = R.OptilandBackend(lens, aiming=aiming)
    fo = be.first_order()
    wp = lens["primary_nm"]
    freqs = lens["mtf_freqs_lpmm"]
    merit_f = lens.get("merit_freqs_lpmm", freqs)
    nu_cut = 1.0 / (wp * 1e-6 * fo["fno"])
    bfl = fo["bfl_mm"]

    def at(dz, fr):
        be.set_image_distance(bfl + dz)
        opd = be.opd_map(0.0, wp, n)
        okv = opd[np.isfinite(opd)]
        return R.mtf_from_opd(opd, fr, nu_cut, pad=2), float(okv.max() - okv.min())

    def merit(dz):
        m, _ = at(dz, merit_f)
        return float(np.mean([0.5 * (v["tangential"] + v["sagittal"]) for v in m.values()]))

    # RMS best focus on axis, as ref_lens.py's analyse()
    px, py = R.pupil_grid(33)
    be.set_image_distance(bfl)
    rays = [be.trace(0.0, w, px, py) for w in lens["wavelengths_nm"]]

    def poly_rms(dz):
        xs, ys = [], []
        for x, y, L, M, N in rays:
            ok = np.isfinite(x)
            xs.append(x[ok] + dz * L[ok] / N[ok]); ys.append(y[ok] + dz * M[ok] / N[ok])
        return R.rms_about_centroid(np.concatenate(xs), np.concatenate(ys))

    from scipy.optimize import minimize_scalar
    span = 0.02 * fo["efl_mm"]
    dz_rms = float(minimize_scalar(poly_rms, bounds=(-span, span), method="bounded",
                                   options={"xatol": 1e-6}).x)
    d = 8.0 * wp * 1e-6 * fo["fno"] ** 2
    lo, hi = min(dz_rms, 0.0) - d, max(dz_rms, 0.0) + d
    h = (hi - lo) / 24
    scan = [(lo + h * k, merit(lo + h * k)) for k in range(25)]
    zb, mb = max(scan, key=lambda t: t[1])
    g = (5 ** 0.5 - 1) / 2
    a, b = max(zb - h, lo), min(zb + h, hi)
    c, e = b - g * (b - a), a + g * (b - a)
    fc, fe = merit(c), merit(e)
    while b - a > 1e-4 * (hi - lo):
        if fc > fe:
            b, e, fe = e, c, fc
            c = b - g * (b - a); fc = merit(c)
        else:
            a, c, fc = c, e, fe
            e = a + g * (b - a); fe = merit(e)
    z = 0.5 * (a + b)
    mz = merit(z)
    if mz < mb:
        z, mz = zb, mb
    out = {"optiland": version("optiland"), "opd_grid": n, "nu_cut_lpmm": nu_cut,
           "fno_w": fo["fno"], "efl_mm": fo["efl_mm"], "bfl_mm": bfl,
           "merit_freqs_lpmm": merit_f, "search_interval_mm": [lo, hi]}
    for key, dz in [("paraxial", 0.0), ("best_rms", dz_rms), ("best_mtf", z)]:
        m, pv = at(dz, freqs)
        out[key] = {"image_shift_mm": dz, "opd_pv_waves": pv, "mtf": m}
    out["best_mtf"]["merit"] = mz
    be.set_image_distance(bfl)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=["field_curvature", "finite", "asphere", "patched", "mtf"])
    ap.add_argument("lens_json")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--opd-grid", type=int, default=512, help="mtf: OPD grid per side")
    ap.add_argument("--optiland-aiming", default="iterative",
                    help="mtf: optiland ray aiming, iterative (default; fills the real stop) or "
                         "paraxial (fills the paraxial entrance pupil, as rayoptics and camsim)")
    a, rest = ap.parse_known_args()
    if a.what == "asphere":
        asphere(a.lens_json, a.output, rest)
        return
    if a.what == "patched":
        patched(a.lens_json, a.output, rest)
        return
    if rest:
        ap.error(f"unrecognised arguments: {' '.join(rest)}")
    if a.what == "field_curvature":
        lens = R.load_lens(a.lens_json)
        res = field_curvature(lens)
    elif a.what == "mtf":
        lens = R.load_lens(a.lens_json)
        # an input run through `patched` gets the same patches (aspheres, model glasses)
        patched_input = lens.get("ref_lens_runner") == "patched"
        undo, record = install_patches(lens) if patched_input else (lambda: None, None)
        try:
            res = mtf_focus(lens, a.opd_grid, a.optiland_aiming)
        finally:
            undo()
        res["optiland_aiming"] = a.optiland_aiming
        if patched_input and (record["aspheres"] or record.get("model_glass_cauchy")):
            res["patches"] = {"runner": "tools/optics_ref_extra.py mtf", **record}
    else:
        with open(a.lens_json) as f:
            lens = json.load(f)
        for s in lens["surfaces"]:
            r = s.get("radius_mm")
            s["radius_mm"] = math.inf if r is None else float(r)
        res = finite(lens)
    doc = {"lens": a.lens_json.split("/")[-1], "what": a.what, "python": sys.version.split()[0],
           "results": res}
    with open(a.output, "w") as f:
        f.write(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
