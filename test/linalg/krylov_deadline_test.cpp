// The Krylov solvers stop at a deadline with the iterate they have (Gmres, ConjugateGradient):
// a deadline already passed stops them after their first iteration, and that iterate is a
// partial solve, never worse than none. Iteration counts are asserted, never times.
// Mutations killed (tried): either solver's deadline check removed (it runs to its tolerance).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "liver_sim/linalg/conjugate_gradient.h"
#include "liver_sim/linalg/gmres.h"

namespace liver_sim {
namespace {

using Clock = Gmres::Clock;

// A system that takes either solver many iterations (no preconditioner): symmetric positive
// definite, with a spread spectrum, plus a skew part for GMRES.
struct System {
  Eigen::MatrixXd A, skew;
  Eigen::VectorXd b;
  System() {
    const int n = 80;
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1, 1);
    Eigen::MatrixXd G(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) G(i, j) = u(rng);
    A = G * G.transpose() + 0.1 * Eigen::MatrixXd::Identity(n, n);
    skew = 0.2 * (G - G.transpose());
    b = Eigen::VectorXd::LinSpaced(n, -1, 1);
  }
};

const auto identity = [](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = v; };

TEST(KrylovDeadline, GmresPastItsDeadlineStopsAfterOneIterationWithAResidualNoWorse) {
  const System s;
  const Eigen::MatrixXd M = s.A + s.skew;
  const Gmres::Operator op = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = M * v; };
  Gmres gmres;
  Eigen::VectorXd x;
  const int unlimited = gmres.solve(op, identity, s.b, x, 1e-10, 60);
  ASSERT_GT(unlimited, 5);
  EXPECT_FALSE(gmres.out_of_time());
  EXPECT_EQ(gmres.solve(op, identity, s.b, x, 1e-10, 60, Clock::now() - Clock::duration(1)), 1);
  EXPECT_TRUE(gmres.out_of_time());
  // The first iterate minimises the residual along the preconditioned b: below ||b|| unless
  // b is orthogonal to M b (it is not: M is positive definite in its symmetric part).
  EXPECT_LT((s.b - M * x).norm(), s.b.norm());
  EXPECT_NEAR(gmres.relative_residual(), (s.b - M * x).norm() / s.b.norm(), 1e-12);
}

TEST(KrylovDeadline, ConjugateGradientPastItsDeadlineStopsAfterOneIterationWithALowerEnergy) {
  const System s;
  const Gmres::Operator op = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = s.A * v; };
  ConjugateGradient cg;
  Eigen::VectorXd x;
  const int unlimited = cg.solve(op, identity, s.b, x, 1e-10, 500);
  ASSERT_GT(unlimited, 5);
  EXPECT_FALSE(cg.out_of_time());
  EXPECT_EQ(cg.solve(op, identity, s.b, x, 1e-10, 500, Clock::now() - Clock::duration(1)), 1);
  EXPECT_TRUE(cg.out_of_time());
  // The energy 1/2 x.Ax - b.x, 0 at x = 0, is lower at the first iterate: a descent direction.
  EXPECT_LT(0.5 * x.dot(s.A * x) - s.b.dot(x), 0.0);
}

}  // namespace
}  // namespace liver_sim
