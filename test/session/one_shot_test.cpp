// The tracking session's one-shot registration of a first cloud far from the model (the organ
// deformed and moved beyond the tracker's 15 mm gate), made on its own thread while frames go
// on, then tracked. ROS-free. The truth is the phantom under a lift the session is not told of,
// seen moved rigidly: a consistency check (the same mesh and material), not accuracy.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "liver_sim/session/tracking_session.h"
#include "scenarios.h"

namespace liver_sim {
namespace {

std::string source(const std::string& path) { return std::string(LIVER_SIM_SOURCE_DIR) + "/" + path; }

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

}  // namespace
}  // namespace liver_sim
