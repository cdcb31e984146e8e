// CHOLMOD against dense Cholesky: solves, entries of the inverse, indefinite and non-finite matrices.
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

TEST(CholmodSolver, SolvesLikeDenseCholeskyAndReusesAnalysis) {
  Assembled A;
  CholmodSolver solver;
  solver.analyze(A.pattern.rows(), A.pattern.column_start(), A.pattern.row_index());
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(A.pattern.rows(), 1.0, 3.0);
  for (double scale : {1.0, 2.5}) {  // new values, same pattern: no new analysis
    std::vector<double> v = A.values;
    for (double& a : v) a *= scale;
    ASSERT_TRUE(solver.factorize(v));
    Eigen::VectorXd x;
    solver.solve(b, x);
    const Eigen::VectorXd expected = (scale * A.dense).llt().solve(b);
    EXPECT_LE((x - expected).norm(), 1e-10 * expected.norm());
  }
  EXPECT_EQ(solver.analyses(), 1);
  EXPECT_EQ(solver.factorizations(), 2);
  // Several right-hand sides at once, as the dense solve's columns; none gives none (a scene
  // without targets: this crashed inside CHOLMOD).
  Eigen::MatrixXd B(A.pattern.rows(), 2), X;
  B << b, b.reverse();
  solver.solve(B, X);
  EXPECT_LE((X - (2.5 * A.dense).llt().solve(B)).norm(), 1e-10 * X.norm());
  solver.solve(Eigen::MatrixXd(A.pattern.rows(), 0), X);
  EXPECT_EQ(X.rows(), A.pattern.rows());
  EXPECT_EQ(X.cols(), 0);
}

// The halves of a solve and the sparse forward columns against a dense inverse, on a box whose
// factor has many supernodes. Checked to fail when forward_unit skips the update of the rows
// below a supernode's diagonal block (entries off by up to 100%), or when dot() compares the
// paths from the leaf end instead of the root (0 where the inverse is not).
TEST(CholmodSolver, HalvesAndSparseColumnsGiveEntriesOfTheInverse) {
  Assembled A(6);
  const int n = A.pattern.rows();
  CholmodSolver solver;
  solver.analyze(n, A.pattern.column_start(), A.pattern.row_index());
  ASSERT_TRUE(solver.factorize(A.values));
  const Eigen::MatrixXd inverse = A.dense.llt().solve(Eigen::MatrixXd::Identity(n, n));
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, -1.0, 3.0);
  Eigen::VectorXd z, x;
  solver.forward(b, z);
  solver.backward(z, x);
  EXPECT_LE((x - inverse * b).norm(), 1e-10 * (inverse * b).norm());
  std::vector<int> rows;
  for (int i = 0; i < n; i += 37) rows.push_back(i);
  std::vector<CholmodSolver::SparseColumn> y(rows.size());
  double stored = 0;
  for (size_t a = 0; a < rows.size(); ++a) {
    solver.forward_unit(rows[a], y[a]);
    stored += y[a].values.size();
  }
  const double scale = inverse.cwiseAbs().maxCoeff();
  for (size_t a = 0; a < rows.size(); ++a) {
    for (size_t c = 0; c < rows.size(); ++c)
      EXPECT_NEAR(solver.dot(y[a], y[c]), inverse(rows[a], rows[c]), 1e-10 * scale) << rows[a] << " " << rows[c];
    EXPECT_NEAR(solver.dot(y[a], z), inverse.row(rows[a]).dot(b), 1e-10 * (inverse * b).norm());
  }
  // z + s L^-1 P e_i solves backward to A^-1 (b + s e_i).
  solver.add(y[1], 2.5, z);
  solver.backward(z, x);
  Eigen::VectorXd rhs = b;
  rhs[rows[1]] += 2.5;
  EXPECT_LE((x - inverse * rhs).norm(), 1e-10 * (inverse * rhs).norm());
  // The columns are sparse: on average well under the full length.
  EXPECT_LT(stored / rows.size(), 0.8 * n);
}

TEST(CholmodSolver, ReportsIndefiniteAndNonFiniteMatrices) {
  Assembled A;
  CholmodSolver solver;
  solver.analyze(A.pattern.rows(), A.pattern.column_start(), A.pattern.row_index());
  std::vector<double> v = A.values;
  for (double& a : v) a = -a;
  EXPECT_FALSE(solver.factorize(v));
  EXPECT_FALSE(solver.factorized());
  v = A.values;
  v[3] = std::nan("");
  EXPECT_FALSE(solver.factorize(v));
  ASSERT_TRUE(solver.factorize(A.values));
}

}  // namespace
}  // namespace liver_sim
