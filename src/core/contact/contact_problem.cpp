#include "liver_sim/contact/contact_problem.h"

#include <algorithm>
#include <limits>

#include "liver_sim/contact/contact_solver.h"

namespace liver_sim {

ContactProblem::ContactProblem(const MechanicalModel& mechanics)
    : mechanics_(mechanics), compliance_(static_cast<int>(mechanics.rest_positions().size() / 3)) {
  const Eigen::Index nodes = mechanics.rest_positions().size() / 3;
  node_vector_.assign(nodes, Eigen::Vector3d::Zero());
  node_marked_.assign(nodes, 0);
}

void ContactProblem::build(const std::vector<SurfaceContact>& contacts, CholmodSolver& factor, const Eigen::VectorXd& r) {
  free_nodes_.clear();
  try {
    for (const SurfaceContact& c : contacts)
      for (int j = 0; j < c.point.count; ++j) {
        const int node = c.point.nodes[j];
        if (mechanics_.fixed_by_scene(node) || node_marked_[node]) continue;
        free_nodes_.push_back(node);
        node_marked_[node] = 1;
      }
  } catch (...) {  // memory: no mark may outlive the list (a marked node is never listed again)
    for (int node : free_nodes_) node_marked_[node] = 0;
    throw;
  }
  for (int node : free_nodes_) node_marked_[node] = 0;
  compliance_.require(free_nodes_, factor);
  forward(factor, r);
  const int m = static_cast<int>(contacts.size());
  W_.resize(3 * m, 3 * m);
  delta_.resize(3 * m);
  lambda_.resize(3 * m);
  bilateral_.resize(m);
  for (int c = 0; c < m; ++c) {
    const SurfaceContact& a = contacts[c];
    delta_.segment<3>(3 * c) = a.rows + a.frame.transpose() * motion(a.point);
    lambda_.segment<3>(3 * c) = a.lambda;
    bilateral_[c] = a.held >= 0;
    for (int d = c; d < m; ++d) {
      const SurfaceContact& b = contacts[d];
      W_.block<3, 3>(3 * c, 3 * d) = a.frame.transpose() * compliance(a.point, b.point) * b.frame;
      W_.block<3, 3>(3 * d, 3 * c) = W_.block<3, 3>(3 * c, 3 * d).transpose();
    }
  }
}

int ContactProblem::solve(const ContactOptions& options, double force_tolerance) {
  return solve_frictional_contacts(W_, delta_, bilateral_, options.friction, gap_tolerance(options, force_tolerance),
                                   options.max_iterations, lambda_)
      .sweeps;
}

double ContactProblem::gap_tolerance(const ContactOptions& options, double force_tolerance) const {
  // A gap left open by e carries a force error of about e / W_cc.
  double compliance = std::numeric_limits<double>::infinity();
  for (Eigen::Index c = 0; c < W_.rows(); c += 3) compliance = std::min(compliance, W_(c, c));
  return std::min(0.01 * options.tolerance, force_tolerance * compliance);
}

void ContactProblem::forward(CholmodSolver& factor, const Eigen::VectorXd& b) {
  factor.forward(b, z_);
  for (int node : free_nodes_) node_vector_[node] = compliance_.dot(node, z_);
}

Eigen::Vector3d ContactProblem::motion(const SurfacePoint& p) const {
  Eigen::Vector3d predicted = Eigen::Vector3d::Zero();
  for (int j = 0; j < p.count; ++j)
    if (!mechanics_.fixed_by_scene(p.nodes[j])) predicted += p.weights[j] * node_vector_[p.nodes[j]];
  return predicted;
}

void ContactProblem::add_forward(const std::vector<SurfaceContact>& contacts, const std::vector<Eigen::Vector3d>& change) {
  for (int node : free_nodes_) node_vector_[node].setZero();
  for (size_t c = 0; c < contacts.size(); ++c) {
    const SurfacePoint& p = contacts[c].point;
    for (int j = 0; j < p.count; ++j)
      if (!mechanics_.fixed_by_scene(p.nodes[j])) node_vector_[p.nodes[j]] += p.weights[j] * change[c];
  }
  for (int node : free_nodes_) compliance_.add(node, node_vector_[node], z_);
}

void ContactProblem::backward(CholmodSolver& factor, Eigen::VectorXd& x) { factor.backward(z_, x); }

}  // namespace liver_sim
