#include "liver_sim/contact/node_compliance.h"

#include <algorithm>

namespace liver_sim {

NodeCompliance::NodeCompliance(int nodes) : slot_(nodes, -1) {}

void NodeCompliance::require(const std::vector<int>& nodes, CholmodSolver& factor) {
  if (&factor != factor_ || factor.factorizations() != factorization_) {
    for (int node : nodes_) slot_[node] = -1;
    nodes_.clear();
    columns_of_.clear();
    factor_ = &factor;
    factorization_ = factor.factorizations();
  }
  int missing = 0;
  for (int node : nodes) missing += slot_[node] < 0;
  if (missing == 0) return;
  try {
    fill(nodes, missing, factor);
  } catch (...) {  // memory: a slot may have no columns yet; the cache starts again
    std::fill(slot_.begin(), slot_.end(), -1);
    nodes_.clear();
    columns_of_.clear();
    factor_ = nullptr;
    throw;
  }
}

void NodeCompliance::fill(const std::vector<int>& nodes, int missing, CholmodSolver& factor) {
  if (kept() + missing > 2 * static_cast<int>(nodes.size()) + 32) keep_only(nodes);
  for (int node : nodes) {
    if (slot_[node] >= 0) continue;
    const int s = kept();
    slot_[node] = s;
    nodes_.push_back(node);
    columns_of_.resize(3 * (s + 1));
    for (int d = 0; d < 3; ++d) factor.forward_unit(3 * node + d, columns_of_[3 * s + d]);
    columns_ += 3;
    if (blocks_.cols() < 3 * (s + 1)) {
      const Eigen::Index size = std::max<Eigen::Index>(3 * (s + 1), 2 * blocks_.cols());
      blocks_.conservativeResize(size, size);
    }
    for (int t = 0; t <= s; ++t)
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          const double g = factor.dot(columns_of_[3 * s + i], columns_of_[3 * t + j]);
          blocks_(3 * s + i, 3 * t + j) = g;
          blocks_(3 * t + j, 3 * s + i) = g;
        }
  }
}

void NodeCompliance::keep_only(const std::vector<int>& nodes) {
  std::vector<int> keep;  // old slots, in their order
  for (int s = 0; s < kept(); ++s)
    if (std::find(nodes.begin(), nodes.end(), nodes_[s]) != nodes.end()) keep.push_back(s);
  for (int node : nodes_) slot_[node] = -1;
  std::vector<int> kept_nodes;
  for (size_t k = 0; k < keep.size(); ++k) {
    const int s = keep[k];
    for (size_t l = 0; l <= k; ++l) {
      const Eigen::Matrix3d g = blocks_.block<3, 3>(3 * s, 3 * keep[l]);
      blocks_.block<3, 3>(3 * k, 3 * l) = g;
      blocks_.block<3, 3>(3 * l, 3 * k) = g.transpose();
    }
    for (int d = 0; d < 3; ++d) std::swap(columns_of_[3 * k + d], columns_of_[3 * s + d]);
    slot_[nodes_[s]] = static_cast<int>(k);
    kept_nodes.push_back(nodes_[s]);
  }
  nodes_.swap(kept_nodes);
  columns_of_.resize(3 * nodes_.size());
  // The blocks grow with the square of the nodes: after a large contact patch has gone, give
  // the memory back rather than keep its high-water mark for the rest of the session.
  const Eigen::Index needed = 3 * static_cast<Eigen::Index>(nodes_.size());
  if (blocks_.cols() > 4 * needed + 96) blocks_.conservativeResize(2 * needed, 2 * needed);
}

Eigen::Matrix3d NodeCompliance::block(int a, int b) const {
  return blocks_.block<3, 3>(3 * slot_[a], 3 * slot_[b]);
}

Eigen::Vector3d NodeCompliance::dot(int a, const Eigen::VectorXd& z) const {
  const int s = slot_[a];
  return Eigen::Vector3d(factor_->dot(columns_of_[3 * s], z), factor_->dot(columns_of_[3 * s + 1], z),
                         factor_->dot(columns_of_[3 * s + 2], z));
}

void NodeCompliance::add(int a, const Eigen::Vector3d& f, Eigen::VectorXd& z) const {
  const int s = slot_[a];
  for (int d = 0; d < 3; ++d) factor_->add(columns_of_[3 * s + d], f[d], z);
}

}  // namespace liver_sim
