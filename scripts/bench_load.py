#!/usr/bin/python3
"""Frame times on a quiet and on a busy computer (doc/performance.md#threads-on-a-shared-computer).

Runs the `bench` tool on the aspiration cube (1 ms frames) and the liver phantom (10 ms frames),
each without and with a probe sweeping the surface (config/bench/probe_sweep_*.yaml), in real-time
frames (modified_newton:1:0), for every thread count of --threads, each once quiet and once beside
--load busy threads (one per processor, bench --load), writes the rows to --csv and prints, per
case and thread count, the busy/quiet ratios of the mean and p95 frame times and the busy mean
against one thread's.
  taskset -c 0,1 scripts/bench_load.py [--threads 1,2] [--load 2] [--csv doc/bench_load.csv]
"""
import argparse
import csv
import io
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))  # package_paths, also through catkin's relay
from package_paths import output_folder, package_file, package_root, tool  # noqa: E402

BENCH = tool("bench")
SCENES = package_file("config", "scenes")
SWEEPS = package_file("config", "bench")
STRATEGY = "modified_newton:1:0"

# label, scene, --set, instruments, frames
CASES = [
    ("cube", "aspiration_cube.yaml", ["solver.dt=0.001"], None, 300),
    ("cube probe", "probe_cube.yaml", [], "probe_sweep_cube.yaml", 300),
    ("phantom", "liver_phantom.yaml", ["solver.dt=0.01"], None, 60),
    ("phantom probe", "liver_phantom.yaml", ["solver.dt=0.01"], "probe_sweep_phantom.yaml", 60),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bench", default=BENCH)
    ap.add_argument("--threads", default="1,2", help="solver.threads of the runs, comma-separated")
    ap.add_argument("--load", type=int, default=2, help="busy threads beside the loaded runs")
    ap.add_argument("--csv", default=os.path.join(output_folder(), "bench_load.csv"))
    args = ap.parse_args()
    rows = []
    for label, scene, sets, instruments, frames in CASES:
        cmd = [args.bench, "--scene", os.path.join(SCENES, scene), "--frames", str(frames), "--strategy", STRATEGY,
               "--threads", args.threads, "--load", f"0,{args.load}", "--quiet"]
        for s in sets:
            cmd += ["--set", s]
        if instruments:
            cmd += ["--instruments", os.path.join(SWEEPS, instruments)]
        print(f"bench_load: {label} ...", file=sys.stderr, flush=True)
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        for row in csv.DictReader(io.StringIO(out)):
            row["case"] = label
            row["scene"] = os.path.relpath(row["scene"], package_root())  # the CSV is committed: no machine path
            rows.append(row)
    with open(args.csv, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["case"] + [k for k in rows[0] if k != "case"])
        w.writeheader()
        w.writerows(rows)
    print("case            threads  quiet mean/p95 (ms)  busy mean/p95 (ms)  busy/quiet mean  p95   busy mean / 1 thread's")
    for label, *_ in CASES:
        runs = {(int(r["threads"]), int(r["load"])): r for r in rows if r["case"] == label}
        one = float(runs[(1, args.load)]["mean_ms"])
        for threads in sorted({t for t, _ in runs}):
            q, b = runs[(threads, 0)], runs[(threads, args.load)]
            qm, qp, bm, bp = (float(r[k]) for r in (q, b) for k in ("mean_ms", "p95_ms"))
            print(f"{label:15s} {threads:7d}  {qm:8.2f} / {qp:8.2f}  {bm:8.2f} / {bp:8.2f}  {bm / qm:15.2f}  "
                  f"{bp / qp:4.2f}  {bm / one:6.2f}")


if __name__ == "__main__":
    main()
