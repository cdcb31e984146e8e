#!/usr/bin/python3
"""Writes the closed boundary surface of a tetrahedral liver mesh as a segmentation tool would:
binary STL, in millimetres by default, optionally in RAS, optionally Loop-subdivided to the
triangle counts of a segmented surface (each level multiplies the count by 4 and smooths).

  scripts/liver_surface.py MESH OUT.stl [--scale S] [--levels K] [--frame LPS|RAS]

MESH: any mesh gmsh reads (the phantom config/phantom/liver_phantom.msh, in metres; the SOFA
livers in config/sofa_liver, legacy Gmsh in decimetres for liver2). --scale: file unit
-> output unit (default 1000: metres to millimetres). --frame RAS negates x and y (the mesh is
taken as LPS, the model frame of make_model). The output is deterministic: the example in
doc/patient_model.md and the timing runs generate their inputs with it instead of committing
large files.
"""
import argparse
import math
import struct
import sys

import gmsh
import numpy as np


def read_boundary(path):
    """Boundary triangles of the tetrahedra of `path`, oriented outward."""
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    tags, xyz, _ = gmsh.model.mesh.getNodes()
    _, nodes = gmsh.model.mesh.getElementsByType(4)
    gmsh.finalize()
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    X = xyz.reshape(-1, 3)
    T = index[nodes.astype(np.int64)].reshape(-1, 4)
    d = np.einsum("ij,ij->i", np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]), X[T[:, 3]] - X[T[:, 0]])
    T[d < 0] = T[d < 0][:, [0, 2, 1, 3]]
    # Faces with outward normals for a positively oriented tetrahedron (0,1,2,3).
    faces = np.concatenate([T[:, [1, 2, 3]], T[:, [0, 3, 2]], T[:, [0, 1, 3]], T[:, [0, 2, 1]]])
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    F = faces[counts[inverse.ravel()] == 1]
    used = np.unique(F)
    remap = np.full(len(X), -1)
    remap[used] = np.arange(len(used))
    return X[used], remap[F]


def loop_subdivide(V, F):
    """One level of Loop subdivision of a closed triangle surface."""
    n = len(V)
    edges = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    opposite = np.concatenate([F[:, 2], F[:, 0], F[:, 1]])
    key = np.sort(edges, axis=1)
    unique, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    # Odd (edge) vertices: 3/8 of the ends plus 1/8 of both opposite vertices.
    odd = 0.375 * (V[unique[:, 0]] + V[unique[:, 1]])
    np.add.at(odd, inverse, 0.125 * V[opposite])
    # Even vertices: (1 - k beta) v + beta * (sum of neighbours).
    valence = np.bincount(unique.ravel(), minlength=n).astype(float)
    beta = (0.625 - (0.375 + 0.25 * np.cos(2 * math.pi / valence)) ** 2) / valence
    ring = np.zeros_like(V)
    np.add.at(ring, unique[:, 0], V[unique[:, 1]])
    np.add.at(ring, unique[:, 1], V[unique[:, 0]])
    even = (1 - valence * beta)[:, None] * V + beta[:, None] * ring
    m = n + inverse.reshape(3, -1).T  # midpoints of edges (0,1), (1,2), (2,0) of each face
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    F = np.concatenate([np.stack([a, m[:, 0], m[:, 2]], 1), np.stack([m[:, 0], b, m[:, 1]], 1),
                        np.stack([m[:, 2], m[:, 1], c], 1), m])
    return np.vstack([even, odd]), F


def write_stl(path, V, F):
    tri = V[F]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    record = np.zeros(len(F), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["n"] = normal
    record["v"] = tri
    with open(path, "wb") as f:
        f.write(b"liver_sim liver_surface.py".ljust(80, b" "))
        f.write(struct.pack("<I", len(F)))
        f.write(record.tobytes())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh")
    ap.add_argument("out")
    ap.add_argument("--scale", type=float, default=1000.0, help="file unit -> output unit (default 1000)")
    ap.add_argument("--levels", type=int, default=0, help="Loop subdivision levels, >= 0 (default 0)")
    ap.add_argument("--frame", choices=["LPS", "RAS"], default="LPS")
    args = ap.parse_args()
    V, F = read_boundary(args.mesh)
    for _ in range(args.levels):
        V, F = loop_subdivide(V, F)
    V = V * args.scale
    if args.frame == "RAS":
        V = V * np.array([-1.0, -1.0, 1.0])
    write_stl(args.out, V, F)
    print("%s: %d triangles, %d vertices" % (args.out, len(F), len(V)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
