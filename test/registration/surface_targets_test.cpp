// The surface springs against their analytic force and the supports.
#include <gtest/gtest.h>

#include <cmath>
#include <pcl/filters/voxel_grid.h>

#include <random>

#include "liver_sim/registration/registration.h"
#include "scenarios.h"
#include "regions.h"

namespace liver_sim {
namespace {

// A block fixed at its base, one spring pulling a top-face point up.
struct SpringBlock {
  Scene scene;
  std::unique_ptr<LiverModel> model;
  int triangle = -1;
  explicit SpringBlock(bool dynamic = false) {
    if (dynamic) {
      scene.solver.mode = SolverOptions::Mode::Dynamic;
      scene.solver.dt = 0.01;
      scene.solver.rayleigh_mass = 20.0;  // 1/s: settles within the test's 2 s
    }
    scene.mesh.box_size = Eigen::Vector3d(0.02, 0.02, 0.02);
    scene.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
    scene.parenchyma.young_modulus = 5000;
    scene.solver.tolerance = 1e-10;
    scene.fixed.push_back(box({-1, -1, -1}, {1, 1, 1e-9}));
    model = std::make_unique<LiverModel>(load_scene_mesh(scene), scene);
    const Eigen::MatrixX3i& F = model->boundary();
    for (int t = 0; t < F.rows() && triangle < 0; ++t) {
      bool top = true;
      for (int j = 0; j < 3; ++j) top &= model->positions()[3 * F(t, j) + 2] > 0.02 - 1e-9;
      if (top) triangle = t;
    }
  }
  Eigen::Vector3d point(const Eigen::Vector3d& w) const {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int j = 0; j < 3; ++j) p += w[j] * model->positions().segment<3>(3 * model->boundary()(triangle, j));
    return p;
  }
};

TEST(SurfaceTargets, PullBalancesTheSupportsAndStopsShortOfTheTarget) {
  SpringBlock b;
  ASSERT_GE(b.triangle, 0);
  const Eigen::Vector3d w(0.2, 0.3, 0.5);
  const Eigen::Vector3d start = b.point(w);
  SurfaceTarget t;
  t.triangle = b.triangle;
  t.weights = w;
  t.point = start + Eigen::Vector3d(0.001, 0.0, 0.004);
  t.stiffness = 50.0;
  b.model->set_surface_targets({t});
  const StepResult r = b.model->step();
  ASSERT_TRUE(r.converged()) << r.message;
  // The spring's force k (p - x) is what the supports hold.
  const Eigen::Vector3d pull = t.stiffness * (t.point - b.point(w));
  const Eigen::VectorXd support = b.model->stepper().support_forces();
  Eigen::Vector3d held = Eigen::Vector3d::Zero();
  for (int i = 0; i < support.size(); i += 3) held += support.segment<3>(i);
  EXPECT_LT((held + pull).norm(), 1e-6 * pull.norm());
  // It moved towards the target, not onto it (the block resists).
  const double gap = (t.point - b.point(w)).norm();
  EXPECT_LT(gap, (t.point - start).norm());
  EXPECT_GT(gap, 0.0);
}

TEST(SurfaceTargets, PointToPlaneIgnoresSlidingAlongThePlane) {
  SpringBlock b;
  const Eigen::Vector3d w(1.0 / 3, 1.0 / 3, 1.0 / 3);
  SurfaceTarget t;
  t.triangle = b.triangle;
  t.weights = w;
  t.point = b.point(w) + Eigen::Vector3d(0.003, -0.002, 0.0);  // in the top face's plane
  t.normal = Eigen::Vector3d::UnitZ();
  t.stiffness = 1e4;
  b.model->set_surface_targets({t});
  const StepResult r = b.model->step();
  ASSERT_TRUE(r.converged()) << r.message;
  EXPECT_LT(b.model->max_displacement(), 1e-12);
  // Raised above the plane, it pulls along the normal only.
  t.point += Eigen::Vector3d(0, 0, 0.002);
  b.model->set_surface_targets({t});
  ASSERT_TRUE(b.model->step().converged());
  const Eigen::VectorXd support = b.model->stepper().support_forces();
  Eigen::Vector3d held = Eigen::Vector3d::Zero();
  for (int i = 0; i < support.size(); i += 3) held += support.segment<3>(i);
  EXPECT_LT(held.head<2>().norm(), 1e-6 * std::abs(held.z()));
  EXPECT_LT(held.z(), 0.0);
}

TEST(SurfaceTargets, DynamicStepsSettleOnTheStaticPull) {
  // The springs' work enters the energy check of dynamic steps: pulling never reads as energy
  // growth, and the motion settles where the static solve ends.
  SpringBlock still, moving(true);
  SurfaceTarget t;
  t.triangle = still.triangle;
  t.weights = Eigen::Vector3d(0.2, 0.3, 0.5);
  t.point = still.point(t.weights) + Eigen::Vector3d(0.001, 0.0, 0.004);
  t.stiffness = 50.0;
  const Eigen::Vector3d start = still.point(t.weights);
  still.model->set_surface_targets({t});
  moving.model->set_surface_targets({t});
  ASSERT_TRUE(still.model->step().converged());
  for (int k = 0; k < 200; ++k) {
    const StepResult r = moving.model->step();
    ASSERT_NE(r.status, StepResult::Status::Diverged) << "step " << k << ": " << r.message;
  }
  const double pulled = (still.point(t.weights) - start).norm();
  ASSERT_GT(pulled, 1e-4);
  EXPECT_LT((moving.point(t.weights) - still.point(t.weights)).norm(), 1e-3 * pulled);
}

TEST(SurfaceTargets, BadTargetsAreRefusedAndChangeNothing) {
  SpringBlock b;
  SurfaceTarget t;
  t.triangle = b.triangle;
  t.weights = Eigen::Vector3d(1, 0, 0);
  t.stiffness = 1.0;
  b.model->set_surface_targets({t});
  SurfaceTarget bad = t;
  bad.triangle = static_cast<int>(b.model->boundary().rows());
  EXPECT_THROW(b.model->set_surface_targets({bad}), std::invalid_argument);
  bad = t;
  bad.point.x() = std::nan("");
  EXPECT_THROW(b.model->set_surface_targets({bad}), std::invalid_argument);
  bad = t;
  bad.normal = Eigen::Vector3d(0, 0, 2);
  EXPECT_THROW(b.model->set_surface_targets({bad}), std::invalid_argument);
  bad = t;
  bad.stiffness = -1;
  EXPECT_THROW(b.model->set_surface_targets({bad}), std::invalid_argument);
  ASSERT_EQ(b.model->surface_targets().size(), 1u);
  EXPECT_EQ(b.model->surface_targets()[0].triangle, t.triangle);
}

}  // namespace
}  // namespace liver_sim
