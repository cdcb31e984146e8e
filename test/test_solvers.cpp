// Linear algebra: the sparse pattern and scatter maps, CHOLMOD against a dense factorisation,
// GMRES on a non-symmetric operator.
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

namespace liver_sim {
namespace {

// Global stiffness of a small box assembled twice: through the pattern and scatter maps, and
// densely by plain index arithmetic.
struct Assembled {
  TetMesh mesh;
  SparsePattern pattern;
  std::vector<double> values;
  Eigen::MatrixXd dense;

  explicit Assembled(int divisions = 2)
      : mesh(make_box_mesh({0.01, 0.01, 0.01}, Eigen::Vector3i::Constant(divisions))),
        pattern(static_cast<int>(mesh.V.rows()), mesh.T) {
    CorotationalTetra tets(mesh.V, mesh.T, ParenchymaOptions{});
    const int n = pattern.rows();
    values.assign(pattern.nonzeros(), 0.0);
    dense.setZero(n, n);
    std::vector<int> map;
    for (int e = 0; e < mesh.T.rows(); ++e) {
      const int nodes[4] = {mesh.T(e, 0), mesh.T(e, 1), mesh.T(e, 2), mesh.T(e, 3)};
      map.clear();
      pattern.append_scatter_map(nodes, 4, map);
      scatter_add(tets.rest_stiffness(e), map.data(), values);
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          dense.block<3, 3>(3 * nodes[a], 3 * nodes[b]) += tets.rest_stiffness(e).block<3, 3>(3 * a, 3 * b);
    }
    // Clamp the bottom face so that the matrix is positive definite.
    for (int i = 0; i < mesh.V.rows(); ++i) {
      if (mesh.V(i, 2) > 1e-12) continue;
      for (int c = 0; c < 3; ++c) {
        const int d = 3 * i + c;
        dense.row(d).setZero();
        dense.col(d).setZero();
        dense(d, d) = 1;
        for (int k = 0; k < pattern.rows(); ++k) {
          const int idx = pattern.find(std::min(k, d), std::max(k, d));
          if (idx >= 0) values[idx] = (k == d) ? 1.0 : 0.0;
        }
      }
    }
  }
};

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

// Polls until `done` holds (the bound only keeps a hang from lasting).
template <class Done>
bool wait_until(Done done) {
  for (int k = 0; k < 60000; ++k) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ADD_FAILURE() << "the background thread did not finish within a minute";
  return false;
}

// The thread's factorisation once it is done.
std::optional<bool> taken_when_done(BackgroundFactorization& background, CholmodSolver& solver) {
  std::optional<bool> taken;
  wait_until([&] { return (taken = background.take(solver)).has_value(); });
  return taken;
}

// A factor made on the background thread and handed over solves the matrix it was given, as a
// dense Cholesky does, while the caller's old factor keeps serving until then; the handover
// counts as a factorisation (the contact's compliance cache keys on it). Checked to fail when
// take() hands over without swapping (the old matrix solved) and when cancel() is ignored (the
// thread then never turns idle).
TEST(BackgroundFactorization, HandsOverTheFactorOfTheMatrixItWasGiven) {
  Assembled A;
  const int n = A.pattern.rows();
  CholmodSolver solver;
  solver.analyze(n, A.pattern.column_start(), A.pattern.row_index());
  ASSERT_TRUE(solver.factorize(A.values));
  BackgroundFactorization background(n, A.pattern.column_start(), A.pattern.row_index());
  EXPECT_TRUE(background.idle());
  EXPECT_FALSE(background.take(solver).has_value());
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, 1.0, 3.0);
  Eigen::VectorXd x;

  std::vector<double> stiffer = A.values;
  for (double& a : stiffer) a *= 3.0;
  ASSERT_TRUE(background.start(stiffer));
  EXPECT_FALSE(background.start(A.values));  // one at a time
  solver.solve(b, x);  // the old factor serves meanwhile
  EXPECT_LE((x - A.dense.llt().solve(b)).norm(), 1e-10 * x.norm());
  const int before = solver.factorizations();
  ASSERT_EQ(taken_when_done(background, solver), std::optional<bool>(true));
  EXPECT_EQ(solver.factorizations(), before + 1);
  EXPECT_TRUE(background.idle());
  solver.solve(b, x);
  const Eigen::VectorXd expected = (3.0 * A.dense).llt().solve(b);
  EXPECT_LE((x - expected).norm(), 1e-10 * expected.norm());

  // The thread reuses the caller's old factor's storage: another round gives the next matrix.
  std::vector<double> softer = A.values;
  for (double& a : softer) a *= 0.5;
  ASSERT_TRUE(background.start(softer));
  ASSERT_EQ(taken_when_done(background, solver), std::optional<bool>(true));
  solver.solve(b, x);
  EXPECT_LE((x - (0.5 * A.dense).llt().solve(b)).norm(), 1e-10 * x.norm());

  // Dropped: never handed over, whether it was running or finished.
  for (int wait_ms : {0, 200}) {
    ASSERT_TRUE(background.start(A.values));
    std::this_thread::sleep_for(std::chrono::milliseconds(wait_ms));
    background.cancel();
    ASSERT_TRUE(wait_until([&] { return background.idle(); }));
    EXPECT_FALSE(background.take(solver).has_value());
    solver.solve(b, x);
    EXPECT_LE((x - (0.5 * A.dense).llt().solve(b)).norm(), 1e-10 * x.norm());
  }

  // Not positive definite: reported, the caller's factor kept.
  std::vector<double> indefinite = A.values;
  for (double& a : indefinite) a = -a;
  ASSERT_TRUE(background.start(indefinite));
  EXPECT_EQ(taken_when_done(background, solver), std::optional<bool>(false));
  solver.solve(b, x);
  EXPECT_LE((x - (0.5 * A.dense).llt().solve(b)).norm(), 1e-10 * x.norm());
}

TEST(Gmres, SolvesNonSymmetricSystemWithPreconditioner) {
  const int n = 60;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::MatrixXd M = Eigen::MatrixXd::Identity(n, n) * 4;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) M(i, j) += 0.3 * u(rng);
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, -1, 1);
  // Preconditioner: the inverse of the symmetric part (like the tangent versus the Jacobian).
  const Eigen::MatrixXd P = (0.5 * (M + M.transpose())).inverse();
  Gmres gmres;
  Eigen::VectorXd x;
  const int iterations = gmres.solve([&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = M * v; },
                                     [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = P * v; },
                                     b, x, 1e-10, 50);
  EXPECT_LT(iterations, 50);
  EXPECT_LE((M * x - b).norm(), 1e-9 * b.norm());
  EXPECT_LE(gmres.relative_residual(), 1e-10);
}

}  // namespace
}  // namespace liver_sim
