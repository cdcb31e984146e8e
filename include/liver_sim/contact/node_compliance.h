// Compliance between the nodes in contact, from the stepper's factor, ROS-free: the 3 x 3 blocks
// G_ab = E_a^T A^-1 E_b (E_a: the three unit columns of node a's DOFs) from which the contact's
// Delassus operator W = H A^-1 H^T is built, and the products with a solve's forward half that
// let one solve carry the contact forces. Each node keeps its three sparse forward columns
// L^-1 P E_a (cholmod_solver.h): a block costs inner products over the shared elimination-tree
// path, not solves. Cached while the factor lasts; knows nothing of instruments.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/linalg/cholmod_solver.h"

namespace liver_sim {

class NodeCompliance {
 public:
  explicit NodeCompliance(int nodes);

  // Every node of `nodes` gets its forward columns and its blocks with the nodes already kept,
  // computed with `factor`; a new factor first empties the cache. When the cache holds more than
  // twice what is asked (nodes the contacts left), it keeps only these. An exception (memory)
  // empties the cache.
  void require(const std::vector<int>& nodes, CholmodSolver& factor);
  // G_ab (3 x 3, m/N) for nodes that are kept.
  Eigen::Matrix3d block(int a, int b) const;
  // E_a^T A^-1 b = (L^-1 P E_a)^T z for z = L^-1 P b (the forward half of a solve), and
  // z += L^-1 P E_a f: the forward half of a force f at node a.
  Eigen::Vector3d dot(int a, const Eigen::VectorXd& z) const;
  void add(int a, const Eigen::Vector3d& f, Eigen::VectorXd& z) const;

  // Forward columns computed since construction (3 per node taken in).
  long columns() const { return columns_; }
  int kept() const { return static_cast<int>(nodes_.size()); }

 private:
  void fill(const std::vector<int>& nodes, int missing, CholmodSolver& factor);  // require's work
  void keep_only(const std::vector<int>& nodes);

  const CholmodSolver* factor_ = nullptr;
  int factorization_ = -1;            // factor.factorizations() when the cache was filled
  std::vector<int> slot_;             // per node: its slot, or -1
  std::vector<int> nodes_;            // node of each slot
  std::vector<CholmodSolver::SparseColumn> columns_of_;  // 3 per slot
  Eigen::MatrixXd blocks_;            // 3 slots x 3 slots, symmetric; the first 3 kept() rows and columns are valid
  long columns_ = 0;
};

}  // namespace liver_sim
