#!/usr/bin/python3
"""Per-step time against the number of active instrument contacts (doc/contact.md).

Dynamic steps (dt 10 ms) on the aspiration cube (capsule on, no suction) and on the liver phantom
(capsule and vessels, no gravity), with a sphere probe held against the top surface at sizes chosen to
touch about 0, 10 and 100 surface nodes. Each run first settles (10 steps), then the probe
follows a slow press (0.05 mm per step) for 20 timed steps: every step has new contacts to
resolve. Prints a Markdown table: contacts, median step time, contact phase, Gauss-Seidel sweeps
and Newton iterations per step. Pin it: taskset -c 0 scripts/contact_timing.py
"""
import json
import os
import subprocess
import sys
import tempfile

import yaml

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))  # package_paths, also through catkin's relay
from package_paths import package_file, tool  # noqa: E402

SIMULATE = tool("simulate")

# (scene, probe tip xy, top surface z at that xy, [(label, radius, depth)])
CASES = [
    ("aspiration_cube.yaml", (0.0075, 0.0075), 0.015,
     [("0", 0.003, -0.01), ("~10", 0.004, 0.0012), ("~100", 0.05, 0.0006)]),
    ("liver_phantom.yaml", (-0.05, -0.02), 0.039,
     [("0", 0.008, -0.02), ("~10", 0.02, 0.006), ("~100", 0.15, 0.012)]),
]


def scene_for(name, xy, top, radius, depth, steps):
    base = package_file("config", "scenes")
    with open(os.path.join(base, name)) as f:
        s = yaml.safe_load(f)
    if "file" in s["mesh"]:
        s["mesh"]["file"] = os.path.join(base, s["mesh"]["file"])
    for v in s.get("vessels", []):
        v["file"] = os.path.join(base, v["file"])
    s["loads"] = []  # the probe alone deforms the organ: its contacts stay where they are set
    s["solver"].update({"mode": "dynamic", "dt": 0.01, "steps": steps, "tolerance": 1e-6, "rayleigh_stiffness": 0.02})
    centre = top + radius - depth
    s["instruments"] = [{"name": "probe", "type": "probe", "radius": radius, "trajectory": [
        {"t": 0.0, "position": [xy[0], xy[1], centre + 0.0005]},
        {"t": 0.1, "position": [xy[0], xy[1], centre + 0.0005]},
        {"t": 0.3, "position": [xy[0], xy[1], centre - 0.0005]}]}]
    s["contact"] = {"friction": 0.3}
    return s


def run(scene):
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
        yaml.safe_dump(scene, f)
    try:
        out = subprocess.run([SIMULATE, "--scene", f.name, "--quiet"], capture_output=True, text=True)
        return json.loads(out.stdout)
    finally:
        os.unlink(f.name)


def main():
    if not os.path.exists(SIMULATE):
        sys.exit(f"{SIMULATE} not found: build first (scripts/run.sh), or source a workspace that has liver_sim")
    print("| mesh | probe radius | contacts | step median (ms) | contact phase (ms/step) | Gauss-Seidel sweeps/step | Newton iterations/step | status |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    for name, xy, top, probes in CASES:
        for label, radius, depth in probes:
            settle = run(scene_for(name, xy, top, radius, depth, 10))
            full = run(scene_for(name, xy, top, radius, depth, 30))
            steps = 20
            def per_step(key):
                return (full[key] - settle[key]) / steps
            ms = full["phase_time_ms_per_step"]
            # Medians of the whole run are dominated by the 20 timed steps (2/3 of them).
            print(f"| {name} ({full['tetrahedra']} tets) | {radius * 1e3:g} mm | {full['contact']['max_contacts']} | "
                  f"{full['step_time_ms']['median']:.1f} | {ms['contact']:.1f} | "
                  f"{(full['contact']['gauss_seidel_sweeps'] - settle['contact']['gauss_seidel_sweeps']) / steps:.1f} | "
                  f"{(full['newton_iterations']['total'] - settle['newton_iterations']['total']) / steps:.1f} | {full['status']} |",
                  flush=True)


if __name__ == "__main__":
    main()
