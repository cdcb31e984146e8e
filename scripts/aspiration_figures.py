#!/usr/bin/python3
"""The reference aspiration test, with and without Glisson's capsule.

Runs the `simulate` tool on config/scenes/aspiration_tube.yaml (the tube's rim in frictional
contact, suction in the lumen, as the paper ran it) and draws
  doc/aspiration_profile.png  top-surface profile along the mid cut y = 7.5 mm (static)
  doc/aspiration_time.png     centre displacement against time (dynamic, suction applied at t = 0)
and prints a JSON summary (centre displacements, their ratio, solver statistics), with the same
static test on config/scenes/aspiration_cube.yaml (the rim as a fixed annulus) for comparison.

usage: scripts/aspiration_figures.py [--simulate PATH] [--out DIR] [--steps N] [--dt S]
(run scripts/run.sh or scripts/test.sh once first so that the simulator is built)
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))  # package_paths, also through catkin's relay
from package_paths import output_folder, package_file, tool  # noqa: E402

SCENE = package_file("config", "scenes", "aspiration_tube.yaml")
ANNULUS_SCENE = package_file("config", "scenes", "aspiration_cube.yaml")


def run(simulate, sets, extra, scene=SCENE):
    cmd = [simulate, "--scene", scene, "--quiet"] + extra
    for s in sets:
        cmd += ["--set", s]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def read_vtu(path):
    root = ET.parse(path).getroot()
    arrays = {}
    for da in root.iter("DataArray"):
        arrays[da.get("Name") or "points"] = np.array(da.text.split(), dtype=float)
    return arrays["points"].reshape(-1, 3), arrays["displacement"].reshape(-1, 3)


def mid_cut_profile(points, disp, size=0.015):
    top = np.abs(points[:, 2] - size) < 1e-9
    cut = top & (np.abs(points[:, 1] - size / 2) < 1e-9)
    order = np.argsort(points[cut, 0])
    return points[cut, 0][order], disp[cut, 2][order]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--simulate", default=tool("simulate"))
    ap.add_argument("--out", default=output_folder())
    ap.add_argument("--steps", type=int, default=200, help="dynamic time steps")
    ap.add_argument("--dt", type=float, default=0.005, help="dynamic time step (s)")
    args = ap.parse_args()
    if not os.path.exists(args.simulate):
        sys.exit(f"{args.simulate} not found: build first (scripts/run.sh)")
    os.makedirs(args.out, exist_ok=True)

    cases = {"with capsule": "true", "without capsule": "false"}
    summary, profiles, histories = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, enabled in cases.items():
            vtu = os.path.join(tmp, "static.vtu")
            print(f"static, {label} ...", file=sys.stderr)
            res = run(args.simulate, [f"capsule.enabled={enabled}"], ["--vtu", vtu])
            profiles[label] = mid_cut_profile(*read_vtu(vtu))
            csv = os.path.join(tmp, "dynamic.csv")
            print(f"dynamic, {label}: {args.steps} steps of {args.dt} s ...", file=sys.stderr)
            dyn = run(args.simulate, [f"capsule.enabled={enabled}", "solver.mode=dynamic",
                                      f"solver.steps={args.steps}", f"solver.dt={args.dt}"], ["--csv", csv])
            data = np.genfromtxt(csv, delimiter=",", names=True)
            histories[label] = (np.concatenate([[0.0], data["time"]]),
                                np.concatenate([[0.0], data["centre_uz"]]))
            summary[label] = {
                "centre_displacement_mm": 1e3 * res["probes"]["centre"]["displacement"][2],
                "newton_iterations": res["newton_iterations"]["total"],
                "step_time_ms": res["step_time_ms"]["median"],
                "phase_time_ms": res["phase_time_ms_per_step"],
                "dynamic_final_centre_mm": 1e3 * dyn["probes"]["centre"]["displacement"][2],
                "dynamic_step_time_ms": dyn["step_time_ms"],
            }
    summary["ratio_without_over_with"] = (summary["without capsule"]["centre_displacement_mm"] /
                                          summary["with capsule"]["centre_displacement_mm"])
    annulus = {label: 1e3 * run(args.simulate, [f"capsule.enabled={enabled}"], [], ANNULUS_SCENE)
               ["probes"]["centre"]["displacement"][2] for label, enabled in cases.items()}
    summary["fixed annulus"] = {"centre_displacement_mm": annulus,
                                "ratio_without_over_with": annulus["without capsule"] / annulus["with capsule"]}

    def figure(curves, xscale, style, xlabel, ylabel, title, name, decorate=None):
        fig, ax = plt.subplots(figsize=(6, 4))
        for label, (x, uz) in curves.items():
            ax.plot(xscale * x, 1e3 * uz, label=label, **style)
        if decorate:
            decorate(ax)
        ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
        ax.legend()
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, name), dpi=100)

    figure(profiles, 1e3, {"marker": "o"}, "x along the mid cut y = 7.5 mm (mm)",
           "vertical displacement of the top face (mm)",
           f"Aspiration at -3 kPa, tube rim in frictional contact: ratio {summary['ratio_without_over_with']:.2f}",
           "aspiration_profile.png",
           lambda ax: ax.axvspan(2.5, 12.5, color="0.9", label="tube lumen (10 mm)"))
    figure(histories, 1.0, {}, "time (s)", "centre node displacement (mm)",
           f"Suction applied at t = 0, backward Euler, dt = {args.dt * 1e3:g} ms", "aspiration_time.png")

    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
