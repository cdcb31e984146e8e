#!/usr/bin/python3
"""Registration truths our model did not make (doc/registration.md, "Truths of another law"): the
phantom's anatomy (scripts/make_phantom.py, meshed again by gmsh at --mesh-size: no node shared
with the model's mesh) deformed by a compressible neo-Hookean material at large strain, solved
here in total-Lagrangian form (numpy, scipy), under displacement-type loads:

  packing    a disc of the inferior face under the right lobe (4 cm radius) pushed up 20 mm
             (surgical packing under the organ), the attachments held
  retractor  the boundary of the right lobe's anterior-inferior edge within 2 cm of a point
             lifted 30 mm and drawn 10 mm anteriorly (a retractor's blade), the attachments held

  W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,  P = mu (F - F^-T) + lambda ln J F^-T
  (E = 15 kPa, nu = 0.47: neither the model's 30 kPa nor its 0.45; the model's two attachments,
  bare area and falciform ligament, but no capsule, no vessels, no gravity)

Each case is written as the Open-CAS in-silico case is (src/testing/insilico_case.h), in mm:
  OUT/<case>/initial-volume.vtk, deformed-volume.vtk   legacy VTK unstructured grids, the same
                                                        nodes and cells
  OUT/<case>/initial-surface.stl, deformed-surface.stl the boundaries
  OUT/<case>/anterior.stl, superior.stl, anterior-hemi.stl
                                                        partial views: the deformed boundary's
                                                        triangles in front of (y below), above
                                                        (z above) the deformed centroid, and the
                                                        anterior view's right half (x below)
  OUT/<case>/oracle.txt   the best rigid fit of all nodes (Kabsch): its error over the interior
                          nodes, the floor a rigid registration cannot go below
so that register_insilico evaluates them as it does that case. Deterministic: the same arguments
give the same files. The files are our own (BSD, as the package); a few MB: write them into the
build tree. Progress (each load step's Newton residuals) on standard error.

--check validates the solver against closed forms instead (exit 1 on a failure; ctest
neohookean_truth_check): a cube whose boundary follows an affine map F0 must follow it inside,
with the reaction on a face equal to P(F0) N times its area, P taken as the derivative of W
(central differences of the energy, not the solver's stress); a bar stretched 1.5x with free
sides must narrow as the traction-free condition P22(l1, l2, l2) = 0 (a scalar root) says,
carrying P11 per area; the tangent must be the derivative of the forces (central differences).
Mutations it kills (tried): the lambda ln J F^-T term dropped from P (both closed forms fail),
the tangent's (mu - lambda ln J) written (mu + lambda ln J) (the tangent check fails).

usage: make_neohookean_truth.py --out DIR [--case packing,retractor] [--mesh-size M] [--steps N]
       make_neohookean_truth.py --check
"""
import argparse
import math
import os
import struct
import sys

import numpy as np
import scipy.optimize
import scipy.sparse as sp
import scipy.sparse.linalg as spla

YOUNG, POISSON = 15000.0, 0.47  # Pa, -
SUPPORTS = [("sphere", (0.0, 0.07, 0.03), 0.03),                      # bare area and vena cava
            ("box", (0.025, -0.08, 0.02), (0.035, 0.0, 0.08))]        # falciform ligament
CASES = {
    # region selecting boundary nodes (m), their prescribed displacement (m)
    "packing": (("disc_below", (-0.04, 0.0), 0.04), (0.0, 0.0, 0.020)),
    "retractor": (("sphere", (-0.05, -0.055, -0.03), 0.02), (0.0, -0.010, 0.030)),
}


def lame(young, poisson):
    return young / (2 * (1 + poisson)), young * poisson / ((1 + poisson) * (1 - 2 * poisson))


class NeoHookean:
    """Linear tetrahedra, total Lagrangian: forces and tangent of W above at positions x."""

    def __init__(self, X, T, young=YOUNG, poisson=POISSON):
        self.X, self.T = X, T
        Dm = np.stack([X[T[:, k]] - X[T[:, 0]] for k in (1, 2, 3)], axis=2)  # columns: edges
        self.volume = np.linalg.det(Dm) / 6
        if (self.volume <= 0).any():
            raise ValueError("inverted or degenerate tetrahedra")
        inv = np.linalg.inv(Dm)
        self.G = np.concatenate([-inv.sum(axis=1, keepdims=True), inv], axis=1)  # (e, 4, 3): grad N_a
        self.mu, self.lam = lame(young, poisson)
        dofs = (3 * T[:, :, None] + np.arange(3)).reshape(len(T), 12)
        self.rows = np.repeat(dofs, 12, axis=1).ravel()
        self.cols = np.tile(dofs, (1, 12)).ravel()
        self.n = 3 * len(X)

    def deformation(self, x):
        return np.einsum("eai,eaj->eij", x[self.T], self.G)

    def stress(self, F):
        Finv = np.linalg.inv(F)
        lnJ = np.log(np.linalg.det(F))
        FinvT = np.transpose(Finv, (0, 2, 1))
        return self.mu * (F - FinvT) + self.lam * lnJ[:, None, None] * FinvT, Finv, lnJ

    def forces(self, x):
        """Internal forces (N per DOF, node-major) and the tangent (sparse) at x."""
        F = self.deformation(x)
        if (np.linalg.det(F) <= 0).any():
            raise FloatingPointError("an element inverted")
        P, Finv, lnJ = self.stress(F)
        fe = self.volume[:, None, None] * np.einsum("eij,eaj->eai", P, self.G)
        f = np.zeros((len(self.X), 3))
        for a in range(4):
            np.add.at(f, self.T[:, a], fe[:, a])
        I = np.eye(3)
        # A_iJkL = dP_iJ/dF_kL = mu d_ik d_JL + (mu - lambda ln J) Finv_Jk Finv_Li + lambda Finv_Ji Finv_Lk
        A = (self.mu * np.einsum("ik,JL->iJkL", I, I)[None]
             + (self.mu - self.lam * lnJ)[:, None, None, None, None] * np.einsum("eJk,eLi->eiJkL", Finv, Finv)
             + self.lam * np.einsum("eJi,eLk->eiJkL", Finv, Finv))
        Ke = self.volume[:, None, None, None, None] * np.einsum("eaJ,eiJkL,ebL->eaibk", self.G, A, self.G, optimize=True)
        K = sp.csr_matrix((Ke.reshape(len(self.T), 144).ravel(), (self.rows, self.cols)), shape=(self.n, self.n))
        return f.ravel(), K


def linear_solve(K, b):
    """K x = b for the symmetric positive definite tangent: conjugate gradients with a Jacobi
    preconditioner (SuperLU's fill-in makes a direct solve ten times slower here), a direct
    solve when they do not converge (an indefinite tangent)."""
    if not b.any():
        return np.zeros_like(b)
    M = sp.diags(1.0 / K.diagonal())
    try:
        x, info = spla.cg(K, b, M=M, rtol=1e-11, atol=0.0, maxiter=20000)
    except TypeError:  # scipy < 1.12 names the relative tolerance tol
        x, info = spla.cg(K, b, M=M, tol=1e-11, atol=0.0, maxiter=20000)
    return x if info == 0 else spla.splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A").solve(b)


def newton(model, x, free, tolerance, log):
    """Equilibrium of the free DOFs from x (changed in place). Converged when the free DOFs'
    residual is below `tolerance` times the reactions' norm; False when it is not in 25 steps."""
    history = []
    for _ in range(25):
        f, K = model.forces(x.reshape(-1, 3))
        norm = np.linalg.norm(f[free])
        scale = max(np.linalg.norm(f), 1e-30)
        history.append(norm / scale)
        if norm <= tolerance * scale:
            log("residual/reactions " + " ".join("%.1e" % h for h in history))
            return True
        dx = linear_solve(K[free][:, free], -f[free])
        # Backtracking: no element may invert.
        for s in (1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125):
            trial = x.copy()
            trial[free] += s * dx
            if (np.linalg.det(model.deformation(trial.reshape(-1, 3))) > 0).all():
                break
        else:
            return False
        x[:] = trial
    log("not converged: residual/reactions " + " ".join("%.1e" % h for h in history))
    return False


def solve_dirichlet(model, prescribed, steps, tolerance=1e-9, log=lambda s: None):
    """Equilibrium with the displacements `prescribed` ({dof: value}) reached in at least `steps`
    equal increments (an increment that does not converge is halved, at most 6 times), Newton's
    method at each; no other load. Returns positions (n, 3) and the internal forces (n, 3): the
    reactions at the prescribed DOFs."""
    x = model.X.copy().ravel()
    fixed = np.array(sorted(prescribed))
    target = model.X.ravel()[fixed] + np.array([prescribed[d] for d in fixed])
    free = np.setdiff1d(np.arange(model.n), fixed)
    done, step, halvings = 0.0, 1.0 / steps, 0
    while done < 1.0 - 1e-12:
        t = min(1.0, done + step)
        saved = x.copy()
        # The increment carried into the free nodes by the tangent (a linear predictor): moved
        # alone, the prescribed nodes would invert their neighbours.
        increment = model.X.ravel()[fixed] + t * (target - model.X.ravel()[fixed]) - x[fixed]
        _, K = model.forces(x.reshape(-1, 3))
        x[free] -= linear_solve(K[free][:, free], K[free][:, fixed] @ increment)
        x[fixed] += increment
        try:
            converged = newton(model, x, free, tolerance, lambda s: log("load %5.1f%%: %s" % (100 * t, s)))
        except FloatingPointError:
            converged = False
        if converged:
            done = t
            continue
        x = saved
        halvings += 1
        step /= 2
        if halvings > 6:
            raise RuntimeError("no convergence at load %.1f%% even in increments of %.2g" % (100 * t, step))
        log("load %5.1f%%: the increment halved" % (100 * t))
    f, _ = model.forces(x.reshape(-1, 3))
    return x.reshape(-1, 3), f.reshape(-1, 3)


def boundary_triangles(T):
    faces = np.concatenate([T[:, [0, 2, 1]], T[:, [0, 1, 3]], T[:, [0, 3, 2]], T[:, [1, 2, 3]]])
    key = np.sort(faces, axis=1)
    _, first, count = np.unique(key, axis=0, return_index=True, return_counts=True)
    return faces[np.sort(first[count == 1])]


def cube_mesh(n):
    """The unit cube in n^3 cells of 6 tetrahedra (Kuhn), positively oriented."""
    g = np.linspace(0.0, 1.0, n + 1)
    X = np.array([(a, b, c) for c in g for b in g for a in g])
    idx = lambda i, j, k: i + (n + 1) * (j + (n + 1) * k)
    T = []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                c = [idx(i + (v & 1), j + ((v >> 1) & 1), k + ((v >> 2) & 1)) for v in range(8)]
                for p in ((1, 3), (1, 5), (2, 3), (2, 6), (4, 5), (4, 6)):
                    T.append([c[0], c[p[0]], c[p[0] | p[1]], c[7]])
    T = np.array(T)
    X4 = X[T]
    vol = np.linalg.det(np.stack([X4[:, k] - X4[:, 0] for k in (1, 2, 3)], axis=2))
    T[vol < 0] = T[vol < 0][:, [0, 2, 1, 3]]
    return X, T


def energy_derivative(F, mu, lam, h=1e-6):
    """dW/dF by central differences of the strain energy, written apart from the solver."""
    def W(F):
        J = np.linalg.det(F)
        return mu / 2 * (np.sum(F * F) - 3) - mu * math.log(J) + lam / 2 * math.log(J) ** 2
    P = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            E = np.zeros((3, 3))
            E[i, j] = h
            P[i, j] = (W(F + E) - W(F - E)) / (2 * h)
    return P


def check_affine(model, X, T):
    """Affine boundary: the inside follows, the face reaction is P(F0) N times the area."""
    F0 = np.array([[1.3, 0.2, 0.0], [0.0, 0.8, 0.1], [0.05, 0.0, 0.9]])
    on_boundary = np.unique(boundary_triangles(T))
    prescribed = {3 * i + a: (F0 @ X[i] - X[i])[a] for i in on_boundary for a in range(3)}
    x, f = solve_dirichlet(model, prescribed, steps=4)
    inside = np.abs(x - X @ F0.T).max()
    reaction = f[np.isclose(X[:, 0], 1.0)].sum(axis=0)
    expected = energy_derivative(F0, model.mu, model.lam) @ np.array([1.0, 0.0, 0.0])  # N = +x, area 1
    print("affine patch: interior off the map by %.1e m; face reaction %s N against dW/dF N %s N" %
          (inside, np.round(reaction, 4), np.round(expected, 4)))
    return inside <= 1e-9 and np.abs(reaction - expected).max() <= 1e-6 * np.abs(expected).max()


def check_uniaxial(model, X):
    """Stretch 1.5, sides free: x = 1 pulled along x, x = 0 held along x, rigid motions removed
    by the edges through the origin."""
    mu, lam, l1 = model.mu, model.lam, 1.5
    l2 = scipy.optimize.brentq(lambda l: mu * (l - 1 / l) + lam * math.log(l1 * l * l) / l, 0.3, 1.0, xtol=1e-14)
    P11 = mu * (l1 - 1 / l1) + lam * math.log(l1 * l2 * l2) / l1
    prescribed = {3 * i: 0.0 for i in np.where(np.isclose(X[:, 0], 0.0))[0]}
    prescribed.update({3 * i: l1 - 1.0 for i in np.where(np.isclose(X[:, 0], 1.0))[0]})
    prescribed.update({3 * i + 2: 0.0 for i in np.where(np.all(np.isclose(X[:, [0, 2]], 0.0), axis=1))[0]})
    prescribed.update({3 * i + 1: 0.0 for i in np.where(np.all(np.isclose(X[:, [0, 1]], 0.0), axis=1))[0]})
    x, f = solve_dirichlet(model, prescribed, steps=6)
    width = x[:, 1].max() - x[:, 1].min()
    pull = f[np.isclose(X[:, 0], 1.0), 0].sum()
    print("uniaxial 1.5: width %.9f against the root's %.9f; force %.6f N against P11 %.6f N" % (width, l2, pull, P11))
    return abs(width - l2) <= 1e-8 and abs(pull - P11) <= 1e-6 * P11


def check_tangent(model, X):
    """The tangent is the forces' derivative, at a large strain (stretched, sheared, perturbed)."""
    rng = np.random.default_rng(1)
    x = X @ np.array([[1.5, 0.3, 0.0], [0.0, 0.8, 0.0], [0.1, 0.0, 0.9]]).T + 0.01 * rng.standard_normal(X.shape)
    v = rng.standard_normal(x.size).reshape(-1, 3)
    K = model.forces(x)[1]
    eps = 1e-6
    fd = (model.forces(x + eps * v)[0] - model.forces(x - eps * v)[0]) / (2 * eps)
    gap = np.linalg.norm(K @ v.ravel() - fd) / np.linalg.norm(fd)
    print("tangent: |K v - central difference of the forces| / |...| = %.1e" % gap)
    return gap <= 1e-6


def check():
    X, T = cube_mesh(4)
    model = NeoHookean(X, T)
    failures = []
    for name, run in (("affine patch", lambda: check_affine(model, X, T)), ("uniaxial stretch", lambda: check_uniaxial(model, X)),
                      ("tangent", lambda: check_tangent(model, X))):
        try:
            if not run():
                failures.append(name)
        except (RuntimeError, FloatingPointError) as e:
            print("%s: %s" % (name, e))
            failures.append(name)
    if failures:
        print("FAILED: " + ", ".join(failures))
        return 1
    print("neo-Hookean solver: the closed forms and the tangent met")
    return 0


def write_vtk(path, x, T):
    with open(path, "w") as f:
        f.write("# vtk DataFile Version 3.0\nneo-Hookean truth (scripts/make_neohookean_truth.py)\nASCII\n"
                "DATASET UNSTRUCTURED_GRID\nPOINTS %d double\n" % len(x))
        for p in 1e3 * x:
            f.write("%.9g %.9g %.9g\n" % tuple(p))
        f.write("CELLS %d %d\n" % (len(T), 5 * len(T)))
        for t in T:
            f.write("4 %d %d %d %d\n" % tuple(t))
        f.write("CELL_TYPES %d\n" % len(T) + "10\n" * len(T))


def write_stl(path, x, F):
    with open(path, "wb") as f:
        f.write(b"neo-Hookean truth".ljust(80, b" "))
        f.write(struct.pack("<I", len(F)))
        for t in F:
            a, b, c = 1e3 * x[t[0]], 1e3 * x[t[1]], 1e3 * x[t[2]]
            n = np.cross(b - a, c - a)
            n = n / max(np.linalg.norm(n), 1e-30)
            f.write(struct.pack("<12fH", *n, *a, *b, *c, 0))


def read_msh22(path):
    with open(path) as f:
        lines = f.read().split("\n")
    i = lines.index("$Nodes")
    ids, X = {}, []
    for k in range(int(lines[i + 1])):
        fields = lines[i + 2 + k].split()
        ids[int(fields[0])] = k
        X.append([float(v) for v in fields[1:4]])
    i = lines.index("$Elements")
    T = [[ids[int(v)] for v in fields[-4:]]
         for fields in (lines[i + 2 + k].split() for k in range(int(lines[i + 1]))) if fields[1] == "4"]
    # gmsh keeps nodes no tetrahedron uses (the surfaces' own): drop them, as the reader does.
    used = np.unique(T)
    renumber = np.full(len(X), -1)
    renumber[used] = np.arange(len(used))
    return np.array(X)[used], renumber[np.array(T)]


def selected(X, on_boundary, region):
    kind = region[0]
    if kind == "sphere":
        keep = np.linalg.norm(X - np.array(region[1]), axis=1) <= region[2]
    elif kind == "box":
        keep = np.all((X >= np.array(region[1])) & (X <= np.array(region[2])), axis=1)
    else:  # disc_below: the inferior face within a radius of (x, y)
        keep = (np.linalg.norm(X[:, :2] - np.array(region[1]), axis=1) <= region[2]) & (X[:, 2] <= X[:, 2].min() + 1e-3)
    return np.where(keep & on_boundary)[0]


def rigid_oracle(X, x, interior):
    """The best rigid map of all nodes X onto x (Kabsch): its errors at the interior nodes."""
    a, b = X - X.mean(axis=0), x - x.mean(axis=0)
    U, _, Vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(U @ Vt))
    R = (U @ np.diag([1.0, 1.0, d]) @ Vt).T
    return np.linalg.norm(a @ R.T - b, axis=1)[interior]


def make_case(name, X, T, out, steps, log):
    F = boundary_triangles(T)
    on_boundary = np.zeros(len(X), bool)
    on_boundary[F.ravel()] = True
    prescribed = {}
    for region in SUPPORTS:
        for i in selected(X, on_boundary, region):
            prescribed.update({3 * i + a: 0.0 for a in range(3)})
    region, displacement = CASES[name]
    moved = selected(X, on_boundary, region)
    if len(moved) == 0:
        raise RuntimeError(name + ": the region selects no boundary node")
    for i in moved:
        prescribed.update({3 * i + a: displacement[a] for a in range(3)})
    log("%s: %d nodes, %d tetrahedra, %d nodes moved, %d held" % (name, len(X), len(T), len(moved), len(prescribed) // 3 - len(moved)))
    x, _ = solve_dirichlet(NeoHookean(X, T), prescribed, steps, log=lambda s: log(name + ", " + s))
    folder = os.path.join(out, name)
    os.makedirs(folder, exist_ok=True)
    write_vtk(os.path.join(folder, "initial-volume.vtk"), X, T)
    write_vtk(os.path.join(folder, "deformed-volume.vtk"), x, T)
    write_stl(os.path.join(folder, "initial-surface.stl"), X, F)
    write_stl(os.path.join(folder, "deformed-surface.stl"), x, F)
    centroid = x[F].mean(axis=1)
    middle = x.mean(axis=0)
    views = {"anterior": centroid[:, 1] < middle[1], "superior": centroid[:, 2] > middle[2]}
    views["anterior-hemi"] = views["anterior"] & (centroid[:, 0] < middle[0])
    for view, keep in views.items():
        write_stl(os.path.join(folder, view + ".stl"), x, F[keep])
    interior = ~on_boundary
    u = 1e3 * np.linalg.norm(x - X, axis=1)[interior]
    r = 1e3 * rigid_oracle(X, x, interior)
    summary = ("%s: %d interior nodes moved mean %.1f mm, max %.1f mm; the best rigid fit of all nodes leaves "
               "mean %.2f mm, p95 %.2f, max %.2f" % (name, interior.sum(), u.mean(), u.max(), r.mean(), np.percentile(r, 95), r.max()))
    with open(os.path.join(folder, "oracle.txt"), "w") as f:
        f.write(summary + "\n")
    print(summary)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", help="output folder (e.g. build/neohookean)")
    ap.add_argument("--case", default="packing,retractor", help="cases, comma-separated: " + ", ".join(CASES))
    ap.add_argument("--mesh-size", type=float, default=0.007, help="m, gmsh's element edge, in [0.004, 0.012] (default 0.007)")
    ap.add_argument("--steps", type=int, default=4, help="load increments at least, in [1, 100] (default 4)")
    ap.add_argument("--check", action="store_true", help="validate the solver against closed forms and exit")
    ap.add_argument("--quiet", action="store_true", help="no progress on standard error")
    args = ap.parse_args()
    if args.check:
        return check()
    if not args.out:
        ap.error("--out is required")
    cases = args.case.split(",")
    if any(c not in CASES for c in cases) or not 0.004 <= args.mesh_size <= 0.012 or not 1 <= args.steps <= 100:
        ap.error("unknown case, or --mesh-size / --steps out of bounds")
    log = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))
    import make_phantom
    os.makedirs(args.out, exist_ok=True)
    mesh = os.path.join(args.out, "truth_mesh.msh")
    make_phantom.make_mesh(mesh, args.mesh_size)
    X, T = read_msh22(mesh)
    for name in cases:
        make_case(name, X, T, args.out, args.steps, log)
    return 0


if __name__ == "__main__":
    sys.exit(main())
