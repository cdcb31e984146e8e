// The contact solver alone: Signorini and Coulomb at one contact, bilateral contacts.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <thread>

#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/contact/contact_solver.h"
#include "liver_sim/simulation/liver_model.h"
#include "regions.h"

namespace liver_sim {
namespace {

// One contact with W = w I: the gap closes, the tangential force sticks inside the cone and
// sits on its edge against the slip outside it; an open gap gives no force.
TEST(ContactSolver, SingleContactSignoriniAndCoulomb) {
  const double w = 2e-3, mu = 0.5;
  const Eigen::MatrixXd W = w * Eigen::MatrixXd::Identity(3, 3);
  const std::vector<char> unilateral = {0};
  auto solve = [&](const Eigen::Vector3d& delta0) {
    Eigen::VectorXd lambda = Eigen::VectorXd::Zero(3);
    const ContactSolveResult r = solve_frictional_contacts(W, delta0, unilateral, mu, 1e-14, 100, lambda);
    EXPECT_TRUE(r.converged);
    return Eigen::Vector3d(lambda);
  };
  const Eigen::Vector3d stick = solve({-1e-3, 0.2e-3, 0});  // |s| / w = 0.1 < mu g / w = 0.25
  EXPECT_NEAR(stick[0], 1e-3 / w, 1e-12);
  EXPECT_NEAR(stick[1], -0.2e-3 / w, 1e-12);
  const Eigen::Vector3d slide = solve({-1e-3, 0, -2e-3});
  EXPECT_NEAR(slide[0], 1e-3 / w, 1e-12);
  EXPECT_NEAR(slide[2], mu * slide[0], 1e-12) << "on the cone's edge, against the slip";
  EXPECT_EQ(solve({1e-3, 5e-3, 0}), Eigen::Vector3d::Zero());
}

// Two coupled contacts, bilateral: the exact solution of W lambda = -delta0.
TEST(ContactSolver, BilateralContactsSolveTheLinearSystem) {
  Eigen::MatrixXd W(6, 6);
  W.setRandom();
  W = W * W.transpose() + 6 * Eigen::MatrixXd::Identity(6, 6);
  const Eigen::VectorXd delta0 = Eigen::VectorXd::LinSpaced(6, -1, 1);
  Eigen::VectorXd lambda = Eigen::VectorXd::Zero(6);
  ASSERT_TRUE(solve_frictional_contacts(W, delta0, {1, 1}, 0.0, 1e-13, 1000, lambda).converged);
  EXPECT_LE((W * lambda + delta0).norm(), 1e-10);
}

}  // namespace
}  // namespace liver_sim
