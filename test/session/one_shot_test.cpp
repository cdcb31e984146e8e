// The tracking session's one-shot registration of a first cloud far from the model (the organ
// deformed and moved beyond the tracker's 15 mm gate), made on its own thread while frames go
// on, then tracked. ROS-free. The truth is the phantom under a lift the session is not told of,
// seen moved rigidly: a consistency check (the same mesh and material), not accuracy.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <thread>

#include "liver_sim/session/tracking_session.h"
#include "scenarios.h"
#include "source_files.h"

namespace liver_sim {
namespace {

struct FarCloud {
  Scene scene = load_scene(source("config/scenes/liver_phantom.yaml"));
  TetMesh mesh = load_scene_mesh(scene);
  Eigen::Isometry3d moved = Eigen::Isometry3d::Identity();  // the model's frame -> the cloud's
  Eigen::VectorXd truth;                                      // the lifted shape, the cloud's frame
  Cloud cloud;
  double displacement = 0;  // m, the nodes' mean distance from the rest shape to the truth

  FarCloud() {
    Scene lifted = scene;
    lifted.loads.push_back(underside_lift(mesh, 15.0));
    LiverModel model(mesh, lifted);
    EXPECT_TRUE(model.step().converged());
    const Eigen::VectorXd& x = model.positions();
    CameraView view = front_view(x);
    view.noise = 1e-3;
    view.seed = 3;
    const pcl::PointCloud<pcl::PointXYZ> seen = render_surface_cloud(x, model.boundary(), view).cloud;
    moved.linear() = Eigen::AngleAxisd(0.12, Eigen::Vector3d(0.3, 1, 0.2).normalized()).toRotationMatrix();
    moved.translation() = Eigen::Vector3d(0.012, -0.008, 0.014);
    for (const pcl::PointXYZ& p : seen) {
      const Eigen::Vector3f q = (moved * p.getVector3fMap().cast<double>()).cast<float>();
      cloud.points.push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
    }
    cloud.stamp = 1;
    const Eigen::VectorXd rest = LiverModel(mesh, scene).positions();
    truth = x;
    for (Eigen::Index i = 0; i < x.size(); i += 3) {
      truth.segment<3>(i) = moved * x.segment<3>(i);
      displacement += (truth.segment<3>(i) - rest.segment<3>(i)).norm();
    }
    displacement /= x.size() / 3;
  }

  // The nodes' mean distance to the truth, the session's model seen in the cloud's frame.
  double error(const TrackingSession& s) const {
    const Eigen::Isometry3d to_cloud = s.registration().alignment().inverse();
    const Eigen::VectorXd& y = s.model().positions();
    double sum = 0;
    for (Eigen::Index i = 0; i < y.size(); i += 3) sum += (to_cloud * y.segment<3>(i) - truth.segment<3>(i)).norm();
    return sum / (y.size() / 3);
  }
};

// The tests' session: the analysis in the frame, the one-shot registration on.
SessionOptions one_shot_options() {
  SessionOptions o;
  o.analysis = RegistrationAnalysis::Placement::InFrame;
  o.one_shot = OneShotOptions();
  return o;
}

// Frames until the session is idle or `frames` have run.
void settle(TrackingSession& s, int frames) {
  for (int i = 0; i < frames && s.advance().converging; ++i) {
  }
}

TEST(OneShotSession, AFarDeformedFirstCloudIsRegisteredOffTheFrameThread) {
  // The first cloud, 15 N of lift and a rigid motion of 20 mm and 7 degrees away: the session
  // starts its one-shot registration and frames return while it runs; once adopted the model
  // is within a quarter of the truth's displacement, and better than the tracker alone given
  // the same cloud. Mutation seen failing: the one-shot's result dropped (adopt_one_shot
  // registering the cloud with the tracker instead): the error is the tracker's.
  FarCloud far;
  TrackingSession session(far.mesh, far.scene, one_shot_options());
  settle(session, 50);  // the scene's own equilibrium first
  session.submit(far.cloud);
  FrameReport report = session.advance();
  EXPECT_EQ(report.one_shot, FrameReport::OneShot::Started);
  EXPECT_FALSE(report.cloud.has_value());
  EXPECT_EQ(session.clouds_registered(), 0u);
  int frames_while_running = 0;
  while (report.one_shot != FrameReport::OneShot::Adopted) {
    ASSERT_NE(report.one_shot, FrameReport::OneShot::Refused) << session.notices().last_refusal();
    if (session.one_shot_running()) ++frames_while_running;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    report = session.advance();
  }
  EXPECT_GT(frames_while_running, 0);
  ASSERT_TRUE(report.cloud.has_value());
  EXPECT_EQ(session.clouds_registered(), 1u);
  settle(session, 200);
  const double one_shot = far.error(session);

  SessionOptions alone_options;
  alone_options.analysis = RegistrationAnalysis::Placement::InFrame;
  TrackingSession alone(far.mesh, far.scene, alone_options);
  settle(alone, 50);
  alone.submit(far.cloud);
  settle(alone, 200);
  const double tracker = far.error(alone);
  RecordProperty("one_shot_mm", std::to_string(1e3 * one_shot));
  RecordProperty("tracker_mm", std::to_string(1e3 * tracker));
  EXPECT_LT(one_shot, 0.25 * far.displacement) << "displacement " << far.displacement << " m";
  EXPECT_LT(one_shot, 0.5 * tracker);
}

TEST(OneShotSession, AFirstCloudOfTheSceneItselfLeavesTheModelWhereItIs) {
  // The first cloud sees the organ as the scene already explains it (its own equilibrium under
  // gravity on its supports, which sags from the rest mesh): the one-shot starts from the
  // session's state, so it finds no rigid motion and the model stays. Mutation seen failing:
  // the solve started from the rest mesh (no set_reference): the sag taken for a rigid motion
  // of 11 mm and the targets 16 mm off in the node's registration test.
  FarCloud far;
  TrackingSession session(far.mesh, far.scene, one_shot_options());
  settle(session, 50);
  const Eigen::VectorXd equilibrium = session.model().positions();
  const Eigen::VectorXd rest = LiverModel(far.mesh, far.scene).positions();
  CameraView view = front_view(equilibrium);
  view.noise = 1e-3;
  view.seed = 5;
  Cloud cloud;
  cloud.points = render_surface_cloud(equilibrium, session.model().boundary(), view).cloud;
  cloud.stamp = 1;
  session.submit(cloud);
  while (session.advance().one_shot != FrameReport::OneShot::Adopted)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const Eigen::VectorXd& y = session.model().positions();
  double sag = 0, error = 0;
  for (Eigen::Index i = 0; i < y.size(); i += 3) {
    sag += (equilibrium.segment<3>(i) - rest.segment<3>(i)).norm();
    error += (y.segment<3>(i) - equilibrium.segment<3>(i)).norm();
  }
  sag /= y.size() / 3;
  error /= y.size() / 3;
  RecordProperty("sag_mm", std::to_string(1e3 * sag));
  RecordProperty("error_mm", std::to_string(1e3 * error));
  EXPECT_LT(session.registration().alignment().translation().norm(), 2e-3);
  EXPECT_LT(error, 0.2 * sag) << "sag " << sag << " m";
}

TEST(OneShotSession, AFirstCloudTooSmallToTrackIsRefusedAndTheNextOneSolved) {
  // Fewer finite points than registration.min_points: refused as the tracker refuses it, and
  // the one-shot still waits for a cloud. Mutation seen failing: the check left out (the
  // handful started a one-shot solve).
  FarCloud far;
  TrackingSession session(far.mesh, far.scene, one_shot_options());
  Cloud few;
  const int min_points = far.scene.registration.min_points;
  for (int i = 0; i < min_points - 1; ++i) few.points.push_back(far.cloud.points[i * far.cloud.points.size() / min_points]);
  session.submit(few);
  EXPECT_EQ(session.advance().one_shot, FrameReport::OneShot::None);
  EXPECT_NE(session.notices().last_refusal().find("min_points"), std::string::npos) << session.notices().last_refusal();
  session.submit(far.cloud);
  EXPECT_EQ(session.advance().one_shot, FrameReport::OneShot::Started);
}

TEST(OneShotSession, AResetCallsForAnotherOneShot) {
  // After a reset the next cloud starts a one-shot registration again; the clouds that come
  // while one runs wait for it (none registered before it is adopted).
  FarCloud far;
  TrackingSession session(far.mesh, far.scene, one_shot_options());
  session.submit(far.cloud);
  EXPECT_EQ(session.advance().one_shot, FrameReport::OneShot::Started);
  while (session.advance().one_shot != FrameReport::OneShot::Adopted)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  session.submit(Reset{});
  session.advance();
  EXPECT_EQ(session.clouds_registered(), 0u);
  session.submit(far.cloud);
  EXPECT_EQ(session.advance().one_shot, FrameReport::OneShot::Started);
  Cloud later = far.cloud;
  later.stamp = 2;
  session.submit(later);
  FrameReport report = session.advance();
  while (report.one_shot != FrameReport::OneShot::Adopted) {
    EXPECT_FALSE(report.cloud.has_value());
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    report = session.advance();
  }
  EXPECT_EQ(session.clouds_registered(), 1u);
  EXPECT_EQ(session.reflected_stamp(), 1);
  report = session.advance();  // the cloud that waited
  ASSERT_TRUE(report.cloud.has_value());
  EXPECT_EQ(session.reflected_stamp(), 2);
}


// The height (m) of the surface at positions x above the point xy: the highest crossing of the
// vertical line through xy with a boundary triangle.
double surface_height(const Eigen::VectorXd& x, const Eigen::MatrixX3i& F, const Eigen::Vector2d& xy) {
  double top = -std::numeric_limits<double>::infinity();
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d a = x.segment<3>(3 * F(t, 0)), b = x.segment<3>(3 * F(t, 1)), c = x.segment<3>(3 * F(t, 2));
    Eigen::Matrix2d e;
    e << (b - a).head<2>(), (c - a).head<2>();
    if (std::abs(e.determinant()) < 1e-15) continue;
    const Eigen::Vector2d uv = e.inverse() * (xy - a.head<2>());
    if (uv.minCoeff() < 0 || uv.sum() > 1) continue;
    top = std::max(top, a.z() + uv[0] * (b - a).z() + uv[1] * (c - a).z());
  }
  return top;
}

// scripts/measure_or.py's probe, frame by frame at 30 Hz: a 2.5 mm shaft above the tumour,
// pressing 2-6 mm into the surface while it sweeps 1 cm to and fro in 2 s.
struct PressingProbe {
  Eigen::Vector3d above;  // the tumour's centre at the surface's height
  InstrumentOptions options;
  explicit PressingProbe(const LiverModel& model) {
    const Eigen::Vector2d tumour(-0.050, -0.020);
    above << tumour, surface_height(model.positions(), model.boundary(), tumour);
    options.name = "probe";
    options.type = InstrumentOptions::Type::Shaft;
    options.radius = 0.0025;
    options.length = 0.1;
  }
  Eigen::Vector3d tip(int frame) const {
    const double phase = 2 * M_PI * frame / 60.0;
    const double depth = 0.002 + 0.004 * (0.5 - 0.5 * std::cos(phase));
    return above + Eigen::Vector3d(0.005 * std::sin(0.5 * phase), 0, options.radius - depth);
  }
  InstrumentPose pose(int frame) const {
    const Stamp stamp = static_cast<Stamp>(1e9 * frame / 30.0);
    return InstrumentPose{options.name, tip(frame), Eigen::Quaterniond::Identity(), stamp, stamp};
  }
};

TEST(OneShotSession, TrackingAfterTheHandOverConvergesWhileAProbePresses) {
  // The node's real-time settings (node_options.cpp) on the phantom; a probe pressing as
  // scripts/measure_or.py drives it; clouds at 15 Hz rendered from a model of the same scene
  // solved to equilibrium under the same probe (a consistency check: the same code and mesh),
  // the 25 mm around the tip hidden by the instrument. The first cloud comes with the probe
  // 4 mm deep; after the hand-over the probe sweeps on for two seconds, then rests. While inputs
  // come every frame is one iteration, capped alike with and without the one-shot; the measure
  // is how many frames the model takes to converge once they stop, and its distance to the
  // truth then, against the tracker alone given the same clouds. Mutation killed (tried): the
  // instruments' forces left in the shape's loads at the hand-over (adopt_one_shot): a ghost
  // press stays where the probe was, and the model took 86 frames to converge (the tracker
  // alone 10, the one-shot with its press left out 14).
  const std::string path = source("config/scenes/liver_phantom.yaml");
  const Scene scene = load_scene(path, {"solver.strategy=modified_newton", "solver.max_iterations=2", "registration.frame_updates=1"});
  const TetMesh mesh = load_scene_mesh(scene);
  LiverModel truth(mesh, load_scene(path));
  ASSERT_TRUE(truth.step().converged());
  const PressingProbe probe(truth);
  const int truth_probe = truth.add_instrument(probe.options);
  const CameraView view = front_view(truth.positions());
  auto cloud_at = [&](int frame) {
    InstrumentOptions o = probe.options;
    o.position = probe.tip(frame);
    truth.update_instrument(truth_probe, o);
    truth.step();  // up to 50 Newton iterations: the shape the cloud shows, converged or nearly
    CameraView v = view;
    v.noise = 1e-3;
    v.seed = frame;
    Cloud cloud;
    for (const pcl::PointXYZ& p : render_surface_cloud(truth.positions(), truth.boundary(), v).cloud)
      if ((p.getVector3fMap().cast<double>() - o.position).norm() > 0.025) cloud.points.push_back(p);
    cloud.stamp = static_cast<Stamp>(1e9 * frame / 30.0);
    return cloud;
  };
  constexpr int kFirstCloud = 16, kLastFrame = 75;
  int settle_frames[2] = {0, 0};
  double error[2] = {0, 0};
  for (const bool one_shot : {false, true}) {
    SessionOptions o = one_shot_options();
    if (!one_shot) o.one_shot.reset();
    TrackingSession session(mesh, scene, o);
    settle(session, 50);
    InstrumentRequest declare;
    declare.name = probe.options.name;
    declare.type = "shaft";
    declare.radius = probe.options.radius;
    declare.length = probe.options.length;
    ASSERT_TRUE(session.submit(declare));
    int frame = 0;
    for (; frame < kFirstCloud; ++frame) {
      session.submit(probe.pose(frame));
      session.advance();
    }
    session.submit(cloud_at(frame));
    FrameReport report = session.advance();
    while (one_shot && report.one_shot != FrameReport::OneShot::Adopted) {  // the probe held meanwhile
      ASSERT_NE(report.one_shot, FrameReport::OneShot::Refused) << session.notices().last_refusal();
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      report = session.advance();
    }
    for (++frame; frame <= kLastFrame; ++frame) {
      session.submit(probe.pose(frame));
      if (frame % 2 == 0) session.submit(cloud_at(frame));
      session.advance();
    }
    int& frames = settle_frames[one_shot];
    for (; frames < 200 && session.advance().converging; ++frames) {
    }
    EXPECT_EQ(session.state(), SessionState::Converged) << one_shot;
    const Eigen::VectorXd& y = session.model().positions();
    const Eigen::Isometry3d to_cloud = session.registration().alignment().inverse();
    for (Eigen::Index i = 0; i < y.size(); i += 3) error[one_shot] += (to_cloud * y.segment<3>(i) - truth.positions().segment<3>(i)).norm();
    error[one_shot] /= y.size() / 3;
  }
  RecordProperty("settle_frames_tracker", settle_frames[0]);
  RecordProperty("settle_frames_one_shot", settle_frames[1]);
  RecordProperty("error_tracker_mm", std::to_string(1e3 * error[0]));
  RecordProperty("error_one_shot_mm", std::to_string(1e3 * error[1]));
  EXPECT_LE(settle_frames[1], settle_frames[0] + 5);
  // The one-shot's own fit (patches 4 cm apart) is coarser than the tracker's, which starts
  // from the truth's own scene: within a quarter of the probe's 4 mm press.
  EXPECT_LT(error[1], 1e-3);
}

}  // namespace
}  // namespace liver_sim
