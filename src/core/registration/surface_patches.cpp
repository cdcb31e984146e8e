#include "liver_sim/registration/surface_patches.h"

#include <cmath>
#include <limits>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {

SurfacePatches make_surface_patches(MechanicalModel& m, double spacing) {
  const Eigen::VectorXd& X = m.rest_positions();
  const Eigen::MatrixX3i& F = m.boundary();
  Eigen::VectorXd area = Eigen::VectorXd::Zero(X.size() / 3);
  for (int t = 0; t < F.rows(); ++t) {
    const double a = 0.5 * (node(X, F(t, 1)) - node(X, F(t, 0))).cross(node(X, F(t, 2)) - node(X, F(t, 0))).norm();
    for (int j = 0; j < 3; ++j) area[F(t, j)] += a / 3;
  }
  SurfacePatches p;
  for (int n : m.boundary_nodes()) {
    bool far = true;
    for (const Eigen::Vector3d& c : p.centres) far &= (node(X, n) - c).norm() >= spacing;
    if (far) p.centres.push_back(node(X, n));
  }
  const double width = 0.5 * spacing;
  const std::vector<char>& fixed = m.fixed_dofs();
  for (const Eigen::Vector3d& c : p.centres) {
    std::vector<int> nodes;
    std::vector<double> weights;
    double total = 0;
    for (int n : m.boundary_nodes()) {
      const double d = (node(X, n) - c).norm();
      if (d > 3 * width || fixed[3 * n]) continue;
      nodes.push_back(n);
      weights.push_back(area[n] * std::exp(-0.5 * d * d / (width * width)));
      total += weights.back();
    }
    for (double& w : weights) w /= total;  // total > 0 when any node is free
    p.nodes.push_back(std::move(nodes));
    p.weights.push_back(std::move(weights));
  }
  p.triangle_patch.resize(F.rows());
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d centroid = (node(X, F(t, 0)) + node(X, F(t, 1)) + node(X, F(t, 2))) / 3;
    double best = std::numeric_limits<double>::infinity();
    for (size_t k = 0; k < p.centres.size(); ++k)
      if ((p.centres[k] - centroid).norm() < best) best = (p.centres[k] - centroid).norm(), p.triangle_patch[t] = static_cast<int>(k);
  }
  return p;
}

std::vector<Eigen::Vector3d> patch_spring_forces(const SurfacePatches& patches, const Eigen::MatrixX3i& boundary,
                                                 const std::vector<SurfaceTarget>& springs, const Eigen::VectorXd& x) {
  std::vector<Eigen::Vector3d> force(patches.centres.size(), Eigen::Vector3d::Zero());
  for (const SurfaceTarget& s : springs) force[patches.triangle_patch[s.triangle]] -= s.stiffness * s.stretch(x, boundary);
  return force;
}

}  // namespace liver_sim
