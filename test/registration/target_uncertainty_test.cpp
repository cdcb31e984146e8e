// The targets' linearised uncertainty against the nonlinear model.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <random>
#include <thread>

#include "depth_camera.h"
#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/registration/target_uncertainty.h"
#include "liver_sim/registration/uncertainty_worker.h"
#include "regions.h"
#include "scenarios.h"
#include "stylus.h"
#include "registration/fixtures.h"

namespace liver_sim {
namespace {

TEST(TargetUncertainty, EmbedsTheTargetsAsTheModelDoes) {
  // Mutation seen failing: the barycentric weights paired with the wrong corners.
  RestPhantom p;
  const TargetUncertainty u(p.model, p.options.uncertainty);
  const std::vector<TrackedTarget> targets = tracked_targets(p.model);
  ASSERT_EQ(u.num_targets(), static_cast<int>(targets.size()));
  // A smooth, large deformation: the embedding is material.
  Eigen::VectorXd x = p.model.positions();
  for (int i = 0; i < x.size(); i += 3) {
    const Eigen::Vector3d X = x.segment<3>(i);
    x.segment<3>(i) += 0.01 * Eigen::Vector3d(std::sin(10 * X.y()), std::cos(8 * X.z()), 50 * X.x() * X.x());
  }
  p.model.set_positions(x);
  const std::vector<TrackedTarget> moved = tracked_targets(p.model);
  for (size_t i = 0; i < moved.size(); ++i) EXPECT_LT((u.position(i, x) - moved[i].position).norm(), 1e-12) << moved[i].name;
}

TEST(TargetUncertainty, AStiffnessErrorMovesTheTargetsByTheirDisplacement) {
  // In the linear range a stiffness k times the model's scales every displacement by 1/k: the
  // linearised shift per unit log-stiffness is the displacement itself. Mutation seen failing:
  // the shift taken as A^-1 of the external load instead of the internal forces at the state
  // with the springs (here: zero, as no spring acts, so the test also checks f_int is used).
  const Scene s = cantilever(5e6);  // stiff: micrometres
  LiverModel model(load_scene_mesh(s), s);
  TargetUncertainty u(model, UncertaintyOptions());
  const std::vector<TrackedTarget> rest = tracked_targets(model);
  ASSERT_TRUE(model.step().converged());
  const std::vector<TrackedTarget> sagged = tracked_targets(model);
  StateCompliance compliance(model);
  compliance.factorize();
  const std::vector<TargetUncertainty::Covariance> c = u.covariances(compliance, {});
  const double sd = UncertaintyOptions().stiffness_log_sd;
  for (size_t i = 0; i < rest.size(); ++i) {
    const Eigen::Vector3d d = sagged[i].position - rest[i].position;
    ASSERT_GT(d.norm(), 1e-7);
    const Eigen::Matrix3d expected = sd * sd * d * d.transpose();
    EXPECT_LT((c[i].stiffness - expected).norm(), 1e-3 * expected.norm()) << rest[i].name;
    EXPECT_EQ(c[i].forces.norm(), 0.0);  // no spring pulls: no scale for unknown forces
    EXPECT_LT((c[i].total - c[i].stiffness).norm(), 1e-15);
  }
}

}  // namespace
}  // namespace liver_sim
