#!/usr/bin/python3
"""Registration judged against an independent truth (doc/registration.md#evaluation).

Writes the truth (scripts/make_truth_phantom.py: a 5 mm gmsh mesh of the phantom's anatomy,
parenchyma E = 15 kPa, the right triangular ligament attached, which the model does not know)
into BUILD/truth, then runs register_bench (depth camera, 10 frames per case) and writes into
OUT (default doc/):
  registration_grid.csv          4 surgical scenarios x model stiffness 0.5, 1, 2 x the truth's
                                 (30% visible, 1 mm depth noise at 25 cm), the springs alone
                                 (registration.estimate_hidden_loads false), as every run below
                                 but the hidden loads' ones
  registration_grid_targets.csv  every target's error and covariance of those cases
  registration_grid_estimated.csv the same cases with the tissue's stiffness estimated from the
                                 clouds (registration.{min,max}_tissue_stiffness_factor 0.25, 4)
  registration_grid_stiffen.csv  the same, the clouds allowed to stiffen the model only (1, 4)
  registration_grid_hidden_loads.csv the same cases with the hidden loads estimated (the
                                 scene's default)
  registration_sweep_hidden_loads.csv  the lift and the breathing, model 2x too soft and too
                                 stiff, over depth noise and visible fraction, the stiffness
                                 fixed (hidden_load_n 0) and with the hidden loads estimated
  registration_sweep.csv         the lift, model 2x too stiff: visible fraction and depth noise
  registration_crime.csv         the same sweep against the model's own lift (the inverse crime)
  registration_sweep_estimated.csv  the depth-noise sweep with the stiffness estimated
  registration_tre_visible.png   TRE (mean, p95) against visible fraction, truth and crime
  registration_tre_noise.png     TRE against depth noise, truth and crime
  registration_tre_stiffness.png TRE p95 per scenario against the model's stiffness error,
                                 fixed and estimated
  registration_tre_hidden_loads.png  the same, fixed and with the hidden loads estimated
then prints the Markdown tables of doc/registration.md and the ellipsoids' calibration.
Pin it: taskset -c 0 /usr/bin/python3 scripts/registration_figures.py   (about 40 min)
  --quick   2 frames, the lift only, one case per sweep (the smoke run)
"""
import argparse
import csv
import io
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(REPO, "build/ws/devel/lib/liver_sim/register_bench")
SCENE = os.path.join(REPO, "config/scenes/liver_phantom.yaml")
TRUTH_STIFFNESS = 0.5  # truth E over the model's (make_truth_phantom.py --stiffness-ratio)
SCENARIOS = ["lift", "press", "breathing", "pneumoperitoneum"]
SPRINGS = ["--set", "registration.estimate_hidden_loads=false"]
ESTIMATE = SPRINGS + ["--set", "registration.min_tissue_stiffness_factor=0.25", "--set", "registration.max_tissue_stiffness_factor=4"]
STIFFEN = SPRINGS + ["--set", "registration.min_tissue_stiffness_factor=1", "--set", "registration.max_tissue_stiffness_factor=4"]
HIDDEN = []  # the scene's default


def fmt(values):
    return ",".join(f"{v:g}" for v in values)


def bench(args, extra, targets_csv=None):
    cmd = [args.bench, "--scene", SCENE, "--frames", str(args.frames), "--quiet"] + extra
    if targets_csv:
        cmd += ["--targets-csv", targets_csv]
    res = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
    if res.returncode != 0:
        sys.exit(f"registration_figures: register_bench failed (exit {res.returncode}): {' '.join(cmd)}")
    return list(csv.DictReader(io.StringIO(res.stdout)))


def write(rows, path):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)


def plot_sweep(truth, crime, key, scale, xlabel, path):
    fig, ax = plt.subplots(figsize=(5, 3.6))
    for rows, label, colour in ((truth, "independent truth", "C3"), (crime, "inverse crime", "C0")):
        x = [scale * float(r[key]) for r in rows]
        ax.plot(x, [float(r["tre_mean_mm"]) for r in rows], "o-", color=colour, label=f"{label}: mean")
        ax.plot(x, [float(r["tre_p95_mm"]) for r in rows], "s--", color=colour, mfc="none", label=f"{label}: p95")
    ax.axhline(3.0, color="grey", lw=0.8, ls=":")
    ax.axhline(5.0, color="grey", lw=0.8, ls="-.")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("TRE (mm)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_stiffness(grid, fixed, path, label):
    fig, ax = plt.subplots(figsize=(5, 3.6))
    for k, s in enumerate(SCENARIOS):
        for rows, style, how in ((grid, "o-", label), (fixed, "s--", "fixed")):
            rows = [r for r in rows if r["scenario"] == s]
            if rows:
                ax.plot([float(r["stiffness_ratio"]) for r in rows], [float(r["tre_p95_mm"]) for r in rows], style,
                        color=f"C{k}", mfc="none" if how == "fixed" else None, label=f"{s}, {how}")
    ax.set_xscale("log", base=2)
    ax.axhline(3.0, color="grey", lw=0.8, ls=":")
    ax.axhline(5.0, color="grey", lw=0.8, ls="-.")
    ax.set_xlabel("model stiffness / truth stiffness (before registration)")
    ax.set_ylabel("TRE p95 (mm)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def table(rows, first):
    print(f"| {first} | TRE mean | p95 | max | tumour mean | bifurcation mean | unregistered mean | inside 95% | stiffness found | cloud CPU (median) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        head = {"grid": f"{r['scenario']}, model x{float(r['stiffness_ratio']):g}",
                "visible": f"{100 * float(r['visible_fraction']):.0f}% visible, {1e3 * float(r['noise_m']):g} mm",
                }[first] if first in ("grid", "visible") else first
        print(f"| {head} | {float(r['tre_mean_mm']):.2f} mm | {float(r['tre_p95_mm']):.2f} mm | {float(r['tre_max_mm']):.2f} mm "
              f"| {float(r['tumour_mean_mm']):.2f} mm | {float(r['bifurcation_mean_mm']):.2f} mm "
              f"| {float(r['tre_unregistered_mean_mm']):.2f} mm | {100 * float(r['inside_95']):.0f}% "
              f"| {float(r['stiffness_ratio']) * float(r['tissue_factor']):.2f} | {float(r['frame_cpu_median_ms']):.0f} ms |")


def compare(grid, fixed, label="estimated", sweep=False):
    print(f"| case | fixed: TRE mean | p95 | {label}: TRE mean | p95 | max | stiffness found | hidden loads | inside 95% |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for a, b in zip(fixed, grid):
        view = f", {100 * float(a['visible_fraction']):.0f}% visible, {1e3 * float(a['noise_m']):g} mm" if sweep else ""
        print(f"| {a['scenario']}, model x{float(a['stiffness_ratio']):g}{view} | {float(a['tre_mean_mm']):.2f} mm "
              f"| {float(a['tre_p95_mm']):.2f} mm | {float(b['tre_mean_mm']):.2f} mm | {float(b['tre_p95_mm']):.2f} mm "
              f"| {float(b['tre_max_mm']):.2f} mm | {float(b['stiffness_ratio']) * float(b['tissue_factor']):.2f} "
              f"| {float(b['hidden_load_n']):.1f} N | {100 * float(b['inside_95']):.0f}% |")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--bench", default=BENCH)
    ap.add_argument("--build", default=os.path.join(REPO, "build"))
    ap.add_argument("--out", default=os.path.join(REPO, "doc"))
    ap.add_argument("--frames", type=int, default=10)
    args = ap.parse_args()
    if args.quick:
        args.frames = 2
    truth_dir = os.path.join(args.build, "truth")
    truth = os.path.join(truth_dir, "truth_phantom.yaml")
    if not os.path.exists(truth):
        subprocess.run([sys.executable, os.path.join(REPO, "scripts", "make_truth_phantom.py"), "--out", truth_dir,
                        "--stiffness-ratio", str(TRUTH_STIFFNESS)], check=True)
    scenarios = ["lift"] if args.quick else SCENARIOS
    model_scales = [TRUTH_STIFFNESS * r for r in ([2.0] if args.quick else [0.5, 1.0, 2.0])]
    visible = [0.3] if args.quick else [0.1, 0.2, 0.3, 0.4]
    noise = [1e-3] if args.quick else [0.5e-3, 1e-3, 2e-3, 4e-3]
    os.makedirs(args.out, exist_ok=True)

    grid = bench(args, ["--truth-scene", truth, "--scenario", ",".join(scenarios), "--stiffness", fmt(model_scales)]
                 + SPRINGS, os.path.join(args.out, "registration_grid_targets.csv"))
    write(grid, os.path.join(args.out, "registration_grid.csv"))
    estimated = bench(args, ["--truth-scene", truth, "--scenario", ",".join(scenarios), "--stiffness", fmt(model_scales)]
                      + ESTIMATE)
    write(estimated, os.path.join(args.out, "registration_grid_estimated.csv"))
    stiffened = bench(args, ["--truth-scene", truth, "--scenario", ",".join(scenarios), "--stiffness", fmt(model_scales)]
                      + STIFFEN)
    write(stiffened, os.path.join(args.out, "registration_grid_stiffen.csv"))
    hidden = bench(args, ["--truth-scene", truth, "--scenario", ",".join(scenarios), "--stiffness", fmt(model_scales)]
                   + HIDDEN)
    write(hidden, os.path.join(args.out, "registration_grid_hidden_loads.csv"))
    two = [f"{TRUTH_STIFFNESS * 2:g}"]
    wrong = fmt([TRUTH_STIFFNESS * 0.5, TRUTH_STIFFNESS * 2])
    sweep_h = []
    for extra in (SPRINGS, HIDDEN):  # the grid's 1 mm and 30% left out
        for axis, values in (("--noise", [v for v in noise if v != 1e-3]), ("--visible", [v for v in visible if v != 0.3])):
            if values:
                sweep_h += bench(args, ["--truth-scene", truth, "--scenario", "lift,breathing", "--stiffness", wrong,
                                        axis, fmt(values)] + extra)
    if sweep_h:
        write(sweep_h, os.path.join(args.out, "registration_sweep_hidden_loads.csv"))
    sweep_v = bench(args, ["--truth-scene", truth, "--stiffness", two[0], "--visible", fmt(visible)] + SPRINGS)
    sweep_n = bench(args, ["--truth-scene", truth, "--stiffness", two[0], "--noise", fmt(noise)] + SPRINGS)
    crime_v = bench(args, ["--visible", fmt(visible)] + SPRINGS)
    crime_n = bench(args, ["--noise", fmt(noise)] + SPRINGS)
    write(sweep_v + sweep_n, os.path.join(args.out, "registration_sweep.csv"))
    sweep_e = bench(args, ["--truth-scene", truth, "--stiffness", two[0], "--noise", fmt(noise)] + ESTIMATE)
    write(sweep_e, os.path.join(args.out, "registration_sweep_estimated.csv"))
    write(crime_v + crime_n, os.path.join(args.out, "registration_crime.csv"))
    plot_sweep(sweep_v, crime_v, "visible_fraction", 100, "visible surface (%)", os.path.join(args.out, "registration_tre_visible.png"))
    plot_sweep(sweep_n, crime_n, "noise_m", 1e3, "depth noise at 25 cm (mm)", os.path.join(args.out, "registration_tre_noise.png"))
    plot_stiffness(estimated, grid, os.path.join(args.out, "registration_tre_stiffness.png"), "estimated")
    plot_stiffness(hidden, grid, os.path.join(args.out, "registration_tre_hidden_loads.png"), "hidden loads")

    print("\nIndependent truth, 30% visible, 1 mm depth noise:\n")
    table(grid, "grid")
    print("\nThe same cases, the model's stiffness fixed and estimated:\n")
    compare(estimated, grid)
    print("\nThe same cases, the model's stiffness fixed and stiffened only:\n")
    compare(stiffened, grid)
    print("\nThe same cases, the model's stiffness fixed and with the hidden loads estimated:\n")
    compare(hidden, grid, "hidden loads")
    if sweep_h:
        half = len(sweep_h) // 2
        print("\nThe lift and the breathing over depth noise and visible fraction, fixed and with the hidden loads:\n")
        compare(sweep_h[half:], sweep_h[:half], "hidden loads", sweep=True)
    print("\nThe lift, model 2x too stiff, over depth noise, the stiffness estimated:\n")
    table(sweep_e, "visible")
    print("\nIndependent truth, lift, model 2x too stiff:\n")
    table(sweep_v + sweep_n, "visible")
    print("\nInverse crime (the model's own lift):\n")
    table(crime_v + crime_n, "visible")
    for name, rows in (("springs alone", grid), ("hidden loads", hidden)):
        inside = [float(r["inside_95"]) for r in rows]
        print(f"\nTargets inside their 95% ellipsoid over the grid, {name}: {100 * sum(inside) / len(inside):.1f}% "
              f"(per case {100 * min(inside):.0f}-{100 * max(inside):.0f}%)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
