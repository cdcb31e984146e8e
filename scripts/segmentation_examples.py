#!/usr/bin/python3
"""Inputs as segmentations give them, made from a tetrahedral liver mesh (default: the phantom),
for make_model's tests, examples and timings (nothing here is committed data):

  scripts/segmentation_examples.py stairs OUT.stl     a CT-like label (0.8 x 0.8 x 2.5 mm voxels,
        partial volume and noise, thresholded) exported as its voxels' faces: stair-steps, noise,
        non-manifold edges where voxels touch along an edge
  scripts/segmentation_examples.py crossing OUT.stl   the smooth surface (Loop level 2) with a
        fold 16 mm across: a local self-crossing
  scripts/segmentation_examples.py labelmap OUT.nii.gz|OUT.nrrd   the liver as label 1 on an
        OBLIQUE grid (rotated 25 deg about (1, 2, 3), spacing 0.9 x 0.8 x 1.6 mm); NIfTI with the
        sform and qform in RAS, NRRD in LPS

Options: --mesh FILE (metres), --seed N. Millimetres, LPS (the model frame).
"""
import argparse
import gzip
import math
import os
import struct
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from liver_surface import loop_subdivide, read_boundary, write_stl  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def inside_grid(V, F, origin, axes, dims):
    """Inside (bool, dims) of the closed surface V, F at the centres origin + axes @ (i, j, k):
    crossings of rays along k counted per (i, j) column (parity)."""
    P = (V - origin) @ np.linalg.inv(axes).T  # index coordinates
    tri = P[F]
    inside = np.zeros(dims, dtype=bool)
    crossings = {}
    for t in tri:
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        i0, i1 = max(0, math.ceil(a.min())), min(dims[0] - 1, math.floor(a.max()))
        j0, j1 = max(0, math.ceil(b.min())), min(dims[1] - 1, math.floor(b.max()))
        if i0 > i1 or j0 > j1:
            continue
        I, J = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1), indexing="ij")
        det = (a[1] - a[0]) * (b[2] - b[0]) - (a[2] - a[0]) * (b[1] - b[0])
        if det == 0:
            continue
        # Barycentric coordinates of the column centres, offset by a hair to avoid ties.
        x, y = I + 1e-7, J + 2.3e-7
        l1 = ((x - a[0]) * (b[2] - b[0]) - (a[2] - a[0]) * (y - b[0])) / det
        l2 = ((a[1] - a[0]) * (y - b[0]) - (x - a[0]) * (b[1] - b[0])) / det
        hit = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
        depth = c[0] + l1 * (c[1] - c[0]) + l2 * (c[2] - c[0])
        for i, j, d in zip(I[hit], J[hit], depth[hit]):
            crossings.setdefault((i, j), []).append(d)
    k = np.arange(dims[2])
    for (i, j), ds in crossings.items():
        ds = np.sort(ds)
        inside[i, j] = (np.searchsorted(ds, k) % 2) == 1
    return inside


def phantom_boundary(mesh, levels=0):
    V, F = read_boundary(mesh)
    for _ in range(levels):
        V, F = loop_subdivide(V, F)
    return V * 1000.0, F  # mm


def grid_around(V, axes, pad):
    """Origin and dims of a grid with step `axes` covering V with `pad` voxels around."""
    P = V @ np.linalg.inv(axes).T
    lo = np.floor(P.min(0)) - pad
    dims = (np.ceil(P.max(0)) + pad - lo + 1).astype(int)
    return axes @ lo, dims


def stairs(args):
    V, F = phantom_boundary(args.mesh)
    axes = np.diag([0.8, 0.8, 2.5])
    origin, dims = grid_around(V, axes, 3)
    inside = inside_grid(V, F, origin, axes, dims).astype(float)
    # CT-like: partial volume (a box average over 3 x 3 in-plane voxels) and noise, thresholded.
    rng = np.random.default_rng(args.seed)
    blurred = sum(np.roll(np.roll(inside, di, 0), dj, 1) for di in (-1, 0, 1) for dj in (-1, 0, 1)) / 9
    label = (blurred + rng.normal(0, 0.15, blurred.shape)) > 0.5
    # Faces between an inside and an outside voxel, on the voxels' corner lattice, facing out.
    quads = []
    L = np.pad(label, 1)
    for axis in range(3):
        diff = np.diff(L.astype(np.int8), axis=axis)
        for sign in (-1, 1):  # -1: inside then outside along +axis (face normal +axis)
            idx = np.argwhere(diff == sign)
            for p in idx:
                corner = p.astype(float) - 1  # voxel p (unpadded), then the face toward p + 1
                corner[axis] += 0.5
                u, w = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
                base = corner - 0.5 * u - 0.5 * w
                q = [base, base + u, base + u + w, base + w]
                if sign == 1:
                    q = q[::-1]
                quads.append(q)
    Q = np.array(quads)  # index units
    P = Q.reshape(-1, 3) @ axes.T + origin
    keys, inv = np.unique(np.round(P, 6), axis=0, return_inverse=True)
    idx = inv.reshape(-1, 4)
    F2 = np.concatenate([idx[:, [0, 1, 2]], idx[:, [0, 2, 3]]])
    write_stl(args.out, keys, F2)
    print("%s: %d triangles (stair-stepped, noisy), voxels %s" % (args.out, len(F2), list(dims)))


def crossing(args):
    V, F = phantom_boundary(args.mesh, levels=2)
    n = np.zeros_like(V)
    face_n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    for k in range(3):
        np.add.at(n, F[:, k], face_n)
    n /= np.linalg.norm(n, axis=1)[:, None]
    # A fold, as an over-smoothed segmentation makes: the patch within 8 mm of a vertex is
    # mirrored along a tangent t, fully within 4 mm, the ring between squeezed through zero
    # width, so that its triangles cross their neighbours around one spot.
    rng = np.random.default_rng(args.seed)
    v = int(rng.integers(len(V)))
    t = np.cross(n[v], [0.0, 0.0, 1.0] if abs(n[v][2]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    dist = np.linalg.norm(V - V[v], axis=1)
    w = np.clip((8.0 - dist) / 4.0, 0, 1)
    V = V - 2 * np.outer(w * ((V - V[v]) @ t), t)
    write_stl(args.out, V, F)
    print("%s: %d triangles, folded within 8 mm of (%.1f, %.1f, %.1f) mm" % (args.out, len(F), *V[v]))


def rotation(axis, degrees):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(degrees)
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def labelmap(args):
    V, F = phantom_boundary(args.mesh)
    R = rotation([1, 2, 3], 25)
    axes = R @ np.diag([0.9, 0.8, 1.6])  # LPS, mm
    origin, dims = grid_around(V, axes, 4)
    label = inside_grid(V, F, origin, axes, dims).astype(np.uint8)
    data = label.transpose(2, 1, 0).tobytes()  # i fastest
    if args.out.endswith(".nrrd"):
        fmt = lambda v: "(%s)" % ",".join("%.17g" % x for x in v)  # noqa: E731
        header = ("NRRD0004\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\nsizes: %d %d %d\n"
                  "space directions: %s %s %s\nkinds: domain domain domain\nencoding: gzip\nspace origin: %s\n"
                  "Segment0_Name:=liver\nSegment0_LabelValue:=1\n\n"
                  % (*dims, fmt(axes[:, 0]), fmt(axes[:, 1]), fmt(axes[:, 2]), fmt(origin)))
        with open(args.out, "wb") as f:
            f.write(header.encode() + gzip.compress(data, mtime=0))
    else:
        flip = np.diag([-1.0, -1.0, 1.0])  # LPS -> RAS
        A, o = flip @ axes, flip @ origin
        hdr = bytearray(352)
        struct.pack_into("<i", hdr, 0, 348)
        struct.pack_into("<8h", hdr, 40, 3, *dims, 1, 1, 1, 1)
        struct.pack_into("<hh", hdr, 70, 2, 8)  # uint8
        spacing = np.linalg.norm(A, axis=0)
        Rr = A / spacing
        qfac = 1.0 if np.linalg.det(Rr) > 0 else -1.0
        Rr[:, 2] *= qfac
        struct.pack_into("<8f", hdr, 76, qfac, *spacing, 0, 0, 0, 0)
        struct.pack_into("<f", hdr, 108, 352.0)
        struct.pack_into("<ff", hdr, 112, 1.0, 0.0)
        hdr[123] = 2  # mm
        w = math.sqrt(max(0.0, 1 + np.trace(Rr))) / 2
        b, c, d = (Rr[2, 1] - Rr[1, 2]) / (4 * w), (Rr[0, 2] - Rr[2, 0]) / (4 * w), (Rr[1, 0] - Rr[0, 1]) / (4 * w)
        struct.pack_into("<hh", hdr, 252, 1, 1)  # qform and sform: scanner
        struct.pack_into("<6f", hdr, 256, b, c, d, *o)
        for r in range(3):
            struct.pack_into("<4f", hdr, 280 + 16 * r, *A[r], o[r])
        hdr[344:348] = b"n+1\0"
        out = bytes(hdr) + data
        with open(args.out, "wb") as f:
            f.write(gzip.compress(out, mtime=0) if args.out.endswith(".gz") else out)
    print("%s: %s voxels, %d labelled 1, oblique direction" % (args.out, list(dims), int(label.sum())))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kind", choices=["stairs", "crossing", "labelmap"])
    ap.add_argument("out")
    ap.add_argument("--mesh", default=os.path.join(REPO, "config", "phantom", "liver_phantom.msh"))
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    {"stairs": stairs, "crossing": crossing, "labelmap": labelmap}[args.kind](args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
