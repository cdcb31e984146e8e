#include "liver_sim/model/corotational_beam.h"

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <stdexcept>

namespace liver_sim {
namespace {

// Linear Euler-Bernoulli beam along local x, DOFs [u1 v1 w1 tx1 ty1 tz1 u2 v2 w2 tx2 ty2 tz2].
Matrix12d local_beam_stiffness(double L, const BeamSection& s) {
  const double E = s.young_modulus, G = E / (2 * (1 + s.poisson_ratio));
  const double A = s.area(), I = s.second_moment(), J = 2 * I;
  Matrix12d K = Matrix12d::Zero();
  auto add = [&K](int i, int j, double v) {
    K(i, j) += v;
    if (i != j) K(j, i) += v;
  };
  const double ka = E * A / L, kt = G * J / L;
  add(0, 0, ka), add(6, 6, ka), add(0, 6, -ka);
  add(3, 3, kt), add(9, 9, kt), add(3, 9, -kt);
  const double b = E * I / (L * L * L);
  // Bending in the x-y plane: (v, theta_z); in the x-z plane: (w, theta_y) with opposite signs
  // of the coupling terms (theta_y = -dw/dx).
  for (const auto& plane : {std::array<int, 3>{1, 5, +1}, std::array<int, 3>{2, 4, -1}}) {
    const int v1 = plane[0], t1 = plane[1], v2 = plane[0] + 6, t2 = plane[1] + 6;
    const double sg = plane[2];
    add(v1, v1, 12 * b), add(v2, v2, 12 * b), add(v1, v2, -12 * b);
    add(v1, t1, sg * 6 * L * b), add(v1, t2, sg * 6 * L * b);
    add(v2, t1, -sg * 6 * L * b), add(v2, t2, -sg * 6 * L * b);
    add(t1, t1, 4 * L * L * b), add(t2, t2, 4 * L * L * b), add(t1, t2, 2 * L * L * b);
  }
  return K;
}

// Unit vector of `q` orthogonal to unit `e1` (Gram-Schmidt); `fallback` if q is along e1.
Eigen::Vector3d orthogonal_part(const Eigen::Vector3d& q, const Eigen::Vector3d& e1, const Eigen::Vector3d& fallback) {
  Eigen::Vector3d e2 = q - e1.dot(q) * e1;
  if (e2.norm() < 1e-6) e2 = fallback - e1.dot(fallback) * e1;
  return e2.normalized();
}

}  // namespace

Eigen::Matrix3d rotation_exp(const Eigen::Vector3d& w) {
  const double a = w.norm();
  const Eigen::Matrix3d W = cross_matrix(w);
  if (a < 1e-8) return Eigen::Matrix3d::Identity() + W + 0.5 * W * W;
  return Eigen::Matrix3d::Identity() + std::sin(a) / a * W + (1 - std::cos(a)) / (a * a) * W * W;
}

Eigen::Vector3d rotation_log(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  if (q.w() < 0) q.coeffs() *= -1;
  const double s = q.vec().norm();
  if (s < 1e-12) return 2 * q.vec();  // angle ~ 2 s
  return 2 * std::atan2(s, q.w()) / s * q.vec();
}

Eigen::Matrix3d left_jacobian(const Eigen::Vector3d& w) {
  const double a = w.norm();
  const Eigen::Matrix3d W = cross_matrix(w);
  if (a < 1e-6) return Eigen::Matrix3d::Identity() + 0.5 * W + W * W / 6.0;
  return Eigen::Matrix3d::Identity() + (1 - std::cos(a)) / (a * a) * W + (a - std::sin(a)) / (a * a * a) * W * W;
}

double BeamSection::area() const {
  const double ri = outer_radius - wall_thickness;
  return M_PI * (outer_radius * outer_radius - ri * ri);
}

double BeamSection::second_moment() const {
  const double ri = outer_radius - wall_thickness;
  return M_PI / 4 * (std::pow(outer_radius, 4) - std::pow(ri, 4));
}

CorotationalBeams::CorotationalBeams(const Eigen::MatrixX3d& X, const Eigen::MatrixX2i& segments,
                                     const std::vector<BeamSection>& sections)
    : segments_(segments) {
  if (static_cast<int>(sections.size()) != segments.rows())
    throw std::invalid_argument("beams: one section per segment expected");
  const int m = static_cast<int>(segments.rows());
  L_.resize(m);
  rest_frame_.resize(m);
  K_local_.resize(m);
  frame_.resize(m);
  local_deformation_.assign(m, Vector12d::Zero());
  local_force_.assign(m, Vector12d::Zero());
  for (int e = 0; e < m; ++e) {
    const Eigen::Vector3d d = X.row(segments(e, 1)) - X.row(segments(e, 0));
    L_[e] = d.norm();
    if (!(L_[e] > 0)) throw std::invalid_argument("beams: segment " + std::to_string(e) + " has zero length");
    const Eigen::Vector3d e1 = d / L_[e];
    // Second axis from the world axis least aligned with the chord: the same for both node
    // orders, so the element does not depend on how the segment is written.
    Eigen::Index k;
    e1.cwiseAbs().minCoeff(&k);
    const Eigen::Vector3d e2 = orthogonal_part(Eigen::Vector3d::Unit(k), e1, Eigen::Vector3d::Unit((k + 1) % 3));
    rest_frame_[e].col(0) = e1;
    rest_frame_[e].col(1) = e2;
    rest_frame_[e].col(2) = e1.cross(e2);
    frame_[e] = rest_frame_[e];
    K_local_[e] = local_beam_stiffness(L_[e], sections[e]);
  }
}

void CorotationalBeams::update_frames(const Eigen::VectorXd& p, const std::vector<Eigen::Matrix3d>& R) {
  for (int e = 0; e < size(); ++e) {
    const int a = segments_(e, 0), b = segments_(e, 1);
    const Eigen::Vector3d chord = p.segment<3>(3 * b) - p.segment<3>(3 * a);
    const double l = chord.norm();
    const Eigen::Vector3d e1 = chord / l;
    // Mean nodal rotation (geodesic midpoint): symmetric in the two nodes.
    const Eigen::Matrix3d Rm = R[a] * rotation_exp(0.5 * rotation_log(R[a].transpose() * R[b]));
    const Eigen::Matrix3d& E0 = rest_frame_[e];
    Eigen::Matrix3d& E = frame_[e];
    E.col(0) = e1;
    E.col(1) = orthogonal_part(Rm * E0.col(1), e1, Rm * E0.col(2));
    E.col(2) = e1.cross(E.col(1));
    Vector12d d = Vector12d::Zero();
    d.segment<3>(3) = rotation_log(E.transpose() * R[a] * E0);
    d[6] = l - L_[e];
    d.segment<3>(9) = rotation_log(E.transpose() * R[b] * E0);
    local_deformation_[e] = d;
    local_force_[e] = K_local_[e] * d;
  }
}

void CorotationalBeams::element_force(int e, Vector12d& f) const {
  for (int k = 0; k < 4; ++k) f.segment<3>(3 * k) = frame_[e] * local_force_[e].segment<3>(3 * k);
}

void CorotationalBeams::element_tangent(int e, Matrix12d& K) const {
  Matrix12d T = Matrix12d::Zero();  // world -> local
  for (int k = 0; k < 4; ++k) T.block<3, 3>(3 * k, 3 * k) = frame_[e].transpose();
  K.noalias() = T.transpose() * K_local_[e] * T;
}

}  // namespace liver_sim
