// The contact nodes' compliance blocks against the inverse.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <random>
#include <thread>

#include "liver_sim/linalg/background_factorization.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/linalg/gmres.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/contact/node_compliance.h"
#include "liver_sim/linalg/sparse_pattern.h"
#include "linalg/assembled_system.h"

namespace liver_sim {
namespace {

// The 3 x 3 compliance blocks between nodes against the dense inverse, while the nodes asked for
// change: a large patch, then a small one (the cache keeps only these and gives memory back),
// then a new factor (the cache starts again). Checked to fail when keep_only moves a block
// without its transpose (the blocks below the diagonal off) and when a new factor keeps the old
// columns (every block off by the scale).
TEST(NodeCompliance, BlocksAreThoseOfTheInverseAsTheContactNodesChange) {
  Assembled A(6);
  const int n = A.pattern.rows();
  CholmodSolver solver;
  solver.analyze(n, A.pattern.column_start(), A.pattern.row_index());
  ASSERT_TRUE(solver.factorize(A.values));
  NodeCompliance compliance(n / 3);
  auto check = [&](const std::vector<int>& nodes, const Eigen::MatrixXd& inverse) {
    const double scale = inverse.cwiseAbs().maxCoeff();
    for (int a : nodes)
      for (int b : nodes)
        EXPECT_LE((compliance.block(a, b) - inverse.block<3, 3>(3 * a, 3 * b)).cwiseAbs().maxCoeff(), 1e-10 * scale)
            << a << " " << b;
  };
  const Eigen::MatrixXd inverse = A.dense.llt().solve(Eigen::MatrixXd::Identity(n, n));
  std::vector<int> patch;
  for (int i = n / 6; i < n / 3; i += 3) patch.push_back(i);  // the upper half: the clamped nodes decouple
  compliance.require(patch, solver);
  check(patch, inverse);
  const std::vector<int> small = {patch[7], patch[2], n / 3 - 2};  // the last one is new
  compliance.require(small, solver);
  EXPECT_EQ(compliance.kept(), 3) << "the nodes the large patch left are dropped";
  check(small, inverse);
  std::vector<double> stiffer = A.values;
  for (double& v : stiffer) v *= 2;
  ASSERT_TRUE(solver.factorize(stiffer));
  compliance.require(small, solver);
  check(small, 0.5 * inverse);
}

}  // namespace
}  // namespace liver_sim
