#!/usr/bin/env python3
"""Mutation testing of the physics core: does the fast test suite notice wrong physics?

Each mutation is a small change of the source (a sign flip, a dropped term, an off-by-one, a
wrong factor) given as (file, exact original text, replacement). One at a time, the script
applies it, rebuilds the core and the fast physics test binaries, runs them (each under
a timeout, stopping at the first failure) and restores the source. A mutation is *killed* when
a test fails (or times out), *survives* when every test passes. A mutation whose original text
is no longer in the file (or occurs more than once) is reported "not applicable" and not run, so
the list stays valid as the code evolves. Mutations marked equivalent cannot change any result
(the reason is given); they are run to confirm that they survive and are not counted.

    scripts/mutate.py                  # every mutation (about an hour on 2 shared cores)
    scripts/mutate.py --only NS1,MM1   # some of them
    scripts/mutate.py --list           # the list and whether each applies, nothing built

Run after a build (scripts/test.sh). Prints a Markdown table and the kill rate; exits non-zero
when the unmutated suite fails or a source could not be restored.
"""
import argparse
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

REPO = pathlib.Path(__file__).resolve().parent.parent
BUILD = REPO / "build" / "ws" / "build"
BIN = REPO / "build" / "ws" / "devel" / "lib" / "liver_sim"
BACKUP = REPO / "build" / "mutation_backup"

# The fast physics tests, in the order they run (cheapest and most discriminating first), each
# stopping at its first failure; the slow ones (phantom frames, Hertz refinement, the haptic
# tracking run) are filtered out or not listed. Last, the reduced stress matrix's expected outcomes.
FAIL_FAST = "--gtest_fail_fast"
TESTS = [
    ("model_tests", [FAIL_FAST, "--gtest_filter=-*VascularisedLiver*"]),
    ("simulation_tests", [FAIL_FAST, "--gtest_filter=-*OneIterationPerHapticFrame*:LiverPhantom.*"]),
    ("geometry_tests", [FAIL_FAST, "--gtest_filter=ClosestOnTriangle.*:ClosestPoints.*"]),
    ("contact_tests", [FAIL_FAST, "--gtest_filter=-Hertz*:NodeCompliance.*:InstrumentDrawing.*"]),
    ("stepper_tests", [FAIL_FAST, "--gtest_filter=Probe.*:TimeBudget.*"]),
    ("io_tests", [FAIL_FAST, "--gtest_filter=VesselTree.*"]),
    ("stress", ["--quick"]),
]


class Mutation:
    def __init__(self, key, path, original, replacement, what, equivalent=None):
        self.key, self.path, self.original, self.replacement = key, path, original, replacement
        self.what, self.equivalent = what, equivalent


M = Mutation
MUTATIONS = [
    # --- parenchyma: corotational tetrahedra (forces, tangent, energy, rotations) ---
    M("T1", "src/core/model/corotational_tetra.cpp",
      "const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));",
      "const double lambda = E * nu / ((1 + nu) * (1 - nu));",
      "wrong first Lame parameter"),
    M("T2", "src/core/model/corotational_tetra.cpp",
      "for (int i = 0; i < 3; ++i) stress(i, i) += lambda_ * trace;",
      "for (int i = 0; i < 3; ++i) stress(i, i) -= lambda_ * trace;",
      "sign of the volumetric stress in the four-element kernel"),
    M("T3", "src/core/model/corotational_tetra.cpp",
      "stress(i, j) = mu_ * (G(i, j) + G(j, i));",
      "stress(i, j) = mu_ * (G(i, j) + G(i, j));",
      "unsymmetrised gradient in the shear stress (four-element kernel)"),
    M("T4", "src/core/model/corotational_tetra.cpp",
      "f[l].head<3>() = -(f[l].segment<3>(3) + f[l].segment<3>(6) + f[l].segment<3>(9));",
      "f[l].head<3>() = -(f[l].segment<3>(3) + f[l].segment<3>(6));",
      "dropped term in node 0's force (four-element kernel)"),
    M("T5", "src/core/model/corotational_tetra.cpp",
      "return 0.5 * block.volume * work;",
      "return block.volume * work;",
      "strain energy twice too large (four-element kernel)"),
    M("T6", "src/core/model/corotational_tetra.cpp",
      "K.block<3, 3>(3 * a, 3 * b).noalias() = R * K0_[e].block<3, 3>(3 * a, 3 * b) * R.transpose();",
      "K.block<3, 3>(3 * a, 3 * b).noalias() = R.transpose() * K0_[e].block<3, 3>(3 * a, 3 * b) * R;",
      "tangent rotated the wrong way"),
    M("T7", "src/core/model/corotational_tetra.cpp",
      "stress.diagonal().array() += lambda_ * strain.trace();",
      "stress.diagonal().array() += 0.5 * lambda_ * strain.trace();",
      "half the volumetric stress in the one-element kernel (geometric rotation, remainders, damping)"),
    M("T8", "src/core/model/corotational_tetra.cpp",
      "f.head<3>() = -(fs.col(0) + fs.col(1) + fs.col(2));",
      "f.head<3>() = -(fs.col(0) + fs.col(1));",
      "dropped term in node 0's force (one-element kernel)"),
    M("T9", "src/core/model/corotational_tetra.cpp",
      "if (continued) q_[e] = (q * q_step_[e].conjugate() * q).normalized();",
      "if (continued) q_[e] = (q * q_step_[e] * q).normalized();",
      "rotations predicted backwards (the polar iteration's starting guess)"),
    M("T10", "src/core/model/corotational_tetra.cpp",
      "frame << a, c.cross(a), c;",
      "frame << a, a.cross(c), c;",
      "left-handed edge frame (geometric rotation)",
      equivalent="the rest and current frames flip the same axis, so R = frame(x) frame(X)^T is unchanged"),
    M("T11", "src/core/model/corotational_tetra.cpp",
      "const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));\n  const double mu = E / (2 * (1 + nu));",
      "const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));\n  const double mu = E / (1 + nu);",
      "shear modulus twice too large"),
    # --- capsule: CST membranes ---
    M("C1", "src/core/model/membrane_cst.cpp",
      "const double lambda = E * nu / (1 - nu * nu);",
      "const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));",
      "3D instead of plane-stress Lame parameter"),
    M("C2", "src/core/model/membrane_cst.cpp",
      "h * area_[e] * (lambda * ga * gb.transpose()",
      "area_[e] * (lambda * ga * gb.transpose()",
      "thickness dropped"),
    M("C3", "src/core/model/membrane_cst.cpp",
      "frame_[first + l](i, 0) = a[i][l] * cr[l] + b[i][l] * sr[l];",
      "frame_[first + l](i, 0) = a[i][l] * cr[l] - b[i][l] * sr[l];",
      "in-plane rotation of the frame with the wrong sign (four-triangle kernel)"),
    M("C4", "src/core/model/membrane_cst.cpp",
      "if (r > 0) R2 << c / r, -s / r, s / r, c / r;",
      "if (r > 0) R2 << c / r, s / r, -s / r, c / r;",
      "in-plane rotation of the frame with the wrong sign (one-triangle path)"),
    M("C5", "src/core/model/membrane_cst.cpp",
      "return 0.5 * u.dot(f2);",
      "return u.dot(f2);",
      "membrane energy twice too large"),
    M("C6", "src/core/model/membrane_cst.cpp",
      "for (int i = 0; i < 3; ++i) v2.segment<2>(2 * i) = A.transpose() * node(v, F_(e, i));",
      "for (int i = 0; i < 3; ++i) v2.segment<2>(2 * i) = A.transpose() * node(v, F_(e, 0));",
      "off-by-one node in the membrane damping product"),
    M("C7", "src/core/model/membrane_cst.cpp",
      "K.block<3, 3>(3 * a, 3 * b).noalias() = A * K2_[e].block<2, 2>(2 * a, 2 * b) * A.transpose();",
      "K.block<3, 3>(3 * a, 3 * b).noalias() = A * K2_[e].block<2, 2>(2 * b, 2 * a) * A.transpose();",
      "membrane tangent assembled from transposed blocks"),
    # --- vessels: corotational beams and their embedding ---
    M("B1", "src/core/model/corotational_beam.cpp",
      "const double A = s.area(), I = s.second_moment(), J = 2 * I;",
      "const double A = s.area(), I = s.second_moment(), J = I;",
      "torsion constant half the polar moment"),
    M("B2", "src/core/model/corotational_beam.cpp",
      "std::array<int, 3>{2, 4, -1}",
      "std::array<int, 3>{2, 4, +1}",
      "bending coupling sign in the x-z plane"),
    M("B3", "src/core/model/corotational_beam.cpp",
      "add(t1, t2, 2 * L * L * b);",
      "add(t1, t2, 4 * L * L * b);",
      "wrong carry-over moment"),
    M("B4", "src/core/model/corotational_beam.cpp",
      "return M_PI * (outer_radius * outer_radius - ri * ri);",
      "return M_PI * (outer_radius * outer_radius + ri * ri);",
      "wrong section area"),
    M("B5", "src/core/model/corotational_beam.cpp",
      "d[6] = l - L_[e];",
      "d[6] = l - 0.5 * L_[e];",
      "wrong rest length"),
    M("B6", "src/core/model/embedded_vessels.cpp",
      "f.segment<3>(3 * T_(at.tet, k)) += at.barycentric[k] * fe.segment<3>(6 * end) + fm.segment<3>(3 * k);",
      "f.segment<3>(3 * T_(at.tet, k)) += at.barycentric[k] * fe.segment<3>(6 * end);",
      "beam moments not carried to the tissue"),
    # --- loads, mass, assembly ---
    M("MM1", "src/core/model/mechanical_model.cpp",
      "const Eigen::Vector3d area = 0.5 * (x.segment<3>(3 * b) - x.segment<3>(3 * a))\n"
      "                                             .cross(x.segment<3>(3 * c) - x.segment<3>(3 * a));",
      "const Eigen::Vector3d area = 0.5 * (X_.segment<3>(3 * b) - X_.segment<3>(3 * a))\n"
      "                                             .cross(X_.segment<3>(3 * c) - X_.segment<3>(3 * a));",
      "pressure on the rest area: follower load becomes a dead load"),
    M("MM2", "src/core/model/mechanical_model.cpp",
      "f.segment<3>(3 * c) += fn;\n",
      "f.segment<3>(3 * c) += 0.5 * fn;\n",
      "a pressure triangle's third node gets half its share"),
    M("MM3", "src/core/model/mechanical_model.cpp",
      "mass_.segment<3>(3 * mesh_.T(e, k)).array() += parenchyma_.density * tetra_.volume(e) / 4;",
      "mass_.segment<3>(3 * mesh_.T(e, k)).array() += parenchyma_.density * tetra_.volume(e) / 8;",
      "lumped mass halved (inertia and gravity)"),
    M("MM4", "src/core/model/mechanical_model.cpp",
      "for (int i = 0; i < f.size(); i += 3) f.segment<3>(i) += mass_[i] * gravity_;",
      "for (int i = 0; i < f.size(); i += 3) f.segment<3>(i) += mass_[i + 2] * gravity_;",
      "gravity from the mass of another DOF of the node",
      equivalent="the lumped mass is the same for the three DOFs of a node"),
    M("MM5", "src/core/model/mechanical_model.cpp",
      "values[pattern_.diagonal(i)] += m * mass_[i];",
      "values[pattern_.diagonal(i)] += 0.5 * m * mass_[i];",
      "half the mass in the Newton matrix (not in the residual)"),
    M("MM6", "src/core/model/mechanical_model.cpp",
      "for (const NodalLoad& l : nodal_loads_)\n    for (int node : l.nodes) f.segment<3>(3 * node) += l.force;",
      "for (const NodalLoad& l : nodal_loads_)\n    for (int node : l.nodes) f.segment<3>(3 * node) -= l.force;",
      "spread force with the wrong sign"),
    M("MM7", "src/core/model/mechanical_model.cpp",
      "membrane_.tangent_product(t, damping_.membrane_frame[t], v, fm);",
      "membrane_.tangent_product(t, damping_.membrane_frame[t], v, fm);\n        fm *= 0;",
      "capsule left out of the stiffness-proportional damping"),
    # --- stepper: residual, inertia, damping, detectors ---
    M("NS1", "src/core/stepper/newton_stepper.cpp",
      "r -= mechanics_.mass().cwiseProduct((v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);",
      "r -= mechanics_.mass().cwiseProduct(0.5 * (v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);",
      "inertia with half the mass"),
    M("NS2", "src/core/stepper/newton_stepper.cpp",
      "r -= mechanics_.mass().cwiseProduct((v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);",
      "r -= mechanics_.mass().cwiseProduct((v_tmp_ - v_) / dt - solver_.rayleigh_mass * v_tmp_);",
      "mass-proportional damping with the wrong sign"),
    M("NS3", "src/core/stepper/newton_stepper.cpp",
      "r -= solver_.rayleigh_stiffness * f_tmp_;",
      "r -= 0.5 * solver_.rayleigh_stiffness * f_tmp_;",
      "half the stiffness-proportional damping"),
    M("NS4", "src/core/stepper/newton_stepper.cpp",
      "r -= mechanics_.mass().cwiseProduct((v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);",
      "r -= mechanics_.mass().cwiseProduct((v_tmp_ - v_previous_) / dt + solver_.rayleigh_mass * v_tmp_);",
      "inertia against the velocity one step too old"),
    M("NS5", "src/core/stepper/newton_stepper.cpp",
      "v_ = (x_ - x_start_) / solver_.dt;",
      "v_ = 0.5 * (x_ - x_start_) / solver_.dt;",
      "velocity update with a wrong factor"),
    M("NS6", "src/core/stepper/newton_matrix.cpp",
      "m_scale = 1.0 / (dt * dt) + solver_.rayleigh_mass / dt;",
      "m_scale = 1.0 / dt + solver_.rayleigh_mass / dt;",
      "mass term of the Newton matrix with a wrong power of dt"),
    M("NS7", "src/core/stepper/newton_stepper.cpp",
      "  r *= load_scale_;\n",
      "  r *= 1.0;\n",
      "load scale ignored"),
    M("NS8", "src/core/stepper/newton_loop.cpp",
      "if (!std::isfinite(s.norm)) {",
      "if (std::isinf(s.norm)) {",
      "non-finite residual detector misses NaN"),
    M("NS9", "src/core/stepper/newton_loop.cpp",
      "if (s.merit > 1e6 * std::max(s.start_merit, force_floor)) {",
      "if (s.merit > 1e12 * std::max(s.start_merit, force_floor)) {",
      "residual blow-up detector a million times too lax"),
    M("NS10", "src/core/stepper/newton_loop.cpp",
      "if (s.merit >= s.start_merit && cap >= kStallIterations) {",
      "if (s.merit >= 10 * s.start_merit && cap >= kStallIterations) {",
      "stall detector ten times too lax"),
    M("NS11", "src/core/stepper/newton_stepper.cpp",
      "energy_after > 2 * (energy_before + std::abs(work))",
      "energy_after > 20 * (energy_before + std::abs(work))",
      "energy-growth detector ten times too lax"),
    M("NS12", "src/core/stepper/newton_loop.cpp",
      "(fresh_factor && !factorize(result))",
      "(fresh_factor && (factorize(result), false))",
      "not-positive-definite detector removed"),
    M("NS13", "src/core/stepper/newton_loop.cpp",
      "for (int i = 0; i < out.size(); ++i) out[i] = fixed[i] ? v[i] : (r_[i] - out[i]) / h;",
      "for (int i = 0; i < out.size(); ++i) out[i] = fixed[i] ? v[i] : (r_[i] - out[i]) / (2 * h);",
      "Jacobian products half too small"),
    M("NS14", "src/core/stepper/newton_stepper.cpp",
      "if (fixed[i]) f[i] = -r_try_[i];  // the support balances the residual",
      "if (fixed[i]) f[i] = r_try_[i];  // the support balances the residual",
      "support reactions with the wrong sign"),
    # --- contact ---
    M("K1", "src/core/contact/instrument_contact.cpp",
      "reaction.force -= force;",
      "reaction.force += force;",
      "instrument reaction with the wrong sign"),
    M("K2", "src/core/contact/instrument_contact.cpp",
      "reaction.torque -= (c.point.at(x) - instruments_[c.instrument].pose.translation()).cross(force);",
      "reaction.torque += (c.point.at(x) - instruments_[c.instrument].pose.translation()).cross(force);",
      "instrument torque with the wrong sign"),
    M("K3", "src/core/contact/tube.cpp",
      "load.pressure = -o.suction;",
      "load.pressure = o.suction;",
      "suction pushes instead of pulling"),
    M("K4", "src/core/contact/surface_contact.cpp",
      "const Eigen::Vector3d slip = p - in.pose * (in.pose_start.inverse() * c.point.at(x_stage));",
      "const Eigen::Vector3d slip = p - c.point.at(x_stage);",
      "slip measured against space, not against the moving instrument"),
    M("K5", "src/core/contact/krylov_contact_update.cpp",
      "if (friction > 0) direction += contact.frame.rightCols<2>() * (lambda.tail<2>() / lambda[0]);",
      "if (friction > 0) direction -= contact.frame.rightCols<2>() * (lambda.tail<2>() / lambda[0]);",
      "sliding force along the slip instead of against it (Krylov update)"),
    M("K6", "src/core/contact/surface_contact.cpp",
      "frame->col(2) = d.normal.cross(t1);",
      "frame->col(2) = t1.cross(d.normal);",
      "left-handed contact frame",
      equivalent="the tangents may be any orthonormal pair; the frame is only used as an orthonormal "
                 "basis (forces are carried in the world frame)"),
    M("K7", "src/core/contact/contact_detection.cpp",
      "worst = std::max(worst, lambda[0] > 0 ? std::abs(rows[0]) : -rows[0]);  // Signorini",
      "worst = std::max(worst, lambda[0] > 0 ? std::abs(rows[0]) : 0.0);  // Signorini",
      "penetration of a contact without force not counted as a violation"),
    M("K11", "src/core/contact/contact_updates.cpp",
      "change_[c] = contacts_[c].frame * (lambda.segment<3>(3 * c) - contacts_[c].lambda);",
      "change_[c] = contacts_[c].frame * lambda.segment<3>(3 * c);",
      "direct contact update adds the whole force, not its change (modified and full Newton)"),
    M("K8", "src/core/contact/contact_solver.cpp",
      "if (full[0] > 0 && full.tail<2>().norm() <= mu * full[0]) return full;  // sticks",
      "if (full[0] > 0 && full.tail<2>().norm() <= 2 * mu * full[0]) return full;  // sticks",
      "friction cone twice too wide"),
    M("K9", "src/core/contact/contact_solver.cpp",
      "out << n, mu * n * d;",
      "out << n, -mu * n * d;",
      "sliding friction along the slip (Gauss-Seidel)"),
    M("K10", "src/core/contact/contact_solver.cpp",
      "const double n = lambda_c[0] - (delta_c[0] + Wcc.row(0).tail<2>().dot(-lambda_c.tail<2>())) / Wcc(0, 0);",
      "const double n = lambda_c[0] - (delta_c[0] + Wcc.row(0).tail<2>().dot(lambda_c.tail<2>())) / Wcc(0, 0);",
      "sign of the tangential coupling in the frictionless update",
      equivalent="without friction the tangential forces are always zero, so the term vanishes"),
    M("K12", "src/core/contact/probe.cpp",
      "return around_point(x, pose.translation(), o.radius, -pose.linear().col(2));",
      "return around_point(x, pose.translation(), 0.5 * o.radius, -pose.linear().col(2));",
      "probe and grasper tips half their radius"),
    M("K13", "src/core/geometry/closest_points.cpp",
      "return {1 - v, v, 0};",
      "return {v, 1 - v, 0};",
      "closest point on a triangle's first edge with swapped weights"),
    M("K14", "src/core/geometry/closest_points.cpp",
      "w[(k + 1) % 3] = st[1];",
      "w[(k + 2) % 3] = st[1];",
      "segment-triangle closest point on the wrong edge (off by one)"),
    M("K15", "src/core/contact/node_compliance.cpp",
      "for (int t = 0; t <= s; ++t)",
      "for (int t = 0; t < s; ++t)",
      "a contact node's own compliance block left out (off by one)"),
    # --- rollback and time budget (newton_stepper.cpp) ---
    M("R1", "src/core/stepper/newton_stepper.cpp",
      "  mechanics_.restore(s.mechanics);\n  contact_.restore(s.contact);",
      "  mechanics_.restore(s.mechanics);",
      "a rollback leaves the contacts, poses and reactions of the failed step"),
    M("R2", "src/core/stepper/newton_stepper.cpp",
      "  mechanics_.restore(s.mechanics);\n  contact_.restore(s.contact);",
      "  contact_.restore(s.contact);",
      "a rollback leaves the rotations and warm starts of the failed step"),
    M("R3", "src/core/stepper/newton_loop.cpp",
      "if (s.result.iterations == 0 ||",
      "if (false ||",
      "out of time before the step's first iteration (no frame moves on)"),
    M("R4", "src/core/stepper/newton_stepper.cpp",
      "if (!(Clock::now() > deadline_ || (result.status != StepResult::Status::Converged &&",
      "if (!(false || (result.status != StepResult::Status::Converged &&",
      "out of time between stages ignored (the instruments reach their target, the tissue does not)"),
    M("R5", "src/core/stepper/newton_loop.cpp",
      "const bool fits = factor_.fits(deadline_);",
      "const bool fits = true;",
      "a modified-Newton refresh that starts its factorisation past the budget"),
    M("R6", "src/core/stepper/newton_loop.cpp",
      "  factor_.mark_stale();\n  if (contact_update) contact_.scale_update(0.0);\n  const bool fits = factor_.fits(deadline_);\n  if (fits) {\n",
      "  if (contact_update) contact_.scale_update(0.0);\n  const bool fits = factor_.fits(deadline_);\n  if (fits) {\n    factor_.mark_stale();\n",
      "a refresh deferred past the budget keeps the old factor (the next step does not refactorise)"),
    M("R7", "src/core/stepper/newton_loop.cpp",
      "  } else {\n    s.result.out_of_time = true;\n    s.result.message = \"time budget\";\n  }\n  s.norm = residual(x_, r_, &s.reference);",
      "  } else {\n    x_.swap(x_try_);\n    s.result.out_of_time = true;\n    s.result.message = \"time budget\";\n  }\n  s.norm = residual(x_, r_, &s.reference);",
      "a refresh deferred past the budget keeps the trial point that found no descent"),
    M("R8", "src/core/stepper/newton_loop.cpp",
      "(s.done() > 0 && fresh_factor && !factor_.fits(deadline_))",
      "(false)",
      "a factor judged stale after a step's first iteration is refreshed in the same step past the budget"),
    M("R9", "src/core/stepper/newton_stepper.cpp",
      "iteration_strategy().factorizes() && !factor_.fits(deadline_)",
      "false",
      "a later stage starts with a factorisation past the budget"),
    M("R10", "include/liver_sim/stepper/newton_stepper.h",
      "kRecoveryAfterRollbacks = 2;",
      "kRecoveryAfterRollbacks = 1;",
      "a recovery step after a single rollback"),
    M("R11", "src/core/stepper/newton_stepper.cpp",
      "    rollbacks_in_a_row_ = 0;\n    rotations_continued_",
      "    rotations_continued_",
      "a kept step leaves the count of rollbacks in a row"),
    M("R12", "src/core/stepper/newton_loop.cpp",
      "recovering_ ? std::max(solver_.max_iterations, kRecoveryIterations) : solver_.max_iterations",
      "solver_.max_iterations",
      "a recovery step held to the frame's iteration cap"),
    M("R13", "src/core/stepper/newton_stepper.cpp",
      "rollbacks_in_a_row_ = recovering_ ? 0 : rollbacks_in_a_row_ + 1;",
      "rollbacks_in_a_row_ = rollbacks_in_a_row_ + 1;",
      "recovery steps one after another while they diverge"),
]


def run(cmd, timeout, log):
    """Runs cmd (niced) with a timeout; returns (return code or 'timeout', seconds)."""
    start = time.monotonic()
    with open(log, "a") as out:
        out.write("$ " + " ".join(map(str, cmd)) + "\n")
        out.flush()
        proc = subprocess.Popen(["nice", "-n", "19"] + list(map(str, cmd)), stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the process group this call started
            proc.wait()
            rc = "timeout"
    return rc, time.monotonic() - start


def build(tests, log, timeout):
    """Builds the given test binaries only (and the core's parts they link)."""
    rc, _ = run(["make", "-C", BUILD, "-j2"] + [name for name, _ in tests], timeout, log)
    return rc == 0


def run_tests(tests, log, timeout):
    """Runs the tests in order; returns the first failing test binary, or None."""
    for name, args in tests:
        rc, _ = run([BIN / name] + args, timeout, log)
        if rc != 0:
            return f"{name} ({'timeout' if rc == 'timeout' else 'failed'})"
    return None


def applicable(m):
    text = (REPO / m.path).read_text()
    count = text.count(m.original)
    return "ok" if count == 1 else ("not applicable (text gone)" if count == 0 else f"not applicable ({count} matches)")


def restore_leftovers():
    """A run killed mid-mutation left its backup: put the original back."""
    if not BACKUP.exists():
        return
    for saved in BACKUP.rglob("*"):
        if saved.is_file():
            target = REPO / saved.relative_to(BACKUP)
            shutil.copy2(saved, target)
            print(f"restored {target} from an interrupted run", file=sys.stderr)
    shutil.rmtree(BACKUP)


def mutate_and_test(m, tests, log, build_timeout, test_timeout):
    source = REPO / m.path
    original = source.read_text()
    saved = BACKUP / m.path
    saved.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy2(source, saved)
    try:
        source.write_text(original.replace(m.original, m.replacement, 1))
        if not build(tests, log, build_timeout):
            return "build error"
        failed = run_tests(tests, log, test_timeout)
        return f"killed by {failed}" if failed else "survived"
    finally:
        source.write_text(original)
        saved.unlink()


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", help="comma-separated mutation keys")
    parser.add_argument("--list", action="store_true", help="list the mutations and whether each applies")
    parser.add_argument("--tests", help="comma-separated test binaries of the fast set to run (default: all)")
    parser.add_argument("--budget", type=float, default=120, help="minutes; mutations beyond it are not run")
    parser.add_argument("--test-timeout", type=float, default=240, help="seconds per test binary")
    parser.add_argument("--build-timeout", type=float, default=900, help="seconds per build")
    parser.add_argument("--log", default=str(REPO / "build" / "mutate.log"))
    args = parser.parse_args()

    selected = MUTATIONS
    if args.only:
        keys = args.only.split(",")
        unknown = set(keys) - {m.key for m in MUTATIONS}
        if unknown:
            parser.error("unknown mutation(s): " + ", ".join(sorted(unknown)))
        selected = [m for m in MUTATIONS if m.key in keys]
    if args.list:
        for m in selected:
            print(f"{m.key:5} {m.path:36} {applicable(m):28} {m.what}" + (" [equivalent]" if m.equivalent else ""))
        return 0

    tests = TESTS
    if args.tests:
        names = args.tests.split(",")
        tests = [t for t in TESTS if t[0] in names]
        if len(tests) != len(names):
            parser.error("--tests takes names among " + ", ".join(name for name, _ in TESTS))

    restore_leftovers()
    open(args.log, "w").close()
    start = time.monotonic()
    print("unmutated build and tests ...", file=sys.stderr)
    if not build(tests, args.log, args.build_timeout) or run_tests(tests, args.log, args.test_timeout):
        print(f"the unmutated suite does not pass: see {args.log}", file=sys.stderr)
        return 1

    rows = []
    for m in selected:
        status = applicable(m)
        if status == "ok":
            if (time.monotonic() - start) / 60 > args.budget:
                status = "not run (budget)"
            else:
                print(f"{m.key}: {m.what} ...", file=sys.stderr)
                status = mutate_and_test(m, tests, args.log, args.build_timeout, args.test_timeout)
                print(f"{m.key}: {status}", file=sys.stderr)
        rows.append((m, status))
    # The build again matches the source.
    if not build(tests, args.log, args.build_timeout):
        print("warning: the rebuild of the restored sources failed", file=sys.stderr)

    print("| mutation | file | change | result |\n|---|---|---|---|")
    for m, status in rows:
        shown = status
        if m.equivalent:
            shown = ("equivalent (survives): " if status == "survived" else f"CLAIMED EQUIVALENT, {status}: ") + m.equivalent
        print(f"| {m.key} | {m.path.split('/')[-1]} | {m.what} | {shown} |")
    counted = [(m, s) for m, s in rows if not m.equivalent and (s.startswith("killed") or s == "survived")]
    killed = sum(s.startswith("killed") for _, s in counted)
    survivors = [m.key for m, s in counted if s == "survived"]
    print(f"\nkilled {killed} of {len(counted)} ({100 * killed / max(1, len(counted)):.0f}%); "
          f"survivors: {', '.join(survivors) or 'none'}; "
          f"{sum(1 for m, _ in rows if m.equivalent)} equivalent; "
          f"{sum(1 for _, s in rows if not (s.startswith('killed') or s == 'survived'))} not counted otherwise; "
          f"{(time.monotonic() - start) / 60:.0f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
