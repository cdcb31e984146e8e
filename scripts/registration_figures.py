#!/usr/bin/python3
"""Target registration error of surface registration against noise and visible surface.

Runs the `register_bench` tool on the liver phantom (ground truth: the model lifted by a known
force under the right lobe, ramped over the frames; each frame a partial, noisy cloud with
outliers is registered) for outlier fractions 0 and 20%, writes doc/registration.csv and draws
  doc/registration_tre_noise.png    TRE against cloud noise (visible 30%)
  doc/registration_tre_visible.png  TRE against the visible fraction of the surface (noise 1 mm)
then prints a Markdown table (TRE, surface error, time per frame).
Pin it: taskset -c 0 /usr/bin/python3 scripts/registration_figures.py
  --quick   2 frames, one noise value and two visible fractions (the smoke run)
  --bench PATH, --scene PATH, --out DIR (default doc/), --frames N (default 10),
  --repeats R (default 3: each case registered R times with other random clouds, averaged)
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
OUTLIERS = [0.0, 0.2]
TARGET_MM = 2.0


def sweeps(quick):
    """(name, noise list in m, visible list) per register_bench call."""
    if quick:
        return [("noise", [1e-3], [0.3]), ("visible", [1e-3], [0.1, 0.3])]
    return [("noise", [0.0, 0.25e-3, 0.5e-3, 1e-3, 2e-3], [0.3]), ("visible", [1e-3], [0.1, 0.2, 0.3, 0.4])]


def fmt(values):
    return ",".join(f"{v:g}" for v in values)


def run(bench, scene, frames, repeats, noise, visible):
    cmd = [bench, "--scene", scene, "--frames", str(frames), "--repeats", str(repeats), "--noise", fmt(noise),
           "--visible", fmt(visible),
           "--outliers", fmt(OUTLIERS)]
    # stderr passes through: the ground truth alone takes ~15 s, its progress is worth seeing.
    res = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
    if res.returncode != 0:
        sys.exit(f"registration_figures: register_bench failed (exit {res.returncode}): {' '.join(cmd)}")
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    if len(rows) != len(noise) * len(visible) * len(OUTLIERS):
        sys.exit(f"registration_figures: register_bench wrote {len(rows)} rows, expected "
                 f"{len(noise) * len(visible) * len(OUTLIERS)}: {' '.join(cmd)}")
    return rows


def plot(rows, x_key, x_scale, xlabel, title, path):
    fig, ax = plt.subplots(figsize=(6, 4.4))
    for i, outliers in enumerate(OUTLIERS):
        pts = sorted((x_scale * float(r[x_key]), float(r["tre_mean_mm"]), float(r["tre_max_mm"]))
                     for r in rows if float(r["outlier_fraction"]) == outliers)
        x, mean, peak = zip(*pts)
        colour = f"C{i}"
        ax.plot(x, mean, "o-", color=colour, label=f"outliers {100 * outliers:g}%: mean")
        ax.plot(x, peak, "s--", color=colour, mfc="none", label=f"outliers {100 * outliers:g}%: max")
    # The unregistered error depends only on the ground truth, so it is the same in every row.
    unregistered = float(rows[0]["tre_unregistered_mean_mm"])
    # The reference lines are labelled in place, keeping the legend (below the axes) off the data.
    for y, style, text in [(unregistered, dict(color="0.5", lw=1.2), f"unregistered mean {unregistered:.2f} mm"),
                           (TARGET_MM, dict(color="k", ls=":", lw=1), f"target {TARGET_MM:g} mm")]:
        ax.axhline(y, **style)
        ax.text(0.99, y, text, transform=ax.get_yaxis_transform(), ha="right", va="bottom", fontsize=8,
                color=style["color"])
    ax.set(xlabel=xlabel, ylabel="target registration error (mm)", title=title)
    # Headroom so the reference labels stay inside the axes when all the data lie below them.
    ax.set_ylim(0, max(ax.get_ylim()[1], 1.12 * max(unregistered, TARGET_MM)))
    ax.legend(fontsize=8, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.16))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def table(rows):
    lines = ["| noise mm | visible % | outliers % | TRE mean mm | TRE max mm | unregistered mean mm | "
             "surface error mm | frame median ms | frames/s |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        median = float(r["frame_median_ms"])
        lines.append(f"| {1e3 * float(r['noise_m']):g} | {100 * float(r['visible_fraction']):.1f} | "
                     f"{100 * float(r['outlier_fraction']):g} | {float(r['tre_mean_mm']):.2f} | "
                     f"{float(r['tre_max_mm']):.2f} | {float(r['tre_unregistered_mean_mm']):.2f} | "
                     f"{float(r['surface_error_mm']):.2f} | {median:.1f} | {1000 / median:.1f} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--bench", default=BENCH)
    ap.add_argument("--scene", default=SCENE)
    ap.add_argument("--out", default=os.path.join(REPO, "doc"))
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    if not os.access(args.bench, os.X_OK):
        sys.exit(f"registration_figures: {args.bench} not found or not executable: build first (scripts/run.sh)")
    frames = 2 if args.quick else args.frames
    repeats = 1 if args.quick else args.repeats

    rows, by_sweep = [], {}
    for name, noise, visible in sweeps(args.quick):
        print(f"registration: sweep {name}: noise {fmt(1e3 * n for n in noise)} mm, visible {fmt(visible)}, "
              f"outliers {fmt(OUTLIERS)}, {frames} frames ...", file=sys.stderr, flush=True)
        by_sweep[name] = run(args.bench, args.scene, frames, repeats, noise, visible)
        rows += [{"sweep": name, **r} for r in by_sweep[name]]
    diverged = [r for r in rows if int(r["diverged"]) > 0]
    for r in diverged:
        print(f"registration: {r['sweep']} sweep, noise {r['noise_m']} m, visible {r['visible_request']}, "
              f"outliers {r['outlier_fraction']}: {r['diverged']} of {r['frames']} frames diverged", file=sys.stderr)

    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "registration.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    plot(by_sweep["noise"], "noise_m", 1e3, "cloud noise, standard deviation (mm)",
         "TRE against cloud noise (30% of the surface visible)", os.path.join(args.out, "registration_tre_noise.png"))
    plot(by_sweep["visible"], "visible_fraction", 100, "visible fraction of the surface (%)",
         "TRE against visible surface (noise 1 mm)", os.path.join(args.out, "registration_tre_visible.png"))

    print(table(rows))
    print(f"\ndiverged frames: {sum(int(r['diverged']) for r in rows)} in {len(diverged)} of {len(rows)} rows")


if __name__ == "__main__":
    main()
