#!/usr/bin/env bash
# Renderer benchmark against the Mitsuba 3 peer, in one run on one machine:
# the shared Cornell scene (<shared>/tools/mitsuba_ref/cornell.gltf) at 256×256, 64 spp,
# bands 380:780:10, rendered by Mitsuba (llvm_ad_spectral, else scalar_spectral) and by
# `camsim render`, two seeds each. Reports render time (load excluded for both), camera
# paths per second, the per-pixel noise of each renderer (from the two seeds, the same
# estimator for both: sqrt(mean((x1 − x2)²/2)) / mean, averaged over bands), the samples/s
# at equal noise (samples/s ÷ relative variance ratio), and compare.py's agreement of the two
# (block 3σ, z_global). Writes docs/benchmarks/render.md.
#
# Usage: bench/render_mitsuba.sh            Env: CAMSIM_SHARED, SPP (64), WIDTH (256),
#        BANDS (380:780:10), VARIANT, CARGO_TARGET_DIR, RR_DEPTH (camsim --rr-depth; default:
#        camsim's default), SCENE (another glTF, e.g. bench/render_mesh.sh's 10⁶-triangle
#        scene), SCENE_DESC (its description in the report), OUT_MD (the report's path),
#        TARGET (the target sentence)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SHARED="${CAMSIM_SHARED:-$ROOT/../shared}"
HARNESS="$SHARED/tools/mitsuba_ref"
SCENE="${SCENE:-$HARNESS/cornell.gltf}"
SCENE_DESC="${SCENE_DESC:-the shared Cornell box (\`shared/tools/mitsuba_ref/cornell.gltf\`)}"
TARGET="${TARGET:-target of issue 7: ≥ 2×}"
SPP="${SPP:-64}"
WIDTH="${WIDTH:-256}"
BANDS="${BANDS:-380:780:10}"
OUT_MD="${OUT_MD:-$ROOT/docs/benchmarks/render.md}"
[[ -f "$SCENE" ]] || { echo "render_mitsuba.sh: $SCENE not found (set CAMSIM_SHARED)" >&2; exit 1; }

if [[ -z "${VARIANT:-}" ]]; then
    VARIANT="$("$ROOT/tools/mitsuba_setup.sh" --no-verify | sed -n 's/^MITSUBA_VARIANT=//p')"
fi
for f in /usr/lib/x86_64-linux-gnu/libLLVM-{19,18,17,16}.so; do
    if [[ -e "$f" ]]; then export DRJIT_LIBLLVM_PATH="${DRJIT_LIBLLVM_PATH:-$f}"; break; fi
done
PY="$ROOT/.venv-mitsuba/bin/python"

(cd "$ROOT" && cargo build --release --quiet --bin camsim)
CAMSIM="${CARGO_TARGET_DIR:-$ROOT/target}/release/camsim"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT

# Mitsuba: a warm-up render first (Dr.Jit compiles its kernels on the first run), then seeds 0, 1.
"$PY" "$HARNESS/gltf_to_mitsuba.py" "$SCENE" -o "$TMP/warm.exr" --variant "$VARIANT" --spp "$SPP" \
    --width "$WIDTH" --bands "$BANDS" --depth-spp 1 >/dev/null
for s in 0 1; do
    "$PY" "$HARNESS/gltf_to_mitsuba.py" "$SCENE" -o "$TMP/mi_s$s.exr" --variant "$VARIANT" --spp "$SPP" \
        --seed "$s" --width "$WIDTH" --bands "$BANDS" --depth-spp 1 >"$TMP/mi_s$s.json"
done
for s in 0 1; do
    "$CAMSIM" render "$SCENE" --width "$WIDTH" --spp "$SPP" --seed "$s" --bands "$BANDS" \
        --mitsuba-channels --depth-spp 1 ${RR_DEPTH:+--rr-depth "$RR_DEPTH"} --out "$TMP/cs_s$s.exr" \
        >"$TMP/cs_s$s.json"
done
"$PY" "$HARNESS/compare.py" "$TMP/cs_s0.exr" "$TMP/mi_s0.exr" --test2 "$TMP/cs_s1.exr" --ref2 "$TMP/mi_s1.exr" \
    --channels 'band_*' --fail-frac 0.02 >"$TMP/compare.txt" || true

"$PY" - "$TMP" "$OUT_MD" "$VARIANT" "$SPP" "$WIDTH" "$BANDS" "${RR_DEPTH:-default}" "$SCENE_DESC" "$TARGET" <<'PY'
import json, os, platform, subprocess, sys, time
import numpy as np
import mitsuba as mi
tmp, out_md, variant, spp, width, bands, rr_depth, scene_desc, target = sys.argv[1:10]
mi.set_variant("scalar_rgb")

def read(p):
    b = mi.Bitmap(p)
    names = [b.struct_()[i].name for i in range(b.channel_count())]
    a = np.array(b, copy=True).astype(np.float64)
    return names, a

def band_mean_image(prefix):
    n0, a0 = read(os.path.join(tmp, prefix + "_s0.exr"))
    idx = [i for i, n in enumerate(n0) if n.startswith("band_")]
    return a0[..., idx].mean(axis=2)

# pixels that see the emitter directly (band-averaged Mitsuba radiance > 10 × the image
# mean): their noise is wavelength-sampling noise, not light-transport noise, and it
# dominates the pooled estimator, so the table also gives the noise over the other pixels
mi_img = band_mean_image("mi")
emitter = mi_img > 10.0 * mi_img.mean()

def noise(prefix, mask=None):
    n0, a0 = read(os.path.join(tmp, prefix + "_s0.exr"))
    n1, a1 = read(os.path.join(tmp, prefix + "_s1.exr"))
    keep = np.ones(a0.shape[:2], bool) if mask is None else ~mask
    rel = []
    for i, n in enumerate(n0):
        if not n.startswith("band_"):
            continue
        j = n1.index(n)
        x0, x1 = a0[..., i][keep], a1[..., j][keep]
        m = 0.5 * (x0 + x1)
        if m.mean() <= 0:
            continue
        rel.append(np.sqrt(np.mean((x0 - x1) ** 2 / 2.0)) / m.mean())
    return float(np.mean(rel))

def runs(prefix, key_s, key_sps):
    js = [json.load(open(os.path.join(tmp, f"{prefix}_s{s}.json"))) for s in (0, 1)]
    return [j[key_s] for j in js], [j[key_sps] for j in js]

mi_t, mi_sps = runs("mi", "render_s", "samples_per_s")
cs_t, cs_sps = runs("cs", "render_s", "samples_per_s")
mi_load, _ = runs("mi", "load_s", "samples_per_s")
cs_load, _ = runs("cs", "load_s", "samples_per_s")
tris = json.load(open(os.path.join(tmp, "cs_s0.json"))).get("triangles")
mi_noise, cs_noise = noise("mi"), noise("cs")
mi_noise_t, cs_noise_t = noise("mi", emitter), noise("cs", emitter)
mi_best, cs_best = max(mi_sps), max(cs_sps)
# samples/s at equal noise: the noise variance per sample scales as noise², so a renderer
# with noise ratio r needs r² as many samples for the same noise
rr_text = "2 (camsim's default)" if rr_depth == "default" else rr_depth
cs_equal = cs_best * (mi_noise / cs_noise) ** 2
cs_equal_t = cs_best * (mi_noise_t / cs_noise_t) ** 2
cmp = open(os.path.join(tmp, "compare.txt")).read().strip().splitlines()
summary = [l for l in cmp if l.startswith("# summary") or l.startswith("PASS") or l.startswith("FAIL")]
cpu = platform.processor() or platform.machine()
try:
    model = [l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")][0]
except Exception:
    model = cpu
ncpu = os.cpu_count()
load = os.getloadavg()
md = f"""# Renderer benchmark: camsim vs Mitsuba 3 (written by bench/render_mitsuba.sh)

Scene: {scene_desc}, {tris} triangles, {width}×{width} px,
{spp} spp, bands {bands} nm, path tracing with unlimited depth (Russian roulette from depth 5
in Mitsuba, from depth {rr_text} in camsim), box pixel filter. Same run, same machine: {model}, {ncpu} logical CPUs, load average
{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1 / 5 / 15 min) at the end of the run
({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}). Render times exclude scene loading for
both renderers; Mitsuba ran one warm-up render first (Dr.Jit kernel compilation).

| renderer | load s (seed 0 / 1) | render s (seed 0 / 1) | camera paths / s (best) | per-pixel noise (rel., 10 nm bands): all pixels / without emitter pixels | paths / s at Mitsuba's noise: all / without emitter pixels |
| --- | --- | --- | --- | --- | --- |
| Mitsuba 3 `{variant}` | {mi_load[0]:.2f} / {mi_load[1]:.2f} | {mi_t[0]:.2f} / {mi_t[1]:.2f} | {mi_best/1e6:.2f} M | {mi_noise:.3f} / {mi_noise_t:.3f} | {mi_best/1e6:.2f} M / {mi_best/1e6:.2f} M |
| camsim `render` (`--rr-depth` {rr_depth}) | {cs_load[0]:.2f} / {cs_load[1]:.2f} | {cs_t[0]:.2f} / {cs_t[1]:.2f} | {cs_best/1e6:.2f} M | {cs_noise:.3f} / {cs_noise_t:.3f} | {cs_equal/1e6:.2f} M / {cs_equal_t/1e6:.2f} M |

Speed ratio camsim / Mitsuba: {cs_best/mi_best:.2f}× in paths per second; at equal noise
{cs_equal/mi_best:.2f}× (all pixels) and {cs_equal_t/mi_best:.2f}× (without the {emitter.mean()*100:.1f} % of pixels that see the
emitter) ({target}). Including scene loading (parse + BVH build), seed 0:
{(mi_load[0] + mi_t[0]) / (cs_load[0] + cs_t[0]):.2f}× in wall time at equal spp.

Noise: from the two seeds, sqrt(mean((x₁ − x₂)²/2)) / mean per band, averaged over the bands
(the same estimator for both renderers). "Without emitter pixels" leaves out the pixels whose
band-averaged Mitsuba radiance exceeds 10× the image mean: there the noise is that of the
wavelength sampling (how many of the 4·spp wavelengths fall in each 10 nm band), which camsim
stratifies per pixel and Mitsuba's independent sampler does not; that noise dominates the
all-pixel figure.

Agreement of the two renders (compare.py, camsim seeds 0+1 against Mitsuba seeds 0+1, 16×16
blocks; a 1-degree-of-freedom variance per pixel):

```
{chr(10).join(summary)}
```
"""
os.makedirs(os.path.dirname(out_md), exist_ok=True)
tmp_md = out_md + ".tmp"
open(tmp_md, "w").write(md)
os.replace(tmp_md, out_md)
print(md)
PY
