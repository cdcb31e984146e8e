// The uncertainty worker: its analysis on a model of its own, and a broken state as an error.
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

// The worker's result once it is ready (polled; the bound only keeps a hang from lasting).
UncertaintyWorker::Result wait_for(UncertaintyWorker& worker) {
  for (int k = 0; k < 60000; ++k) {
    if (std::optional<UncertaintyWorker::Result> r = worker.take()) return *r;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ADD_FAILURE() << "no analysis within a minute";
  return {};
}

TEST(UncertaintyWorker, AnalysesTheStateItIsHandedOnAModelOfItsOwn) {
  // The registered phantom with a stiffer tissue and the capsule on, a probe pressing its top,
  // analysed by the worker on its own model (no instrument), against the analysis on the
  // caller's model: the same to round-off (the elements' polar iterations start from each
  // model's last rotations). Mutations seen failing: the stiffness factor, the springs, the
  // positions, the surface loads, the capsule or the instrument's forces not handed over
  // (each alone).
  RestPhantom p;
  const std::vector<int> top = p.above(0.05);
  std::vector<Eigen::Vector3d> points;
  for (int t : top) points.push_back(p.on_triangle(t, 2e-3));
  SurfaceRegistration registration(p.model, p.options);
  registration.register_cloud(cloud_of(points));
  ASSERT_FALSE(registration.cloud_springs().empty());
  UncertaintyWorker worker(std::make_unique<LiverModel>(load_scene_mesh(p.scene), p.scene), p.options.uncertainty);
  CapsuleOptions capsule = p.model.capsule();
  capsule.enabled = !capsule.enabled;
  ASSERT_EQ(p.model.set_capsule(capsule), "");
  worker.set_capsule(capsule);
  p.model.set_stiffness_scale(1.5);
  Eigen::VectorXd loads = Eigen::VectorXd::Zero(p.model.positions().size());
  loads(3 * p.model.boundary()(top.back(), 0) + 2) = -0.5;  // N, as a hidden load
  p.model.set_surface_loads(loads);
  InstrumentOptions probe;
  probe.name = "probe";
  probe.radius = 0.005;
  probe.position = p.on_triangle(top[top.size() / 2], probe.radius - 2e-3);  // 2 mm into the top
  p.model.add_instrument(probe);
  p.model.step();  // one step: the worker takes the state as it is, at equilibrium or not
  const Eigen::VectorXd pressed = p.model.contact().forces(p.model.positions());
  ASSERT_GT(pressed.norm(), 0.0);
  ASSERT_TRUE(worker.start(p.model, registration.cloud_springs(), 7));
  EXPECT_FALSE(worker.start(p.model, registration.cloud_springs(), 8));  // one at a time
  const UncertaintyWorker::Result r = wait_for(worker);
  EXPECT_FALSE(worker.take());  // once
  ASSERT_EQ(r.error, "");
  EXPECT_EQ(r.tag, 7u);
  EXPECT_GT(r.cpu_time, 0.0);  // its thread's processor time, reported with it
  EXPECT_EQ(r.cloud_springs.size(), registration.cloud_springs().size());
  StateCompliance compliance(p.model);
  compliance.set_instrument_forces(pressed);
  compliance.factorize();
  TargetUncertainty direct(p.model, p.options.uncertainty);
  const std::vector<TargetUncertainty::Covariance> expected = direct.covariances(compliance, registration.cloud_springs());
  ASSERT_EQ(r.covariances.size(), expected.size());
  ASSERT_GT(expected.size(), 0u);
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_GT(expected[i].total.norm(), 0.0);
    EXPECT_LT((r.covariances[i].total - expected[i].total).norm(), 1e-9 * expected[i].total.norm()) << "target " << i;
  }
  // Its factor stays for the registration's estimates: the same displacements as the caller's.
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(p.model.positions().size(), 1), u_worker, u_direct;
  f(3 * p.model.boundary()(top.front(), 0) + 2, 0) = 1.0;
  worker.compliance().solve(f, u_worker);
  compliance.solve(f, u_direct);
  EXPECT_LT((u_worker - u_direct).norm(), 1e-9 * u_direct.norm());
  EXPECT_TRUE(worker.start(p.model, {}, 9));  // free again once taken
  EXPECT_EQ(wait_for(worker).tag, 9u);
  // A capsule its model refuses: that start throws, the next one runs. Killed by a refused
  // capsule kept for the next start (tried).
  CapsuleOptions refused = capsule;
  refused.young_modulus = -1;
  worker.set_capsule(refused);
  EXPECT_THROW(worker.start(p.model, {}, 10), std::invalid_argument);
  ASSERT_TRUE(worker.start(p.model, {}, 11));
  EXPECT_EQ(wait_for(worker).tag, 11u);
}

TEST(UncertaintyWorker, ABrokenStateIsAnErrorNotACrash) {
  // The cantilever handed over with a node at NaN (no factor: the factorisation throws), then
  // with a spring whose point is NaN (a factor, but covariances that are not finite). Mutations
  // seen failing: the worker's catch removed (the exception ends the process); the finite check
  // removed (NaN covariances without an error); polar_rotation's non-finite guard removed (after
  // the other registration tests of this executable, Eigen's SVD of the NaN element's gradient
  // returned a finite rotation built from memory it never set: finite covariances, no error).
  const Scene s = cantilever(5e6);
  LiverModel model(load_scene_mesh(s), s);
  UncertaintyWorker worker(std::make_unique<LiverModel>(load_scene_mesh(s), s), UncertaintyOptions());
  const Eigen::VectorXd rest = model.positions();
  Eigen::VectorXd broken = rest;
  broken[broken.size() - 1] = std::numeric_limits<double>::quiet_NaN();
  model.set_positions(broken);
  ASSERT_TRUE(worker.start(model, {}, 1));
  UncertaintyWorker::Result r = wait_for(worker);
  EXPECT_NE(r.error, "");
  EXPECT_TRUE(r.covariances.empty());
  model.set_positions(rest);
  SurfaceTarget spring;
  spring.triangle = 0;
  spring.weights = Eigen::Vector3d::Constant(1.0 / 3);
  spring.point = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  spring.stiffness = 1.0;
  ASSERT_TRUE(worker.start(model, {spring}, 2));
  r = wait_for(worker);
  EXPECT_NE(r.error, "");
  EXPECT_TRUE(r.covariances.empty());
}

}  // namespace
}  // namespace liver_sim
