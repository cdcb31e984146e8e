#!/usr/bin/python3
"""Writes a ground-truth liver for registration benchmarks that the registered model did not
make (doc/registration.md#an-independent-truth):

  OUT/truth_phantom.msh   the phantom's anatomy (scripts/make_phantom.py: the same two lobes and
                          flattened inferior face) meshed again by gmsh, finer: 5 mm elements,
                          about 61,000 tetrahedra against the model's 11,288 (a different mesh,
                          not a refinement of the model's: no node or face is shared)
  OUT/truth_phantom.yaml  its scene: a different material (parenchyma E = RATIO x 30 kPa,
                          nu = 0.47; the ex-vivo capsule, 8.22 MPa x 20 um), the model's two
                          attachments plus one the model does not have (the right triangular
                          ligament unless --unknown-support says otherwise), the same vessel
                          trees (config/phantom) and tumour points, so that the truth's targets
                          are the same material points embedded in its own tetrahedra

The surgical loads (a retractor's lift, an instrument's pressure, the diaphragm, the
pneumoperitoneum) are applied by register_bench (src/testing/scenarios.h), ramped over the
frames. Deterministic (gmsh single-threaded, fixed seed): the same arguments give the same files.
The mesh is 3 MB: write it into the build tree, not the repository.

usage: make_truth_phantom.py --out DIR [--stiffness-ratio RATIO] [--unknown-support NAME] [--mesh-size M]
"""
import argparse
import os
import sys

import make_phantom

PHANTOM = os.path.realpath(os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "config", "phantom"))
MODEL_YOUNG_MODULUS = 30000.0  # Pa, config/scenes/liver_phantom.yaml
# The attachment the model is not given, in the phantom's LPS frame (the right lobe at -x).
UNKNOWN_SUPPORTS = {
    "right_triangular": "  - sphere: {center: [-0.105, 0.035, 0.025], radius: 0.02}        # right triangular ligament: unknown to the model\n",
    "hepatorenal": "  - sphere: {center: [-0.08, 0.05, -0.03], radius: 0.02}           # hepatorenal ligament: unknown to the model\n",
    "none": "",
}

SCENE = """\
# Ground truth for register_bench, written by scripts/make_truth_phantom.py; not the model.
mesh: {{file: truth_phantom.msh}}          # {tets} tetrahedra, {size:g} m elements
parenchyma: {{young_modulus: {young:g}, poisson_ratio: 0.47, density: 1060, rotation: polar}}
capsule: {{enabled: true, young_modulus: 8.22e6, thickness: 20.0e-6, poisson_ratio: 0.45}}
vessels:
  - {{name: portal, file: {phantom}/portal.vtk, young_modulus: 0.62e6, poisson_ratio: 0.45}}
  - {{name: hepatic, file: {phantom}/hepatic.vtk, young_modulus: 0.62e6, poisson_ratio: 0.45}}
fixed:
  - sphere: {{center: [0.0, 0.07, 0.03], radius: 0.03}}             # bare area and vena cava (as the model)
  - box: {{min: [0.025, -0.08, 0.02], max: [0.035, 0.0, 0.08]}}     # falciform ligament (as the model)
{unknown}loads:
  - {{type: gravity, acceleration: [0, 0, -9.81]}}
solver: {{mode: static, strategy: newton_krylov, max_iterations: 100, tolerance: 1.0e-9}}
probes:                     # the model's tumour points (config/scenes/liver_phantom.yaml)
  - {{name: tumour_centre, point: [-0.050, -0.020, 0.005]}}
  - {{name: tumour_x+, point: [-0.038, -0.020, 0.005]}}
  - {{name: tumour_x-, point: [-0.062, -0.020, 0.005]}}
  - {{name: tumour_y+, point: [-0.050, -0.008, 0.005]}}
  - {{name: tumour_y-, point: [-0.050, -0.032, 0.005]}}
  - {{name: tumour_z+, point: [-0.050, -0.020, 0.017]}}
  - {{name: tumour_z-, point: [-0.050, -0.020, -0.007]}}
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="output folder (e.g. build/truth)")
    ap.add_argument("--stiffness-ratio", type=float, default=0.5,
                    help="truth parenchyma E over the model's 30 kPa, in [0.1, 10] (default 0.5: the model is 2x too stiff)")
    ap.add_argument("--unknown-support", choices=sorted(UNKNOWN_SUPPORTS), default="right_triangular",
                    help="the attachment the model does not know (default right_triangular)")
    ap.add_argument("--mesh-size", type=float, default=0.005,
                    help="m, target element edge, in [0.003, 0.009] (default 0.005: 5.4x the model's tetrahedra)")
    args = ap.parse_args()
    if not 0.1 <= args.stiffness_ratio <= 10:
        sys.exit("make_truth_phantom: --stiffness-ratio must be in [0.1, 10]")
    if not 0.003 <= args.mesh_size <= 0.009:
        sys.exit("make_truth_phantom: --mesh-size must be in [0.003, 0.009] m")
    os.makedirs(args.out, exist_ok=True)
    tets = make_phantom.make_mesh(os.path.join(args.out, "truth_phantom.msh"), args.mesh_size)
    with open(os.path.join(args.out, "truth_phantom.yaml"), "w") as f:
        f.write(SCENE.format(tets=tets, size=args.mesh_size, young=args.stiffness_ratio * MODEL_YOUNG_MODULUS,
                             phantom=PHANTOM, unknown=UNKNOWN_SUPPORTS[args.unknown_support]))
    print("truth_phantom.msh: %d tetrahedra; truth_phantom.yaml: E = %g Pa" %
          (tets, args.stiffness_ratio * MODEL_YOUNG_MODULUS))
    return 0


if __name__ == "__main__":
    sys.exit(main())
