// The background factorization hands over the factor of the matrix it was given.
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

}  // namespace
}  // namespace liver_sim
