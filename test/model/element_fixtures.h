// Shared by the element tests: fields, rigid motions, materials, forces of one element set.
#pragma once

#include <Eigen/Geometry>

#include <random>

#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/model/membrane_cst.h"
#include "liver_sim/geometry/mesh.h"
#include "positions.h"

namespace liver_sim {

constexpr double kSize = 0.01;  // m
constexpr double kE = 5000.0;   // Pa

inline Eigen::VectorXd transform(const Eigen::VectorXd& x, const Eigen::Matrix3d& Q, const Eigen::Vector3d& t) {
  Eigen::VectorXd y(x.size());
  for (int i = 0; i < x.size(); i += 3) y.segment<3>(i) = Q * x.segment<3>(i) + t;
  return y;
}

// Global internal forces of a set of elements (tetrahedra or membranes) at positions x.
template <typename Elements, typename Nodes>
inline Eigen::VectorXd assembled_forces(Elements& elements, const Nodes& nodes, const Eigen::VectorXd& x) {
  Eigen::VectorXd f = Eigen::VectorXd::Zero(x.size());
  elements.update_rotations(x);
  Eigen::Matrix<double, 3 * Nodes::ColsAtCompileTime, 1> fe;
  for (int e = 0; e < elements.size(); ++e) {
    elements.element_force(e, x, fe);
    for (int k = 0; k < Nodes::ColsAtCompileTime; ++k) f.template segment<3>(3 * nodes(e, k)) += fe.template segment<3>(3 * k);
  }
  return f;
}

inline Eigen::VectorXd tet_forces(CorotationalTetra& tets, const Eigen::VectorXd& x) {
  return assembled_forces(tets, tets.elements(), x);
}

inline Eigen::VectorXd membrane_forces(MembraneCST& m, const Eigen::VectorXd& x) {
  return assembled_forces(m, m.triangles(), x);
}

inline Eigen::VectorXd random_field(int n, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  Eigen::VectorXd d(n);
  for (int i = 0; i < n; ++i) d[i] = u(rng);
  return d;
}

inline Eigen::Matrix3d some_rotation() {
  return Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
}

inline ParenchymaOptions material(RotationMethod method) {
  ParenchymaOptions o;
  o.young_modulus = kE;
  o.poisson_ratio = 0.45;
  o.rotation = method;
  return o;
}

inline CapsuleOptions capsule() {
  CapsuleOptions c;
  c.enabled = true;
  c.young_modulus = 8e6;
  c.thickness = 20e-6;
  c.poisson_ratio = 0.4;
  return c;
}

}  // namespace liver_sim
