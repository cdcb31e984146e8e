#!/usr/bin/python3
"""Run time against error for every solver strategy (doc/performance.md).

Runs the `bench` tool (the scene's equilibrium, then breathing loads 1 + 0.5 sin(2 pi t)) on the
aspiration cube at about 2k, 10k and 50k tetrahedra (frames of 1 ms) and on the liver phantom
(11k tetrahedra, frames of 10 ms and 33 ms); then with instruments in contact (config/bench/): a
probe pressing and sweeping on the cube (1 ms frames) and on the phantom (10 ms and 33 ms), a
grasper lifting the edge of the right lobe, and the aspiration tube. Errors are against converged
dynamics (Newton to 1e-10) of the same run, contact included. Writes doc/bench.csv (a contact
row carries `contact_free_ratio`: its mean frame over the contact-free frame of the same mesh and
strategy) and draws
  doc/bench_pareto.png   error against time per frame (the Pareto front), per case
  doc/bench_scaling.png  time per frame and one factorisation against DOFs (log-log, fitted exponents)
Pin it: taskset -c 0 scripts/bench.py (one core), or taskset -c 0,1 (both, OpenMP).
  --quick   the 2k cube only, without (20 frames) and with the probe (100 frames), a few strategies
            (the test suite's smoke run)
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
CUBE = package_file("config", "scenes", "aspiration_cube.yaml")
PHANTOM = package_file("config", "scenes", "liver_phantom.yaml")
PROBE_CUBE = package_file("config", "scenes", "probe_cube.yaml")
TUBE = package_file("config", "scenes", "aspiration_tube.yaml")
INSTRUMENTS = package_file("config", "bench")

ALL = ["newton_krylov:30:1e-6", "newton_krylov:1:0", "full_newton:30:1e-6", "full_newton_eigen:30:1e-6",
       "reused_factor_cg:30:1e-6", "cg:30:1e-6", "modified_newton:1:0", "modified_newton:2:0"]
LARGE = ["newton_krylov:30:1e-6", "newton_krylov:1:0", "full_newton:30:1e-6", "reused_factor_cg:30:1e-6",
         "modified_newton:1:0", "modified_newton:2:0"]


CONTACT = ["newton_krylov:30:1e-6", "full_newton:30:1e-6", "modified_newton:1:0", "modified_newton:2:0",
           "modified_newton:3:0"]


def cases(quick):
    """(label, scene, --set overrides, frames, strategies, instruments file or None, contact-free case)"""
    if quick:
        return [("cube 2k", CUBE, ["mesh.box.divisions.0=8", "mesh.box.divisions.1=8", "mesh.box.divisions.2=8",
                                   "solver.dt=0.001"], 20, ["newton_krylov:30:1e-6", "full_newton_eigen:30:1e-6",
                                                            "modified_newton:1:0"], None, None),
                ("cube 2k probe", PROBE_CUBE, [], 100, ["newton_krylov:30:1e-6", "modified_newton:1:0"],
                 os.path.join(INSTRUMENTS, "probe_sweep_cube.yaml"), None)]
    out = []
    # Jacobi-preconditioned CG only on the small cube: with the capsule it needs thousands of
    # iterations per update on the larger meshes.
    for label, n, frames, strategies in [("cube 2k", 8, 200, ALL), ("cube 10k", 13, 100, LARGE + ["full_newton_eigen:30:1e-6"]),
                                         ("cube 50k", 22, 30, LARGE)]:
        out.append((label, CUBE, [f"mesh.box.divisions.{i}={n}" for i in range(3)] + ["solver.dt=0.001"], frames,
                    strategies, None, None))
    out.append(("phantom 11k", PHANTOM, ["solver.dt=0.01"], 50, LARGE + ["full_newton_eigen:30:1e-6", "modified_newton:3:0"],
                None, None))
    out.append(("phantom 11k 33 ms", PHANTOM, ["solver.dt=0.033"], 30, CONTACT, None, None))
    probe_phantom = os.path.join(INSTRUMENTS, "probe_sweep_phantom.yaml")
    out += [("cube 2k probe", PROBE_CUBE, [], 300, CONTACT, os.path.join(INSTRUMENTS, "probe_sweep_cube.yaml"), "cube 2k"),
            ("phantom probe", PHANTOM, ["solver.dt=0.01"], 90, CONTACT, probe_phantom, "phantom 11k"),
            ("phantom probe 33 ms", PHANTOM, ["solver.dt=0.033"], 28, CONTACT, probe_phantom, "phantom 11k 33 ms"),
            ("phantom grasper lift", PHANTOM, ["solver.dt=0.01"], 60, CONTACT,
             os.path.join(INSTRUMENTS, "grasper_lift_phantom.yaml"), "phantom 11k"),
            ("aspiration tube", TUBE, [], 60, CONTACT, None, None)]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--bench", default=BENCH)
    ap.add_argument("--out", default=output_folder())
    args = ap.parse_args()
    if not os.path.exists(args.bench):
        sys.exit(f"{args.bench} not found: build first (scripts/run.sh), or source a workspace that has liver_sim")
    rows = []
    for label, scene, sets, frames, strategies, instruments, free in cases(args.quick):
        cmd = [args.bench, "--scene", scene, "--frames", str(frames)]
        if instruments:
            cmd += ["--instruments", instruments]
        for s in sets:
            cmd += ["--set", s]
        for s in strategies:
            cmd += ["--strategy", s]
        print(f"bench: {label}: {len(strategies)} strategies, {frames} frames ...", file=sys.stderr, flush=True)
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        for row in csv.DictReader(io.StringIO(out)):
            row["case"] = label
            row["scene"] = os.path.relpath(row["scene"], package_root())  # the CSV is committed: no machine path
            row["instruments"] = os.path.relpath(instruments, package_root()) if instruments else ""
            row["contact_free_ratio"] = ""
            if free:
                same = [r for r in rows if r["case"] == free and r["strategy"] == row["strategy"]
                        and r["iterations"] == row["iterations"]]
                if same:
                    row["contact_free_ratio"] = f"{float(row['mean_ms']) / float(same[0]['mean_ms']):.3f}"
            rows.append(row)
            ratio = f"  x{row['contact_free_ratio']} of contact-free" if row["contact_free_ratio"] else ""
            print(f"  {row['strategy']}:{row['iterations']}  mean {float(row['mean_ms']):.2f} ms  "
                  f"error {float(row['max_error']):.2e}  contacts {float(row['contacts']):.1f}{ratio}",
                  file=sys.stderr, flush=True)
    for row in rows:
        if int(row["diverged"]) > 0 or not float(row["max_error"]) < 1:
            print(f"bench: {row['case']} {row['strategy']}:{row['iterations']}: {row['diverged']} frames rolled back, "
                  f"error {row['max_error']}", file=sys.stderr)
    if args.quick:  # the smoke run checks that the driver works, not how fast
        exact = [r for r in rows if r["strategy"] == "newton_krylov"]
        if len(exact) != 2 or any(float(r["max_error"]) > 1e-4 for r in exact):
            sys.exit("bench: a tolerance-driven run does not match its reference")
        if not float(exact[1]["contacts"]) > 0:
            sys.exit("bench: the probe never touched the cube")
        print(f"bench: smoke ok ({len(rows)} strategies)")
        return
    os.makedirs(args.out, exist_ok=True)
    fields = ["case"] + [k for k in rows[0] if k != "case"]
    with open(os.path.join(args.out, "bench.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    plot(rows, args.out)


def plot(rows, out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    case_names = list(dict.fromkeys(r["case"] for r in rows))
    columns = (len(case_names) + 1) // 2
    fig, axes = plt.subplots(2, columns, figsize=(3.6 * columns, 8), sharey=True, squeeze=False)
    for ax in axes.flat[len(case_names):]:
        ax.set_visible(False)
    for ax, case in zip(axes.flat, case_names):
        for r in (r for r in rows if r["case"] == case):
            label = f"{r['strategy']}:{r['iterations']}"
            ax.scatter(float(r["mean_ms"]), max(float(r["max_error"]), 1e-9), s=30)
            ax.annotate(label, (float(r["mean_ms"]), max(float(r["max_error"]), 1e-9)), fontsize=6)
        ax.axhline(0.01, color="0.6", ls="--", lw=0.8)
        ax.set(xscale="log", yscale="log", xlabel="mean time per frame (ms)", title=case)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("max displacement error / peak motion")
    fig.suptitle("Error against time per frame (1% line dashed; lower row: instruments in contact)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "bench_pareto.png"), dpi=90)

    fig, ax = plt.subplots(figsize=(6, 4.2))
    cubes = [r for r in rows if r["case"].startswith("cube")]
    series = {"newton_krylov:30 (to 1e-6)": ("newton_krylov", "30", "mean_ms"),
              "modified_newton:1": ("modified_newton", "1", "mean_ms"),
              "one factorisation": ("full_newton", "30", "factorization_ms")}
    for label, (strategy, its, key) in series.items():
        pts = sorted((int(r["dofs"]), float(r[key])) for r in cubes if r["strategy"] == strategy and r["iterations"] == its)
        if len(pts) < 2:
            continue
        x, y = np.array(pts).T
        slope = np.polyfit(np.log(x), np.log(y), 1)[0]
        ax.loglog(x, y, "o-", label=f"{label}: ~DOFs^{slope:.2f}")
    ax.set(xlabel="DOFs (aspiration cube)", ylabel="ms", title="Cost against problem size")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "bench_scaling.png"), dpi=90)


if __name__ == "__main__":
    main()
