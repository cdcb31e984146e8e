// The corotational beam against beam theory: rigid motions, Euler-Bernoulli, the circular arc.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <fstream>
#include <sstream>

#include "liver_sim/model/corotational_beam.h"
#include "liver_sim/simulation/liver_model.h"
#include "regions.h"
#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/io/vessel_io.h"

namespace liver_sim {
namespace {

TEST(Rotations, ExpLogRoundTripAndLeftJacobian) {
  for (const Eigen::Vector3d& w : {Eigen::Vector3d(1e-10, -2e-10, 3e-10), Eigen::Vector3d(0.3, -0.2, 0.5),
                                  Eigen::Vector3d(2.0, 1.0, -1.5)}) {
    EXPECT_LE((rotation_log(rotation_exp(w)) - w).norm(), 1e-12 * std::max(1.0, w.norm()));
    // d/dt exp(w + t v) = [J_l(w) v]x exp(w), checked by central differences.
    const Eigen::Vector3d v(0.2, 0.7, -0.4);
    const double h = 1e-6;
    const Eigen::Matrix3d dR = (rotation_exp(w + h * v) - rotation_exp(w - h * v)) / (2 * h);
    const Eigen::Matrix3d W = dR * rotation_exp(w).transpose();
    const Eigen::Vector3d omega(W(2, 1), W(0, 2), W(1, 0));
    EXPECT_LE((omega - left_jacobian(w) * v).norm(), 1e-8);
  }
}

// Free beams (no tissue): unknowns [p (3N), rotation vectors (3N)], node 0 clamped; static
// equilibrium by Newton with a finite-difference Jacobian, an independent check of the element.
struct FreeBeam {
  Eigen::MatrixX3d X;
  Eigen::MatrixX2i S;
  BeamSection section;
  Eigen::VectorXd q;                 // state
  Eigen::VectorXd force;             // dead nodal forces (3N)
  Eigen::VectorXd moment;            // dead spatial nodal moments (3N)

  FreeBeam(const Eigen::MatrixX3d& points, const BeamSection& s) : X(points), section(s) {
    const int n = static_cast<int>(X.rows());
    S.resize(n - 1, 2);
    for (int e = 0; e + 1 < n; ++e) S.row(e) << e, e + 1;
    q.setZero(6 * n);
    for (int i = 0; i < n; ++i) q.segment<3>(3 * i) = X.row(i).transpose();
    force.setZero(3 * n);
    moment.setZero(3 * n);
  }
  int nodes() const { return static_cast<int>(X.rows()); }

  Eigen::VectorXd residual(const Eigen::VectorXd& state, double load) const {
    const int n = nodes();
    CorotationalBeams beams(X, S, std::vector<BeamSection>(n - 1, section));
    std::vector<Eigen::Matrix3d> R(n);
    for (int i = 0; i < n; ++i) R[i] = rotation_exp(state.segment<3>(3 * n + 3 * i));
    beams.update_frames(state.head(3 * n), R);
    Eigen::VectorXd r = Eigen::VectorXd::Zero(6 * n);
    r.head(3 * n) = load * force;
    for (int i = 0; i < n; ++i)
      r.segment<3>(3 * n + 3 * i) = left_jacobian(state.segment<3>(3 * n + 3 * i)).transpose() * (load * moment.segment<3>(3 * i));
    Vector12d f;
    for (int e = 0; e < beams.size(); ++e) {
      beams.element_force(e, f);
      for (int end = 0; end < 2; ++end) {
        const int i = S(e, end);
        r.segment<3>(3 * i) -= f.segment<3>(6 * end);
        r.segment<3>(3 * n + 3 * i) -= left_jacobian(state.segment<3>(3 * n + 3 * i)).transpose() * f.segment<3>(6 * end + 3);
      }
    }
    return r;
  }

  // Free DOFs: all but node 0's position and rotation.
  std::vector<int> free_dofs() const {
    std::vector<int> d;
    for (int i = 0; i < 6 * nodes(); ++i)
      if (i >= 3 && !(i >= 3 * nodes() && i < 3 * nodes() + 3)) d.push_back(i);
    return d;
  }

  void solve(int load_steps) {
    const std::vector<int> dofs = free_dofs();
    const int k = static_cast<int>(dofs.size());
    for (int step = 1; step <= load_steps; ++step) {
      const double load = static_cast<double>(step) / load_steps;
      for (int it = 0; it < 30; ++it) {
        const Eigen::VectorXd r = residual(q, load);
        Eigen::VectorXd rf(k);
        for (int i = 0; i < k; ++i) rf[i] = r[dofs[i]];
        if (rf.norm() <= 1e-11 * (force.norm() + moment.norm() / X.col(0).norm())) break;
        Eigen::MatrixXd J(k, k);
        for (int j = 0; j < k; ++j) {
          const double h = 1e-7 * (dofs[j] < 3 * nodes() ? 1e-2 : 1.0);
          Eigen::VectorXd qp = q, qm = q;
          qp[dofs[j]] += h;
          qm[dofs[j]] -= h;
          const Eigen::VectorXd dr = (residual(qp, load) - residual(qm, load)) / (2 * h);
          for (int i = 0; i < k; ++i) J(i, j) = -dr[dofs[i]];
        }
        const Eigen::VectorXd dq = J.fullPivLu().solve(rf);
        for (int i = 0; i < k; ++i) q[dofs[i]] += dq[i];
      }
    }
  }
  Eigen::Vector3d tip_displacement() const {
    const int t = nodes() - 1;
    return q.segment<3>(3 * t) - X.row(t).transpose();
  }
};

BeamSection vessel_section() {
  BeamSection s;
  s.outer_radius = 0.002;
  s.wall_thickness = 0.0005;
  s.young_modulus = 0.62e6;
  s.poisson_ratio = 0.45;
  return s;
}

Eigen::MatrixX3d straight_line(const Eigen::Vector3d& from, const Eigen::Vector3d& to, int segments) {
  Eigen::MatrixX3d X(segments + 1, 3);
  for (int i = 0; i <= segments; ++i) X.row(i) = (from + (to - from) * i / double(segments)).transpose();
  return X;
}

TEST(CorotationalBeam, RigidMotionGivesZeroForce) {
  Eigen::MatrixX3d X(3, 3);
  X << 0, 0, 0, 0.01, 0.002, 0, 0.018, 0.006, 0.003;
  Eigen::MatrixX2i S(2, 2);
  S << 0, 1, 1, 2;
  CorotationalBeams beams(X, S, {vessel_section(), vessel_section()});
  const Eigen::Matrix3d Q = rotation_exp(Eigen::Vector3d(0.7, -1.9, 0.4));
  const Eigen::Vector3d shift(0.03, -0.02, 0.05);
  Eigen::VectorXd p(9);
  for (int i = 0; i < 3; ++i) p.segment<3>(3 * i) = Q * X.row(i).transpose() + shift;
  beams.update_frames(p, std::vector<Eigen::Matrix3d>(3, Q));
  // Force scale: a bending force for a unit-ish rotation, 12 E I / L^2.
  const double scale = 12 * 0.62e6 * vessel_section().second_moment() / (0.01 * 0.01);
  Vector12d f;
  for (int e = 0; e < 2; ++e) {
    beams.element_force(e, f);
    EXPECT_LE(f.norm(), 1e-12 * scale) << "element " << e;
  }
}

TEST(CorotationalBeam, CantileverTipLoadMatchesEulerBernoulli) {
  const double L = 0.1;
  const BeamSection s = vessel_section();
  const double EI = s.young_modulus * s.second_moment();
  const double P = 3 * EI * 1e-4 * L / (L * L * L);  // tip deflection 1e-4 L
  FreeBeam beam(straight_line({0, 0, 0}, {L, 0, 0}, 10), s);
  beam.force[3 * 10 + 1] = P;
  beam.solve(1);
  const Eigen::Vector3d u = beam.tip_displacement();
  EXPECT_NEAR(u.y(), P * L * L * L / (3 * EI), 0.01 * P * L * L * L / (3 * EI));
  EXPECT_NEAR(beam.q[3 * 11 + 3 * 10 + 2], P * L * L / (2 * EI), 0.01 * P * L * L / (2 * EI));  // tip slope
  EXPECT_LE(std::abs(u.z()), 1e-9 * u.y());
}

TEST(CorotationalBeam, CantileverIsInvariantUnderRigidRotation) {
  const double L = 0.1;
  const BeamSection s = vessel_section();
  const double P = 3 * s.young_modulus * s.second_moment() * 0.05 / (L * L);  // 5% deflection
  FreeBeam a(straight_line({0, 0, 0}, {L, 0, 0}, 8), s);
  a.force[3 * 8 + 1] = P;
  a.solve(2);
  const Eigen::Matrix3d Q = rotation_exp(Eigen::Vector3d(0.3, 1.1, -0.6));
  FreeBeam b(straight_line({0, 0, 0}, Q * Eigen::Vector3d(L, 0, 0), 8), s);
  b.force.segment<3>(3 * 8) = Q * Eigen::Vector3d(0, P, 0);
  b.solve(2);
  EXPECT_LE((b.tip_displacement() - Q * a.tip_displacement()).norm(), 1e-8 * a.tip_displacement().norm());
}

// Large rotation: an end moment M bends the cantilever into a circular arc of curvature M / EI.
TEST(CorotationalBeam, EndMomentBendsIntoCircularArc) {
  const double L = 0.1;
  const BeamSection s = vessel_section();
  const double EI = s.young_modulus * s.second_moment();
  const double kappa = M_PI / (2 * L);  // a quarter circle
  FreeBeam beam(straight_line({0, 0, 0}, {L, 0, 0}, 20), s);
  beam.moment[3 * 20 + 2] = EI * kappa;
  beam.solve(8);
  const Eigen::Vector3d tip = beam.q.segment<3>(3 * 20);
  EXPECT_NEAR(tip.x(), std::sin(kappa * L) / kappa, 0.01 * L);
  EXPECT_NEAR(tip.y(), (1 - std::cos(kappa * L)) / kappa, 0.01 * L);
  EXPECT_NEAR(rotation_log(rotation_exp(beam.q.segment<3>(3 * 21 + 3 * 20))).z(), M_PI / 2, 0.01);
}

// --- Beams embedded in a soft block ---------------------------------------------------------

}  // namespace
}  // namespace liver_sim
