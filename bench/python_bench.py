#!/usr/bin/env python3
"""Overhead of the Python package against the CLI, same run, same machine (issue 19):

1. 1,000 small calls from Python (acceptance: ≤ 1 s in total): `camsim.noop` (the bare
   boundary), `camsim.airy_radius_um` (a scalar formula) and `camsim.delta_e_2000` on one pair
   (an array in, an array out).
2. The 12 MP flat field of bench/bench.py (4000 × 3000, every noise source, cos⁴): the CLI
   `camsim simulate` (whole process incl. the 16-bit PNG) against Python in the same process
   doing the same work — `CaptureSet.load(...).write(...)` (same PNG) — and returning the frame
   as a NumPy array instead (`CaptureSet.load(...).simulate()`). Acceptance: Python within 10 %
   of the CLI.

Writes docs/benchmarks/python.md. Usage: bench/python.sh
"""
import json, os, platform, statistics, subprocess, sys, tempfile, time

import numpy as np

import camsim

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench import BIN, ROOT, camera  # noqa: E402  (the 12 MP camera of the core benchmark)


def timeit(fn, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), min(ts)


def main():
    repeats = int(os.environ.get("BENCH_REPEATS", "7"))
    # 1. small calls
    lab1, lab2 = np.array([50.0, 2.6772, -79.7751]), np.array([50.0, 0.0, -82.7485])
    small = {
        "noop": lambda: [camsim.noop(1.0) for _ in range(1000)],
        "airy_radius_um": lambda: [camsim.airy_radius_um(550.0, 2.8) for _ in range(1000)],
        "delta_e_2000 (one pair)": lambda: [camsim.delta_e_2000(lab1, lab2) for _ in range(1000)],
    }
    small_t = {k: timeit(f, repeats) for k, f in small.items()}

    # 2. 12 MP simulate
    tmp = tempfile.mkdtemp(prefix="camsim-pybench-")
    json.dump(camera(3000, 4000), open(os.path.join(tmp, "camera.json"), "w"))
    json.dump({"camera": "camera.json", "shots": [{"id": "flat", "exposure_s": 0.02,
               "target": {"kind": "uniform", "radiance": 0.003}, "frames": ["flat.png"]}]},
              open(os.path.join(tmp, "captures.json"), "w"))
    caps = os.path.join(tmp, "captures.json")
    runs = iter(range(100000))
    new_out = lambda: os.path.join(tmp, f"out{next(runs)}")
    cli = lambda: subprocess.run([BIN, "simulate", caps, "--out", new_out()], check=True)
    py_write = lambda: camsim.CaptureSet.load(caps).write(new_out())
    py_array = lambda: camsim.CaptureSet.load(caps).simulate().images["flat"]
    cli(); py_write(); py_array()  # warm-up (page cache, thread pool)
    # interleaved rounds so that load changes on the shared machine hit both sides alike
    t_cli, t_pyw, t_pya = [], [], []
    for _ in range(repeats):
        for fn, ts in ((cli, t_cli), (py_write, t_pyw), (py_array, t_pya)):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
    med = statistics.median
    # the frames are the CLI's
    out = new_out()
    subprocess.run([BIN, "simulate", caps, "--out", out], check=True)
    same = np.array_equal(camsim.read_frame(os.path.join(out, "flat.png")), py_array()[0])

    cpu = "unknown"
    try:
        cpu = [l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")][0]
    except Exception:
        pass
    load = os.getloadavg()
    ratio_w = med(t_pyw) / med(t_cli)
    ratio_a = med(t_pya) / med(t_cli)
    lines = [
        "# Python package overhead (bench/python.sh)",
        "",
        f"Machine: {cpu}, {os.cpu_count()} logical CPUs, load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f}; "
        f"Python {platform.python_version()}, numpy {np.__version__}, camsim {camsim.__version__} (release wheel built by maturin). "
        f"Median of {repeats} runs (min in brackets).",
        "",
        "## 1,000 small calls (acceptance: ≤ 1 s)",
        "",
        "| call | 1,000 calls | per call |",
        "|---|---|---|",
    ]
    for k, (m, lo) in small_t.items():
        lines.append(f"| `{k}` | {m*1e3:.2f} ms ({lo*1e3:.2f}) | {m*1e3:.2f} µs |")
    lines += [
        "",
        "## 12 MP simulate (acceptance: Python within 10 % of the CLI)",
        "",
        "4000 × 3000 flat field, every noise source, cos⁴ fall-off, 10-bit ADC (the camera of bench/bench.py). "
        "Rounds interleave the three so machine load hits them alike.",
        "",
        "| run | median | min | ratio to CLI (median) |",
        "|---|---|---|---|",
        f"| CLI `camsim simulate` (process, JSON, simulate, 16-bit PNG) | {med(t_cli):.3f} s | {min(t_cli):.3f} s | 1 |",
        f"| Python `CaptureSet.load(...).write(out)` (same work, same PNG) | {med(t_pyw):.3f} s | {min(t_pyw):.3f} s | {ratio_w:.3f} |",
        f"| Python `CaptureSet.load(...).simulate()` (frame as a NumPy array) | {med(t_pya):.3f} s | {min(t_pya):.3f} s | {ratio_a:.3f} |",
        "",
        f"Python's frame equals the CLI's PNG pixel for pixel: {'yes' if same else 'NO'}.",
        "",
    ]
    text = "\n".join(lines)
    os.makedirs(os.path.join(ROOT, "docs", "benchmarks"), exist_ok=True)
    open(os.path.join(ROOT, "docs", "benchmarks", "python.md"), "w").write(text)
    print(text)
    ok = all(m <= 1.0 for m, _ in small_t.values()) and ratio_w <= 1.10 and same
    print("acceptance:", "met" if ok else "NOT met")


if __name__ == "__main__":
    main()
