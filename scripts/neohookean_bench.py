#!/usr/bin/python3
"""The phantom's model registered in one shot to truths of another law (doc/registration.md,
"Truths of another law"): makes the neo-Hookean cases (scripts/make_neohookean_truth.py) unless
they are there, runs register_insilico with the phantom's scene on each case's partial views
(1 mm sensor noise by default), and prints per case and view the TRE over the interior nodes
(mean, p95, max, the deepest 10%), the calibration of the targets' 95% ellipsoids and the best
rigid fit of all nodes (the floor of a rigid registration). One registration option, the soft
supports' stiffness (`support`), was chosen on the packing case: the retractor case is held out.
The rows are kept in OUT/<case>.csv.

usage: scripts/neohookean_bench.py [--out DIR] [--register-insilico PATH] [--scene FILE]
                                   [--case packing,retractor] [--noise M] [--repeats R]
"""
import argparse
import csv
import os
import subprocess
import sys

REPO = os.path.realpath(os.path.join(os.path.dirname(os.path.realpath(__file__)), ".."))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(REPO, "build", "neohookean"), help="the cases' folder (default build/neohookean)")
    ap.add_argument("--register-insilico", default=os.path.join(REPO, "build", "ws", "devel", "lib", "liver_sim", "register_insilico"),
                    help="the tool (default: the workspace's build)")
    ap.add_argument("--scene", default=os.path.join(REPO, "config", "scenes", "liver_phantom.yaml"),
                    help="the model (default: the phantom's scene, whose anatomy the cases share)")
    ap.add_argument("--case", default="packing,retractor", help="cases, comma-separated (default packing,retractor)")
    ap.add_argument("--noise", default="0.001", help="sensor noise, m per coordinate (default 0.001)")
    ap.add_argument("--repeats", default="1", help="clouds per view with other noise (default 1)")
    args = ap.parse_args()
    if not os.access(args.register_insilico, os.X_OK):
        ap.error(args.register_insilico + " is not there: build the workspace first (scripts/run.sh or scripts/test.sh), or give --register-insilico")
    cases = args.case.split(",")
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    from make_neohookean_truth import CASES
    if any(c not in CASES for c in cases):
        ap.error("--case: each of " + ", ".join(CASES))
    missing = [c for c in cases if not os.path.exists(os.path.join(args.out, c, "oracle.txt"))]
    if missing:
        subprocess.run([sys.executable, os.path.join(REPO, "scripts", "make_neohookean_truth.py"), "--out", args.out,
                        "--case", ",".join(missing)], check=True)
    print("| case | view | share of the surface | registration's rigid stage: mean | TRE mean | p95 | max | "
          "deepest 10% mean | inside 95% | d² median | processor time |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    oracles = []
    for case in cases:
        rows = os.path.join(args.out, case + ".csv")
        subprocess.run([args.register_insilico, "--scene", args.scene, "--data", os.path.join(args.out, case),
                        "--noise", args.noise, "--repeats", args.repeats, "--csv", rows], check=True)
        with open(rows) as f:
            for r in csv.DictReader(f):
                v = {k: float(x) for k, x in r.items() if k != "view"}
                print("| %s | %s #%d | %.0f%% | %.2f mm | %.2f mm | %.2f mm | %.2f mm | %.2f mm | %.1f%% | %.2f | %.2f s |" %
                      (case, r["view"], v["repeat"], 100 * v["fraction"], v["rigid_mean_mm"], v["tre_mean_mm"], v["tre_p95_mm"],
                       v["tre_max_mm"], v["deep_mean_mm"], 100 * v["all_inside_95"], v["all_d2_median"], v["cpu_ms"] / 1e3))
        with open(os.path.join(args.out, case, "oracle.txt")) as f:
            oracles.append(f.read().strip())
    print("\n".join(oracles))
    return 0


if __name__ == "__main__":
    sys.exit(main())
