// Registration of the vascularised phantom to rendered partial clouds of a known deformation: an
// undeformed cloud changes nothing, a lifted liver is recovered, outliers are rejected, a rigid
// offset is found, bad clouds are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <pcl/filters/voxel_grid.h>

#include <random>

#include "liver_sim/registration/registration.h"
#include "scenarios.h"
#include "regions.h"
#include "registration/fixtures.h"
#include "geometry/brute_force_distance.h"

namespace liver_sim {
namespace {

// The phantom at its equilibrium (pre-operative), and the ground truth lifted by `lift` newtons
// on the right lobe's underside.
struct Phantom {
  Scene scene;
  TetMesh mesh;
  std::unique_ptr<LiverModel> model, truth;
  Eigen::VectorXd preoperative;
  explicit Phantom(double lift) {
    scene = load_scene(phantom_scene());
    mesh = load_scene_mesh(scene);
    Scene t = scene;
    t.solver.tolerance = 1e-10;
    truth = std::make_unique<LiverModel>(mesh, t);
    EXPECT_TRUE(truth->step().converged());
    preoperative = truth->positions();
    model = std::make_unique<LiverModel>(mesh, scene);
    model->set_positions(preoperative);
    if (lift > 0) {
      t.loads.push_back(underside_lift(mesh, lift));
      truth = std::make_unique<LiverModel>(mesh, t);
      EXPECT_TRUE(truth->step().converged());
    }
  }
  CameraView view(double noise, double outliers, unsigned seed) const {
    CameraView v = front_view(preoperative);
    v.visible_fraction = 0.3;
    v.noise = noise;
    v.outlier_fraction = outliers;
    v.seed = seed;
    return v;
  }
  // Mean and largest distance of the model's targets from the truth's (m).
  std::pair<double, double> tre() const {
    const std::vector<TrackedTarget> a = tracked_targets(*model), b = tracked_targets(*truth);
    double mean = 0, max = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      const double d = (a[i].position - b[i].position).norm();
      mean += d / a.size();
      max = std::max(max, d);
    }
    return {mean, max};
  }
  // Registers `frames` clouds of the truth.
  RegistrationFrame run(const RegistrationOptions& o, double noise, double outliers, int frames) {
    SurfaceRegistration registration(*model, o);
    RegistrationFrame f;
    for (int k = 0; k < frames; ++k) {
      const CameraView v = view(noise, outliers, 10 + k);
      f = registration.register_cloud(render_surface_cloud(truth->positions(), model->boundary(), v).cloud, v.eye);
      EXPECT_NE(f.step.status, StepResult::Status::Diverged) << f.step.message;
    }
    return f;
  }
};

TEST(Targets, AreTheTumourProbesAndTheVesselBifurcations) {
  Phantom p(0.0);
  const std::vector<TrackedTarget> targets = tracked_targets(*p.model);
  ASSERT_GT(targets.size(), 7u);
  EXPECT_EQ(targets[0].name, "tumour_centre");
  EXPECT_EQ(targets[6].kind, TrackedTarget::Kind::Probe);
  EXPECT_EQ(targets[7].kind, TrackedTarget::Kind::Bifurcation);
  EXPECT_NE(targets[7].name.find("bifurcation"), std::string::npos);
}

TEST(PhantomRegistration, UndeformedCloudChangesNothing) {
  // Points on the surface (float coordinates) leave the model where it is.
  Phantom p(0.0);
  RegistrationOptions raw = p.scene.registration;
  raw.voxel_size = 0;
  RegistrationFrame f = p.run(raw, 0.0, 0.0, 2);
  EXPECT_GT(f.correspondences, 500);
  EXPECT_LT(f.rms, 1e-7);
  EXPECT_LT(p.tre().second, 1e-7);
  // The voxel grid's centroids lie slightly inside the faceted surface where it bends (5 mm
  // voxels across 9 mm triangles): tens of micrometres, under 1/40 of the 2 mm budget.
  Phantom q(0.0);
  f = q.run(q.scene.registration, 0.0, 0.0, 2);
  EXPECT_LT(f.rms, 50e-6);
  EXPECT_LT(q.tre().second, 50e-6);
}

TEST(PhantomRegistration, UpdatesSpreadOverFramesAreTheUpdatesOfOneFrame) {
  // A cloud's three correspondence updates, one per call (registration.frame_updates 1: the
  // cloud's own frame, then two refine() calls), are the same computation as all three in its
  // frame; later refine() calls only solve (the springs stay). Killed by a refine() that only
  // solves (tried).
  Phantom all(5.0), spread(5.0);
  RegistrationOptions o = all.scene.registration;
  ASSERT_EQ(o.correspondence_updates, 3);
  SurfaceRegistration one_frame(*all.model, o);
  o.frame_updates = 1;
  SurfaceRegistration per_frame(*spread.model, o);
  const CameraView v = all.view(1e-3, 0.0, 10);
  const pcl::PointCloud<pcl::PointXYZ> cloud = render_surface_cloud(all.truth->positions(), all.model->boundary(), v).cloud;
  const RegistrationFrame f = one_frame.register_cloud(cloud, v.eye);
  RegistrationFrame g = per_frame.register_cloud(cloud, v.eye);
  EXPECT_GT((all.model->positions() - spread.model->positions()).norm(), 1e-6);  // one update fewer so far
  for (int k = 0; k < 2; ++k) g = per_frame.refine();
  EXPECT_EQ(g.correspondences, f.correspondences);
  EXPECT_EQ(g.coverage, f.coverage);
  EXPECT_EQ(all.model->positions(), spread.model->positions());
  const std::vector<SurfaceTarget> springs = per_frame.cloud_springs();
  per_frame.refine();
  ASSERT_EQ(per_frame.cloud_springs().size(), springs.size());
  for (size_t i = 0; i < springs.size(); ++i) {
    EXPECT_EQ(per_frame.cloud_springs()[i].point, springs[i].point);
    EXPECT_EQ(per_frame.cloud_springs()[i].triangle, springs[i].triangle);
    EXPECT_EQ(per_frame.cloud_springs()[i].weights, springs[i].weights);
  }
}

TEST(PhantomRegistration, AFrameOutOfTimeLeavesItsUpdatesToTheNextFrames) {
  // With the scene's time budget spent after the first solve (a budget of 1 ns), a cloud's
  // frame does one correspondence update and leaves the other two to the next refine() calls:
  // the same computation as one update per frame (registration.frame_updates 1) under the same
  // budget. Killed by updates that ignore the budget (tried: all three run in the cloud's frame).
  Phantom timed(5.0), spread(5.0);
  RegistrationOptions o = timed.scene.registration;
  ASSERT_EQ(o.correspondence_updates, 3);
  ASSERT_GT(o.frame_updates, 1);
  SolverOptions budget = timed.model->solver_options();
  budget.time_budget = 1e-9;
  ASSERT_EQ(timed.model->set_solver_options(budget), "");
  ASSERT_EQ(spread.model->set_solver_options(budget), "");
  SurfaceRegistration out_of_time(*timed.model, o);
  o.frame_updates = 1;
  SurfaceRegistration per_frame(*spread.model, o);
  const CameraView v = timed.view(1e-3, 0.0, 10);
  const pcl::PointCloud<pcl::PointXYZ> cloud = render_surface_cloud(timed.truth->positions(), timed.model->boundary(), v).cloud;
  out_of_time.register_cloud(cloud, v.eye);
  per_frame.register_cloud(cloud, v.eye);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(out_of_time.updates_pending(), k < 2) << "after frame " << k;
    EXPECT_EQ(timed.model->positions(), spread.model->positions()) << "after frame " << k;
    out_of_time.refine();
    per_frame.refine();
  }
  EXPECT_EQ(timed.model->positions(), spread.model->positions());
}

TEST(PhantomRegistration, ACloudsFrameTakesItsIterationsOnlyFarFromEquilibrium) {
  // A cloud's frame under a time budget (10 s, far more than it needs) ends at
  // registration.newton_iterations although its residual is above solver.capped_residual: the
  // model converges on the cloud over the frames that follow (refine()), and a frame that
  // iterated on would take the time of the next cloud. Killed by the registration's frames
  // iterating on (mutation R17, tried).
  Phantom p(5.0);
  SolverOptions budget = p.model->solver_options();
  budget.time_budget = 10.0;
  ASSERT_EQ(p.model->set_solver_options(budget), "");
  RegistrationOptions o = p.scene.registration;
  o.frame_updates = 1;
  SurfaceRegistration registration(*p.model, o);
  const CameraView v = p.view(1e-3, 0.0, 10);
  const RegistrationFrame f =
      registration.register_cloud(render_surface_cloud(p.truth->positions(), p.model->boundary(), v).cloud, v.eye);
  ASSERT_NE(f.step.status, StepResult::Status::Diverged) << f.step.message;
  EXPECT_EQ(f.newton_iterations, o.newton_iterations);
  EXPECT_GT(f.step.residual, budget.capped_residual);  // ended far from equilibrium: the case tests the rule
  EXPECT_EQ(p.model->solver_options().capped_residual, budget.capped_residual) << "the scene's solver again after the frame";
}

TEST(PhantomRegistration, PointsBeyondTheGateAreFoundOnceTheSurfaceComesNear) {
  // Points 4 mm above the top of the right lobe pull it up; others 15.1-17 mm above it lie
  // beyond the 15 mm gate until the surface has come near. Later updates search again only
  // the points that may have come within the gate (their lower bound less the surface's motion
  // since): the accepted points must be those of a brute-force search at every update. Killed
  // by a test that ignores the motion (tried). Not killed by a bound carried over without the
  // motion subtracted (tried): here the first solve moves the surface farther than any far
  // point's margin.
  const Scene scene = load_scene(phantom_scene());
  LiverModel model(load_scene_mesh(scene), scene);
  RegistrationOptions o = scene.registration;
  o.voxel_size = 0;
  o.trim_fraction = 0;
  o.frame_updates = 1;
  o.correspondence_updates = 3;
  const Eigen::MatrixX3i& F = model.boundary();
  auto corner = [&](int t, int j) -> Eigen::Vector3d { return model.positions().segment<3>(3 * F(t, j)); };
  pcl::PointCloud<pcl::PointXYZ> cloud;
  int inliers = 0;
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d a = corner(t, 0), b = corner(t, 1), c = corner(t, 2), centre = (a + b + c) / 3;
    if (centre.z() < 0.05) continue;
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    const Eigen::Vector3d near = centre + 4e-3 * n, far = centre + (0.0151 + 2e-3 * (t % 10) / 10) * n;
    cloud.push_back(pcl::PointXYZ(near.x(), near.y(), near.z()));
    cloud.push_back(pcl::PointXYZ(far.x(), far.y(), far.z()));
    ++inliers;
  }
  pcl::PointCloud<pcl::PointXYZ> used;  // the cloud cropped to the model's box
  auto within_gate = [&](const Eigen::VectorXd& x) {
    int n = 0;
    for (const pcl::PointXYZ& q : used) n += brute_force_distance(Eigen::Vector3d(q.x, q.y, q.z), x, F) <= o.max_distance;
    return n;
  };
  auto fit_of_all = [&] {
    double sum = 0;
    for (const pcl::PointXYZ& q : used)
      sum += std::pow(std::min(brute_force_distance(Eigen::Vector3d(q.x, q.y, q.z), model.positions(), F), o.max_distance), 2);
    return std::sqrt(sum / used.size());
  };
  SurfaceRegistration registration(model, o);
  Eigen::VectorXd searched_at = model.positions();
  RegistrationFrame f = registration.register_cloud(cloud);
  used = registration.points();
  ASSERT_GT(static_cast<int>(used.size()), inliers + 100);
  int expected = within_gate(searched_at);
  EXPECT_EQ(expected, inliers);  // the far ones beyond the gate at rest
  for (int call = 0; call < 5; ++call) {
    if (call < 3) {  // an update searched
      EXPECT_EQ(f.correspondences, within_gate(searched_at)) << "update " << call;
    }
    // The fit of all points takes each point's distance to the triangle its search found: no
    // less than the brute-force fit, no more than that and twice the surface's motion since.
    // Killed by the points beyond the gate left out of it (tried).
    const double moved = (model.positions() - searched_at).reshaped(3, model.positions().size() / 3).colwise().norm().maxCoeff();
    const double exact = fit_of_all();
    EXPECT_GE(f.rms_all, exact - 1e-12) << "call " << call;
    EXPECT_LE(f.rms_all, exact + 2 * moved + 1e-12) << "call " << call;
    const Eigen::VectorXd before = model.positions();
    f = registration.refine();
    if (f.updates > 0) searched_at = before;
  }
  EXPECT_GT(within_gate(model.positions()), inliers + 10);  // the surface came near some far points
  // A cloud of as many points, all deep inside the lobe (beyond the gate), is refused; the fit
  // of all points is the last accepted cloud's again, from that cloud's hits, whatever this
  // one's search left. Killed by the refused cloud's hits kept (tried).
  pcl::PointCloud<pcl::PointXYZ> deep;
  for (size_t k = 0; k < used.size(); ++k) deep.push_back(pcl::PointXYZ(-0.05, -0.02, 0.005 + 1e-6 * k));
  EXPECT_THROW(registration.register_cloud(deep), std::invalid_argument);
  f = registration.refine();
  const double moved = (model.positions() - searched_at).reshaped(3, model.positions().size() / 3).colwise().norm().maxCoeff();
  EXPECT_GE(f.rms_all, fit_of_all() - 1e-12);
  EXPECT_LE(f.rms_all, fit_of_all() + 2 * moved + 1e-12);
}

TEST(PhantomRegistration, RecoversALiftFromNoisyPartialClouds) {
  Phantom p(5.0);
  const auto [unregistered_mean, unregistered_max] = p.tre();
  ASSERT_GT(unregistered_mean, 5e-3);  // the lift moves the targets by centimetres at most
  p.run(p.scene.registration, 1e-3, 0.0, 10);
  const auto [mean, max] = p.tre();
  // 1 mm noise, 30% of the surface seen: the error falls to a fraction of the motion, and under
  // the 2 mm that image guidance asks for everywhere (the tumour and every bifurcation).
  EXPECT_LT(mean, 0.15 * unregistered_mean) << "unregistered " << unregistered_mean;
  EXPECT_LT(max, 2e-3) << "unregistered " << unregistered_max;
}

TEST(PhantomRegistration, RejectsOutliers) {
  // 20% of the points scattered around the view: gating, trimming and Huber weights keep the
  // registration close to the outlier-free one; plain least squares on every point does not.
  Phantom robust(5.0);
  robust.run(robust.scene.registration, 1e-3, 0.2, 10);
  Phantom plain(5.0);
  RegistrationOptions o = plain.scene.registration;
  o.max_distance = 1.0;
  o.trim_fraction = 0.0;
  o.huber_width = 1.0;
  plain.run(o, 1e-3, 0.2, 10);
  const double unregistered = Phantom(5.0).tre().first;
  EXPECT_LT(robust.tre().first, 0.15 * unregistered);
  EXPECT_LT(robust.tre().second, 2e-3);
  EXPECT_GT(plain.tre().first, 2 * robust.tre().first);
}

TEST(PhantomRegistration, RigidAlignmentFindsACameraOffset) {
  // The cloud of the undeformed liver, seen through a camera calibration that is 4 mm and 2
  // degrees off: ICP finds the offset, and the deformable step then has nothing left to do.
  Phantom p(0.0);
  const Eigen::Isometry3d offset =
      Eigen::Translation3d(0.004, -0.002, 0.001) * Eigen::AngleAxisd(2.0 * M_PI / 180, Eigen::Vector3d(1, 2, 3).normalized());
  const CameraView v = p.view(0.0, 0.0, 7);
  pcl::PointCloud<pcl::PointXYZ> cloud = render_surface_cloud(p.preoperative, p.model->boundary(), v).cloud;
  for (pcl::PointXYZ& q : cloud) {
    const Eigen::Vector3d moved = offset * Eigen::Vector3d(q.x, q.y, q.z);
    q = pcl::PointXYZ(moved.x(), moved.y(), moved.z());
  }
  // Asked for once (the scene's default is no alignment): the first cloud is aligned.
  ASSERT_FALSE(p.scene.registration.rigid_alignment);
  SurfaceRegistration registration(*p.model, p.scene.registration);
  registration.request_rigid_alignment();
  const RegistrationFrame f = registration.register_cloud(cloud, offset * v.eye);
  // Where the aligned points land against where they were seen from: within a quarter of the
  // 2 mm budget. (Point-to-point ICP against surface samples left 0.8 mm here: the samples'
  // spacing biased it. Point-to-plane does not.)
  const Eigen::Isometry3d residual = registration.alignment() * offset;
  double worst = 0;
  for (const pcl::PointXYZ& q : cloud) {
    const Eigen::Vector3d seen = offset.inverse() * Eigen::Vector3d(q.x, q.y, q.z);
    worst = std::max(worst, (residual * seen - seen).norm());
  }
  EXPECT_LT(worst, 0.5e-3) << "rotation left " << Eigen::AngleAxisd(residual.linear()).angle() * 180 / M_PI << " deg";
  EXPECT_LT(Eigen::AngleAxisd(residual.linear()).angle(), Eigen::AngleAxisd(offset.linear()).angle());
  EXPECT_LT(f.rms, 0.1e-3);
  EXPECT_LT(p.tre().second, 0.1e-3);
}

TEST(PhantomRegistration, RefusesCloudsWithNothingToRegisterAndKeepsItsState) {
  Phantom p(5.0);
  SurfaceRegistration registration(*p.model, p.scene.registration);
  const CameraView v = p.view(1e-3, 0.0, 3);
  registration.register_cloud(render_surface_cloud(p.truth->positions(), p.model->boundary(), v).cloud, v.eye);
  const Eigen::VectorXd state = p.model->positions();
  const size_t springs = p.model->surface_targets().size(), points = registration.points().size();
  pcl::PointCloud<pcl::PointXYZ> empty, nan, far;
  const float q = std::numeric_limits<float>::quiet_NaN();
  for (int i = 0; i < 100; ++i) nan.push_back(pcl::PointXYZ(q, q, q));
  for (int i = 0; i < 100; ++i) far.push_back(pcl::PointXYZ(5.0f, 5.0f, 5.0f + i));
  pcl::PointCloud<pcl::PointXYZ> off_surface;  // inside the box's margin, beyond max_distance of the surface
  Eigen::Vector3d corner = p.model->positions().segment<3>(0);  // of the box of the current shape
  for (int i = 0; i < p.model->positions().size(); i += 3) corner = corner.cwiseMax(p.model->positions().segment<3>(i));
  for (int i = 0; i < 10; ++i) off_surface.push_back(pcl::PointXYZ(corner.x() + 0.012, corner.y() + 0.012, corner.z() + 0.012));
  EXPECT_THROW(registration.register_cloud(empty), std::invalid_argument);
  EXPECT_THROW(registration.register_cloud(nan), std::invalid_argument);
  EXPECT_THROW(registration.register_cloud(far), std::invalid_argument);
  EXPECT_THROW(registration.register_cloud(off_surface), std::invalid_argument);
  EXPECT_THROW(registration.register_cloud(far, Eigen::Vector3d(q, 0, 0)), std::invalid_argument);
  const pcl::PointCloud<pcl::PointXYZ> seen = render_surface_cloud(p.truth->positions(), p.model->boundary(), v).cloud;
  EXPECT_THROW(registration.register_cloud(seen, Eigen::Vector3d(0.02, 0.0, 0.0)), std::invalid_argument)
      << "a viewpoint inside the liver faces no triangle";
  // A requested rigid alignment is not used up, nor its transform kept, by a refused cloud
  // (ICP aligns this one, then no triangle faces its viewpoint).
  registration.request_rigid_alignment();
  EXPECT_THROW(registration.register_cloud(seen, Eigen::Vector3d(0.02, 0.0, 0.0)), std::invalid_argument);
  EXPECT_TRUE(registration.alignment().isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_EQ((p.model->positions() - state).norm(), 0.0);
  EXPECT_EQ(p.model->surface_targets().size(), springs);
  EXPECT_EQ(registration.points().size(), points);
  registration.register_cloud(seen, v.eye);  // the request still stands: this one is aligned
  EXPECT_FALSE(registration.alignment().isApprox(Eigen::Isometry3d::Identity()));
  registration.clear();
  EXPECT_TRUE(registration.alignment().isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_TRUE(p.model->surface_targets().empty());
  RegistrationOptions bad = p.scene.registration;
  bad.trim_fraction = 0.95;
  EXPECT_THROW(SurfaceRegistration(*p.model, bad), std::invalid_argument);
}

TEST(PhantomRegistration, AStepThatThrowsTakesItsUpdateBack) {
  // A model step that throws during a registration (an injected fault; NewtonStepper rolls the
  // state back) takes its update's springs back with it. Checked against a twin that never met
  // the fault: after a cloud whose first solve threw, the twin has not seen the cloud; after a
  // refine() whose update threw, the twin has not made that update. Both then go on alike, to
  // the last bit. Killed by leaving out the springs' restore in accept_update (tried: the failed
  // cloud's springs stay and the next refine() pulls towards it) and by register_cloud keeping
  // the failed cloud's points (tried: refine() searches the new points).
  Phantom a(5.0), b(5.0);
  RegistrationOptions o = a.scene.registration;
  o.frame_updates = 1;
  SurfaceRegistration faulty(*a.model, o), twin(*b.model, o);
  auto cloud = [&](unsigned seed) {
    const CameraView v = a.view(1e-3, 0.0, seed);
    return std::make_pair(render_surface_cloud(a.truth->positions(), a.model->boundary(), v).cloud, v.eye);
  };
  auto same = [&](const char* when) {
    SCOPED_TRACE(when);
    EXPECT_EQ(a.model->positions(), b.model->positions());
    ASSERT_EQ(faulty.cloud_springs().size(), twin.cloud_springs().size());
    for (size_t i = 0; i < twin.cloud_springs().size(); ++i) {
      EXPECT_EQ(faulty.cloud_springs()[i].point, twin.cloud_springs()[i].point);
      EXPECT_EQ(faulty.cloud_springs()[i].triangle, twin.cloud_springs()[i].triangle);
    }
    EXPECT_EQ(a.model->surface_targets().size(), b.model->surface_targets().size());
  };
  const auto first = cloud(3), second = cloud(4);
  faulty.register_cloud(first.first, first.second);
  twin.register_cloud(first.first, first.second);
  a.model->stepper().inject_fault(NewtonStepper::InjectedFault::Exception);
  EXPECT_THROW(faulty.register_cloud(second.first, second.second), std::runtime_error);
  same("after a cloud whose first solve threw");
  faulty.refine();
  twin.refine();
  same("refined on the first cloud");

  faulty.register_cloud(second.first, second.second);
  twin.register_cloud(second.first, second.second);
  ASSERT_TRUE(twin.updates_pending());
  a.model->stepper().inject_fault(NewtonStepper::InjectedFault::Exception);
  EXPECT_THROW(faulty.refine(), std::runtime_error);
  same("after a refine() whose update threw");
  const RegistrationFrame f = faulty.refine(), g = twin.refine();
  same("the update made again");
  EXPECT_EQ(f.correspondences, g.correspondences);
  EXPECT_EQ(f.coverage, g.coverage);
}

TEST(PhantomRegistration, HugeCloudIsCroppedAndDownsampled) {
  // 1M points, a quarter of them far away: the voxel grid keeps a few thousand.
  Phantom p(0.0);
  pcl::PointCloud<pcl::PointXYZ> cloud;
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(-0.1f, 0.1f);
  for (int i = 0; i < 1000000; ++i)
    cloud.push_back(i % 4 == 0 ? pcl::PointXYZ(100 * u(rng), 100 * u(rng), 100 * u(rng))
                               : pcl::PointXYZ(u(rng), u(rng), 0.06f + 0.001f * u(rng)));
  RegistrationOptions o = p.scene.registration;
  SurfaceRegistration registration(*p.model, o);
  const RegistrationFrame f = registration.register_cloud(cloud);
  EXPECT_EQ(f.input_points, 1000000);
  EXPECT_LE(f.used_points, o.max_points);
  EXPECT_GT(f.used_points, 100);
  for (const pcl::PointXYZ& q : registration.points()) EXPECT_LT(std::abs(q.x), 0.2);
}

}  // namespace
}  // namespace liver_sim
