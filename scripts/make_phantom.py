#!/usr/bin/python3
"""Generates the vascularised liver phantom (SI units, metres) reproducibly:

  config/phantom/liver_phantom.msh  tetrahedral mesh (Gmsh 2.2 ASCII), two fused ellipsoidal
                                    lobes with a flattened inferior face
  config/phantom/portal.vtk         portal vein tree (legacy VTK polydata: radius, wall_thickness)
  config/phantom/hepatic.vtk        hepatic vein tree

The files are in the package's frame, the patient's LPS (doc/patient_model.md): +x toward the
patient's left, +y posterior, +z superior; the right lobe (the larger) lies at -x. The lobes and
trees below are laid out in their mirror image (the right lobe at +x) and reflected, x -> -x,
when written: the mesh is then exactly the mirror of the one gmsh makes from these shapes, node
for node, so its physics is the same to round-off.
  config/phantom/sofa_liver_portal.vtk, sofa_liver2_portal.vtk
                                    portal-like trees inside the two external SOFA liver meshes
                                    (config/sofa_liver, scales 0.03 and 0.1)

Run: scripts/make_phantom.sh (installs python3-gmsh if missing). The scene that uses these
files, with the tumour targets and the ligament attachments, is config/scenes/liver_phantom.yaml.
With --check, writes into --out and compares byte for byte with the committed files (exit 1 on
a difference): the test suite runs this so that the phantom stays reproducible.
"""
import argparse
import filecmp
import math
import os
import sys

import gmsh
import numpy as np

COMMITTED = os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "config", "phantom")
MESH_SIZE = 0.009  # m, target tetrahedron edge: about 11,000 tetrahedra

# Lobes: centre (m), semi-axes (m). Inferior face cut at z = Z_CUT.
LOBES = [((0.030, 0.000, 0.000), (0.085, 0.075, 0.060)),   # right lobe
         ((-0.060, 0.010, 0.015), (0.060, 0.045, 0.030))]  # left lobe
Z_CUT = -0.035
MARGIN = 0.006    # m, vessel centre lines stay this far inside the analytic surface
SPACING = 0.006   # m, beam length along a branch


def inside_phantom(p, margin=MARGIN):
    if p[2] < Z_CUT + margin:
        return False
    for c, a in LOBES:
        if sum(((p[i] - c[i]) / (a[i] - margin)) ** 2 for i in range(3)) <= 1.0:
            return True
    return False


def make_mesh(path, size=MESH_SIZE):
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.NumThreads", 1)
    gmsh.model.add("liver_phantom")
    occ = gmsh.model.occ
    vols = []
    for c, a in LOBES:
        s = occ.addSphere(c[0], c[1], c[2], 1.0)
        occ.dilate([(3, s)], c[0], c[1], c[2], a[0], a[1], a[2])
        vols.append((3, s))
    fused, _ = occ.fuse([vols[0]], vols[1:])
    cut_box = occ.addBox(-0.3, -0.3, -0.3, 0.6, 0.6, 0.3 + Z_CUT)
    occ.cut(fused, [(3, cut_box)])
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * size)
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.option.setNumber("Mesh.RandomSeed", 1)
    gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.model.addPhysicalGroup(3, [t for _, t in gmsh.model.getEntities(3)], 1)
    gmsh.model.mesh.generate(3)
    gmsh.write(path)
    _, elem_tags, _ = gmsh.model.mesh.getElements(3)
    count = sum(len(t) for t in elem_tags)
    gmsh.finalize()
    reflect_msh(path)
    return count


def negate(token):
    """-x of a number as text, exactly (no re-printing); zero stays zero."""
    if float(token) == 0.0:
        return token
    return token[1:] if token.startswith("-") else "-" + token


def reflect_msh(path):
    """Reflects a Gmsh 2.2 ASCII mesh in x, in place: node x negated, each tetrahedron's last two
    nodes swapped so that its volume stays positive."""
    with open(path) as f:
        lines = f.read().split("\n")
    section = None
    for i, line in enumerate(lines):
        if line.startswith("$"):
            section = line
            continue
        fields = line.split(" ")
        if section == "$Nodes" and len(fields) == 4:
            fields[1] = negate(fields[1])
        elif section == "$Elements" and len(fields) > 3 and fields[1] == "4":
            fields[-2], fields[-1] = fields[-1], fields[-2]
        lines[i] = " ".join(fields)
    with open(path, "w") as f:
        f.write("\n".join(lines))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def rotate(v, axis, angle):
    """Rodrigues rotation of v about a unit axis."""
    axis = unit(axis)
    return (v * math.cos(angle) + np.cross(axis, v) * math.sin(angle)
            + axis * np.dot(axis, v) * (1 - math.cos(angle)))


class Tree:
    def __init__(self, inside=inside_phantom):
        self.inside = inside
        self.points, self.radius, self.wall, self.segments = [], [], [], []

    def node(self, p, r):
        self.points.append(np.asarray(p, float))
        self.radius.append(r)
        self.wall.append(0.1 * r)  # vein walls: about a tenth of the radius
        return len(self.points) - 1

    def branch(self, parent, direction, length, radius, depth, spin):
        """A straight branch from node `parent`, then two children (bifurcation) while inside."""
        start = self.points[parent]
        d = unit(direction)
        steps = max(1, int(round(length / SPACING)))
        last = parent
        for k in range(1, steps + 1):
            p = start + d * length * k / steps
            if not self.inside(p):
                return
            n = self.node(p, radius)
            self.segments.append((last, n))
            last = n
        if depth == 0:
            return
        # Children split +-32 degrees about an axis normal to the branch, turning 90 degrees at
        # each generation so that the tree fills the volume.
        axis = rotate(unit(np.cross(d, [0.0, 0.0, 1.0]) if abs(d[2]) < 0.95 else [1.0, 0.0, 0.0]), d, spin)
        for sign in (1, -1):
            self.branch(last, rotate(d, axis, sign * math.radians(32)), 0.72 * length, 0.75 * radius,
                        depth - 1, spin + math.pi / 2)

    def reflected(self):
        """The tree reflected in x (into LPS, as the phantom's mesh)."""
        for p in self.points:
            p[0] = 0.0 - p[0]  # no negative zero in the file
        return self

    def write_vtk(self, path, title):
        n = len(self.points)
        with open(path, "w") as f:
            f.write("# vtk DataFile Version 3.0\n%s (m)\nASCII\nDATASET POLYDATA\n" % title)
            f.write("POINTS %d double\n" % n)
            for p in self.points:
                f.write("%.6f %.6f %.6f\n" % tuple(p))
            f.write("LINES %d %d\n" % (len(self.segments), 3 * len(self.segments)))
            for a, b in self.segments:
                f.write("2 %d %d\n" % (a, b))
            f.write("POINT_DATA %d\n" % n)
            for name, values in (("radius", self.radius), ("wall_thickness", self.wall)):
                f.write("SCALARS %s double 1\nLOOKUP_TABLE default\n" % name)
                f.write("\n".join("%.6g" % v for v in values) + "\n")


def portal_tree():
    """Enters at the hilum on the inferior face, splits into a right and a left branch."""
    t = Tree()
    hilum = t.node((0.000, -0.005, Z_CUT + MARGIN + 0.001), 0.0060)
    t.branch(hilum, (0.0, 0.1, 1.0), 0.018, 0.0060, 0, 0.0)
    trunk_end = len(t.points) - 1
    t.branch(trunk_end, (1.0, 0.0, 0.35), 0.045, 0.0045, 3, 0.0)    # right portal vein (+x before the reflection)
    t.branch(trunk_end, (-1.0, 0.15, 0.3), 0.040, 0.0040, 3, 0.0)   # left portal vein
    return t


def hepatic_tree():
    """Right, middle and left hepatic veins draining to the vena cava, posterior-superior."""
    t = Tree()
    cava = t.node((0.000, 0.040, 0.030), 0.0070)
    t.branch(cava, (1.0, -0.5, -0.2), 0.045, 0.0050, 2, 0.0)    # right
    t.branch(cava, (0.15, -1.0, -0.3), 0.040, 0.0045, 2, 0.7)   # middle
    t.branch(cava, (-1.0, -0.3, -0.15), 0.040, 0.0045, 2, 0.0)  # left
    return t


class MeshInside:
    """Point-in-mesh test for a tetrahedral mesh file, with a clearance from its surface."""

    def __init__(self, path, scale):
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(path)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = {t: i for i, t in enumerate(tags)}
        xyz = coords.reshape(-1, 3) * scale
        _, _, nodes = gmsh.model.mesh.getElements(3, -1)
        tets = np.array([index[t] for t in nodes[0]]).reshape(-1, 4)
        gmsh.finalize()
        self.x0 = xyz[tets[:, 0]]
        edges = np.stack([xyz[tets[:, k]] - self.x0 for k in (1, 2, 3)], axis=2)
        self.inv = np.linalg.inv(edges)
        self.centroid = xyz.mean(axis=0)

    def contains(self, p):
        w = np.einsum("tij,tj->ti", self.inv, p - self.x0)
        b = np.column_stack([1 - w.sum(axis=1), w])
        return bool((b.min(axis=1) >= -1e-9).any())

    def __call__(self, p, margin=0.005):
        offsets = np.vstack([np.zeros(3), margin * np.eye(3), -margin * np.eye(3)])
        return all(self.contains(p + o) for o in offsets)


def sofa_portal_tree(path, scale):
    """A tree from the middle of a SOFA liver mesh toward both ends of the organ."""
    inside = MeshInside(path, scale)
    t = Tree(inside)
    root = t.node(inside.centroid, 0.005)
    t.branch(root, (1.0, 0.2, 0.1), 0.035, 0.0045, 3, 0.0)
    t.branch(root, (-1.0, 0.1, 0.1), 0.035, 0.0045, 3, 0.0)
    return t


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=COMMITTED, help="output folder (default: config/phantom)")
    ap.add_argument("--check", action="store_true", help="compare the output with config/phantom")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    tets = make_mesh(os.path.join(args.out, "liver_phantom.msh"))
    trees = [("portal", portal_tree().reflected()), ("hepatic", hepatic_tree().reflected())]
    sofa = os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "config", "sofa_liver")
    for mesh, scale in (("liver", 0.03), ("liver2", 0.1)):  # file units -> m, as in the tests
        path = os.path.join(sofa, mesh + ".msh")
        if os.path.exists(path):
            trees.append(("sofa_%s_portal" % mesh, sofa_portal_tree(path, scale)))
        else:
            print("skipped the SOFA %s tree: %s not found" % (mesh, path))
    for name, tree in trees:
        tree.write_vtk(os.path.join(args.out, name + ".vtk"), name + " vein tree of the liver phantom")
        print("%s: %d nodes, %d segments" % (name, len(tree.points), len(tree.segments)))
    print("liver_phantom.msh: %d tetrahedra" % tets)
    if args.check:
        files = ["liver_phantom.msh"] + [name + ".vtk" for name, _ in trees]
        _, differ, missing = filecmp.cmpfiles(args.out, COMMITTED, files, shallow=False)
        if differ or missing:
            print("differs from config/phantom: %s" % ", ".join(differ + missing))
            return 1
        print("identical to config/phantom: %s" % ", ".join(files))
    return 0


if __name__ == "__main__":
    sys.exit(main())
