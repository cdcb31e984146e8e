// GMRES on a non-symmetric system with a preconditioner.
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
