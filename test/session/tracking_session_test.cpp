// The tracking session against the parts composed by hand (the same model, registration and
// analyses called directly) and against what its inputs ask for: the latest input wins, the
// instruments' slots, staleness, resets, capsule and live changes, faults. ROS-free.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "liver_sim/session/tracking_session.h"
#include "scenarios.h"
#include "source_files.h"

namespace liver_sim {
namespace {

// The phantom and a cloud of it lifted by 5 N, seen from the front.
struct Phantom {
  Scene scene = load_scene(source("config/scenes/liver_phantom.yaml"));
  TetMesh mesh = load_scene_mesh(scene);
  pcl::PointCloud<pcl::PointXYZ> cloud(double newtons, unsigned seed) const {
    Scene lifted = scene;
    lifted.loads.push_back(underside_lift(mesh, newtons));
    LiverModel truth(mesh, lifted);
    EXPECT_TRUE(truth.step().converged());
    CameraView view = front_view(truth.positions());
    view.noise = 1e-3;
    view.seed = seed;
    return render_surface_cloud(truth.positions(), truth.boundary(), view).cloud;
  }
  Eigen::Vector3d eye() const {
    const LiverModel m(mesh, scene);
    return front_view(m.positions()).eye;
  }
};

// A clock the test sets.
struct TestClock {
  FrameTime now;
  std::function<FrameTime()> function() {
    return [this] { return now; };
  }
};

// The cube with the probe scene's material, small enough for many frames.
Scene probe_cube() {
  Scene s = load_scene(source("config/scenes/probe_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
  s.instruments.clear();
  return s;
}

// The request that declares the tests' 2 mm probe, "pointer".
InstrumentRequest pointer_probe() {
  InstrumentRequest declare;
  declare.name = "pointer";
  declare.type = "probe";
  declare.radius = 0.002;
  return declare;
}

TEST(TrackingSession, RegistersTheLatestCloudAsTheDirectCompositionDoes) {
  // Two clouds before a frame: the frame registers the second alone, to the same bits as the
  // model and registration composed by hand; the analysis in frame equals the hand-made
  // sequence (factorise, covariances, supports, stiffness, hidden loads). Guards against:
  // clouds queued (the first registered); the covariances made after the estimates.
  Phantom p;
  const pcl::PointCloud<pcl::PointXYZ> first = p.cloud(2.0, 1), second = p.cloud(5.0, 2);
  SessionOptions o;
  o.analysis = RegistrationAnalysis::Placement::InFrame;
  o.analysis_period = 0;
  TrackingSession session(p.mesh, p.scene, o);
  session.submit(Cloud{first, p.eye(), 1});
  session.submit(Cloud{second, p.eye(), 2});
  session.want_covariances();
  const FrameReport report = session.advance();
  ASSERT_TRUE(report.cloud.has_value());
  EXPECT_TRUE(report.stepped);
  EXPECT_EQ(session.clouds_registered(), 1u);
  EXPECT_EQ(session.reflected_stamp(), 2);
  EXPECT_TRUE(report.analysis.adopted) << report.analysis.error;

  LiverModel model(p.mesh, p.scene);
  SurfaceRegistration registration(model, p.scene.registration);
  TargetUncertainty uncertainty(model, p.scene.registration.uncertainty);
  StateCompliance compliance(model);
  const RegistrationFrame f = registration.register_cloud(second, p.eye());
  compliance.factorize();
  const std::vector<TargetUncertainty::Covariance> covariances = uncertainty.covariances(compliance, registration.cloud_springs());
  registration.estimate_supports(compliance, registration.cloud_springs());
  registration.estimate_tissue_stiffness(compliance, registration.cloud_springs());
  registration.estimate_hidden_loads(compliance, registration.cloud_springs());
  EXPECT_EQ(report.cloud->correspondences, f.correspondences);
  EXPECT_TRUE(same_bits(session.model().observable_state(), model.observable_state()));
  EXPECT_EQ(session.registration().hidden_loads(), registration.hidden_loads());
  ASSERT_EQ(session.covariances().size(), covariances.size());
  for (size_t i = 0; i < covariances.size(); ++i) EXPECT_EQ(session.covariances()[i].total, covariances[i].total) << i;
}

TEST(TrackingSession, TheBackgroundAnalysisDescribesTheStateItWasHanded) {
  // The same cloud in two sessions: the covariances the worker's thread made on its own model
  // (adopted at a later frame) are those made in frame on the session's model, to rounding.
  // Guards against: the analysis started before the cloud's step (the rest state's).
  Phantom p;
  const pcl::PointCloud<pcl::PointXYZ> cloud = p.cloud(5.0, 3);
  SessionOptions in_frame;
  in_frame.analysis = RegistrationAnalysis::Placement::InFrame;
  TrackingSession a(p.mesh, p.scene, in_frame);
  a.submit(Cloud{cloud, p.eye(), 1});
  a.want_covariances();
  ASSERT_TRUE(a.advance().analysis.adopted);
  TrackingSession b(p.mesh, p.scene, SessionOptions());
  b.submit(Cloud{cloud, p.eye(), 1});
  b.advance();
  bool adopted = false;
  for (int frame = 0; frame < 3000 && !adopted; ++frame) {
    adopted = b.advance().analysis.adopted;
    if (!adopted) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(adopted);
  ASSERT_EQ(b.covariances().size(), a.covariances().size());
  for (size_t i = 0; i < a.covariances().size(); ++i) {
    const Eigen::Matrix3d& c = a.covariances()[i].total;
    EXPECT_LT((b.covariances()[i].total - c).norm(), 1e-9 * c.norm()) << i;
  }
}

TEST(TrackingSession, NamedInstrumentsTakeSlotsGoStaleAndAreReleasedOnReset) {
  // A probe declared and posed: in the model at its pose; retyped: another slot, the old one out
  // of the scene; a pose older than the timeout: withdrawn and told (held when asked); a reset:
  // back to the rest shape, out until the next pose. Guards against: a retyped
  // instrument updated in its old slot (the model refuses the type change); staleness counted
  // from the pose's own stamp; a reset that keeps the instruments in the scene.
  TestClock clock;
  SessionOptions o;
  o.clock = clock.function();
  o.instruments.pose_timeout = 1.0;
  const Scene scene = probe_cube();
  TrackingSession session(load_scene_mesh(scene), scene, o);
  const Eigen::VectorXd rest = session.model().positions();
  InstrumentRequest declare = pointer_probe();
  ASSERT_TRUE(session.submit(declare));
  InstrumentPose pose{"pointer", Eigen::Vector3d(0.0075, 0.0075, 0.027), Eigen::Quaterniond::Identity(), 7, 1};
  session.submit(pose);
  FrameReport r = session.advance();
  ASSERT_EQ(session.instruments().size(), 1u);
  const int probe_slot = session.instruments()[0].index;
  ASSERT_GE(probe_slot, 0);
  EXPECT_TRUE(session.model().instrument(probe_slot).enabled);
  EXPECT_LT((session.model().instrument_pose(probe_slot).translation() - pose.position).norm(), 1e-12);
  EXPECT_EQ(session.reflected_stamp(), 7);
  EXPECT_TRUE(r.instruments_redrawn);

  declare.type = "shaft";
  declare.length = 0.05;
  ASSERT_TRUE(session.submit(declare));
  session.submit(pose);
  session.advance();
  const int shaft_slot = session.instruments()[0].index;
  EXPECT_NE(shaft_slot, probe_slot);
  EXPECT_EQ(session.model().instrument(shaft_slot).type, InstrumentOptions::Type::Shaft);
  EXPECT_FALSE(session.model().instrument(probe_slot).enabled);

  session.notices().take_fresh();
  clock.now.stamp = static_cast<Stamp>(1.5e9);  // 1.5 s after the pose came
  session.advance();
  EXPECT_FALSE(session.model().instrument(shaft_slot).enabled);
  EXPECT_NE(session.notices().take_fresh().find("withdrawn"), std::string::npos);
  LiveOptions hold = session.live_options();
  hold.hold_stale = true;
  session.submit(hold);
  EXPECT_EQ(session.advance().live, FrameReport::Live::Applied);
  EXPECT_TRUE(session.model().instrument(shaft_slot).enabled);

  session.submit(Reset{});
  r = session.advance();
  EXPECT_TRUE(r.reset);
  EXPECT_FALSE(session.model().instrument(shaft_slot).enabled);
  EXPECT_EQ(session.model().positions(), rest);
}

TEST(TrackingSession, CountsTheStepsIteratedPastTheirCapUntilAReset) {
  // A probe just above the cube, then pressed 0.8 mm into it in one frame of one iteration a
  // stage, with a time budget (far more than the frame needs): that frame cannot come within
  // solver.capped_residual in its last stage's one iteration and iterates on; the count the node
  // shows on /diagnostics says one step, and a reset clears it with the steps.
  // Kills the count not kept and the count not reset (each tried).
  TestClock clock;
  SessionOptions o;
  o.clock = clock.function();
  Scene scene = probe_cube();
  scene.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  scene.solver.max_iterations = 1;
  scene.solver.time_budget = 1000.0;
  TrackingSession session(load_scene_mesh(scene), scene, o);
  ASSERT_TRUE(session.submit(pointer_probe()));
  InstrumentPose pose{"pointer", Eigen::Vector3d(0.0075, 0.0075, 0.0172), Eigen::Quaterniond::Identity(), 1, 1};
  session.submit(pose);
  FrameReport r = session.advance();
  ASSERT_TRUE(r.stepped);
  EXPECT_FALSE(r.step.past_cap) << "the probe above the cube touches nothing";
  EXPECT_EQ(session.steps_past_cap(), 0u);

  pose.position.z() = 0.0162;
  pose.stamp = 2;
  session.submit(pose);
  r = session.advance();
  ASSERT_TRUE(r.stepped);
  ASSERT_GT(r.step.contacts, 0);
  EXPECT_GT(r.step.iterations, 2) << "two stages of one iteration each, then iterations past the cap";
  EXPECT_TRUE(r.step.past_cap);
  EXPECT_EQ(session.steps_past_cap(), 1u);
  EXPECT_GE(session.steps(), 2u);

  session.submit(Reset{});
  session.advance();
  EXPECT_EQ(session.steps_past_cap(), 0u);
}

TEST(TrackingSession, AnInputWakesTheFrameWaitUntilTheFrameTakesIt) {
  // The node starts a frame when an input arrives (frame_pacing.h): every kind of input wakes
  // the wait, and a frame takes what came before it. Guards against an input kind that does
  // not wake it (a pose then waits for the next tick) and against advance() not taking them
  // (the node would run frames back to back). Mutation killed (tried): submit(Cloud) without
  // the wake.
  SessionOptions o;
  const Scene scene = probe_cube();
  TrackingSession session(load_scene_mesh(scene), scene, o);
  const auto now = [] { return InputSignal::Clock::now(); };
  session.advance();
  EXPECT_FALSE(session.wait_for_input(now()));
  const InstrumentRequest declare = pointer_probe();
  const std::vector<std::function<void()>> inputs = {
      [&] { ASSERT_TRUE(session.submit(declare)); },
      [&] { session.submit(InstrumentPose{"pointer", Eigen::Vector3d(0, 0, 0.05), Eigen::Quaterniond::Identity(), 1, 1}); },
      [&] { session.submit(Cloud{}); },
      [&] { session.submit(Reset{}); },
      [&] { session.submit(AlignRigidly{}); },
      [&] { session.submit(session.live_options()); },
      [&] {
        CapsuleOptions c;
        ASSERT_EQ(session.submit(CapsuleEdit{true, 0, 0, 0}, c), "");
      },
      [&] { session.wake(); },  // the node's reconfigure request, held by the node
  };
  for (size_t i = 0; i < inputs.size(); ++i) {
    inputs[i]();
    EXPECT_TRUE(session.wait_for_input(now())) << "input " << i;
    session.advance();
    EXPECT_FALSE(session.wait_for_input(now())) << "input " << i << " taken by the frame";
  }
}

TEST(TrackingSession, RefusedInputsAreCountedAndChangeNothing) {
  // A capsule out of bounds, an unknown instrument's change, a pose the shape refuses, live
  // options the model refuses: each counted, the model as it was. Guards against: a
  // refused live change that keeps the parts applied before the refusal.
  const Scene scene = probe_cube();
  TrackingSession session(load_scene_mesh(scene), scene, SessionOptions());
  for (int frame = 0; frame < 20 && session.advance().converging; ++frame) {
  }
  const std::vector<double> before = session.model().observable_state();
  const SolverOptions solver = session.model().solver_options();
  CapsuleOptions capsule;
  CapsuleEdit edit;
  edit.young_modulus = -1;
  EXPECT_FALSE(session.submit(edit, capsule).empty());
  EXPECT_EQ(capsule.young_modulus, scene.capsule.young_modulus);
  InstrumentRequest change;
  change.name = "nobody";
  EXPECT_FALSE(session.submit(change));
  LiveOptions live = session.live_options();
  live.max_iterations = 1;
  live.friction = -1;  // refused after the solver's part was taken
  session.submit(live);
  const FrameReport r = session.advance();
  EXPECT_EQ(r.live, FrameReport::Live::Refused);
  EXPECT_EQ(session.notices().refused(), 3u);
  EXPECT_EQ(session.model().solver_options().max_iterations, solver.max_iterations);
  EXPECT_FALSE(r.stepped);
  EXPECT_TRUE(same_bits(session.model().observable_state(), before));
}

TEST(TrackingSession, AFaultKeepsTheLastGoodStateAndAsksTheNextFrameToStep) {
  // The barrier's test hook at every step: the state says fault, the model is the one before,
  // the fault is counted and the next frame is asked to step again. Guards against: a
  // faulted frame that does not ask the next one to step (the model never settles).
  Scene scene = load_scene(source("config/scenes/aspiration_cube.yaml"));  // suction: the step iterates
  scene.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
  SessionOptions o;
  o.test_fault_every = 1;
  TrackingSession session(load_scene_mesh(scene), scene, o);
  const std::vector<double> before = session.model().observable_state();
  const FrameReport r = session.advance();
  EXPECT_EQ(r.state, SessionState::Fault);
  EXPECT_TRUE(r.converging);
  EXPECT_EQ(session.faults(), 1u);
  EXPECT_TRUE(same_bits(session.model().observable_state(), before));
}

}  // namespace
}  // namespace liver_sim
