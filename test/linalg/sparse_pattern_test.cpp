// The sparse pattern's scattered assembly and products against dense ones.
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

TEST(SparsePattern, ScatteredAssemblyEqualsDenseAssembly) {
  Assembled A;
  Eigen::MatrixXd from_pattern = Eigen::MatrixXd::Zero(A.pattern.rows(), A.pattern.rows());
  for (int col = 0; col < A.pattern.rows(); ++col)
    for (int k = A.pattern.column_start()[col]; k < A.pattern.column_start()[col + 1]; ++k) {
      from_pattern(A.pattern.row_index()[k], col) = A.values[k];
      from_pattern(col, A.pattern.row_index()[k]) = A.values[k];
    }
  EXPECT_LE((from_pattern - A.dense).norm(), 1e-12 * A.dense.norm());
  // Every structurally coupled pair of nodes is in the pattern, nothing else.
  int couplings = 0;
  for (int i = 0; i < A.pattern.rows(); ++i)
    for (int j = i; j < A.pattern.rows(); ++j) couplings += (A.pattern.find(i, j) >= 0);
  EXPECT_EQ(couplings, A.pattern.nonzeros());
}

TEST(SparsePattern, SymmetricProductMatchesDense) {
  Assembled A;
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(A.pattern.rows(), -1.0, 2.0);
  Eigen::VectorXd y;
  A.pattern.multiply(A.values, x, y);
  EXPECT_LE((y - A.dense * x).norm(), 1e-12 * (A.dense * x).norm());
}

}  // namespace
}  // namespace liver_sim
