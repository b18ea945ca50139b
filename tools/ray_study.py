#!/usr/bin/env python3
"""Run the points of a camsim study on a Ray cluster (`camsim study SPEC --engine ray`).

camsim writes every unfinished point as POINT_DIR/point.json and lists them in a JSON file
{"points": [{"point": ".../point.json", "out": "POINT_DIR"}, ...]}; this script submits one
Ray task per point that runs `camsim --threads 1 study-point POINT --out POINT_DIR` (the same
Rust code as the local engine, so the results are identical) and waits for all of them.
camsim then reads the results and writes the tables and the report.

Without --address (and without RAY_ADDRESS) a local cluster is started with --num-cpus CPUs and
shut down at the end. Workers must see the camsim binary and the output folder at the same paths
(one machine, or a shared file system).
"""
import argparse
import json
import os
import subprocess
import sys
import time

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

import ray  # noqa: E402  (installed by tools/ray_setup.sh)


@ray.remote(num_cpus=1)
def run_point(camsim, point, out):
    r = subprocess.run(
        [camsim, "--threads", "1", "study-point", point, "--out", out],
        capture_output=True,
        text=True,
    )
    return {"point": point, "code": r.returncode, "stderr": r.stderr[-4000:]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camsim", required=True, help="the camsim binary")
    ap.add_argument("--points", required=True, help="the point list camsim wrote")
    ap.add_argument("--address", help="address of a running Ray cluster")
    ap.add_argument("--num-cpus", type=int, help="CPUs of the local cluster")
    a = ap.parse_args()
    with open(a.points) as f:
        points = json.load(f)["points"]
    if a.address:
        ray.init(address=a.address, log_to_driver=False)
    else:
        ray.init(num_cpus=a.num_cpus, include_dashboard=False, log_to_driver=False)
    failed = []
    try:
        pending = [run_point.remote(a.camsim, p["point"], p["out"]) for p in points]
        done = 0
        t0 = time.time()
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for r in ray.get(ready):
                done += 1
                if r["code"] != 0:
                    failed.append(r)
                    print(f"ray_study: {r['point']}: failed: {r['stderr'].strip()}", file=sys.stderr)
            print(f"ray_study: {done}/{len(points)} points ({time.time() - t0:.0f} s)", file=sys.stderr)
    finally:
        ray.shutdown()
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
