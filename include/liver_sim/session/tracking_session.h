// A tracking session, ROS-free: the liver model as an OR's guidance stack drives it, frame after
// frame. It owns the model (LiverModel), its registration to point clouds (SurfaceRegistration),
// the registration's analyses (registration_analysis.h), the loop's barrier (StepGuard) and the
// named instruments (instrument_slots.h).
//
// Any thread submits inputs: each is kept as the latest of its kind (a cloud, each instrument's
// pose, a reset, a capsule change, live options), so nothing queues, and wakes the simulation
// thread if it waits for one (wait_for_input). The simulation thread calls advance() once a
// frame: it applies what was submitted, then steps when there is something to
// do (a new input, a step that has not converged, a cloud still being registered, estimates the
// analysis changed), behind the barrier, and reports what the frame did. A step that fails is a
// counted fault and the model keeps its last good state.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/registration/registration.h"
#include "liver_sim/runtime/input_signal.h"
#include "liver_sim/session/inputs.h"
#include "liver_sim/session/instrument_slots.h"
#include "liver_sim/session/notices.h"
#include "liver_sim/session/one_shot_worker.h"
#include "liver_sim/session/registration_analysis.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/simulation/step_guard.h"

namespace liver_sim {

// How the model is after a frame.
enum class SessionState {
  Idle,       // nothing to do: the last step converged, or no input since
  Converged,  // this frame's step converged
  Iterating,  // this frame's step has not converged yet: the next frame goes on
  Diverged,   // this frame's step diverged and was rolled back; waits for new input
  Fault,      // a fault (an exception, a non-finite value): the last good state kept
};

struct SessionOptions {
  RegistrationAnalysis::Placement analysis = RegistrationAnalysis::Placement::Background;
  double analysis_period = 1.0;  // s (wall clock): at most one analysis a period, after a registered cloud
  InstrumentSlots::Settings instruments;
  int test_fault_every = 0;      // StepGuard::set_test_fault_every
  Eigen::VectorXd start;         // positions the model starts from (3 #V, m); empty: its rest shape
  // Processors of the background work (factor refreshes, analyses); empty: the simulation
  // thread's. A refusal is told (Notices) and leaves them there.
  std::vector<int> helper_processors;
  // One-shot registration (one_shot.h), on a thread of its own while the frames go on, of the
  // first cloud after the start or a reset, and of the cloud after one whose registration
  // accepted less than one_shot_below_inliers of its points or was refused (the organ far from
  // the model); the clouds that come meanwhile wait, the latest one registered once it is
  // adopted. None: every cloud to the tracker alone.
  std::optional<OneShotOptions> one_shot;
  double one_shot_below_inliers = 0.5;  // -, in [0, 1]
  // The frames' clocks, read where a frame needs them (staleness, the analysis's period and stamp).
  std::function<FrameTime()> clock = [] { return FrameTime(); };
};

// What a frame did.
struct FrameReport {
  bool stepped = false;          // a step ran (one that faulted included)
  StepResult step;               // its result
  SessionState state = SessionState::Idle;
  bool converging = false;       // the next frame steps even without input
  int factorizations = 0;        // in this frame's steps
  std::optional<RegistrationFrame> cloud;  // of a cloud registered in this frame (a rolled-back one too)
  bool hidden_loads_reverted = false;  // a registration step diverged on new hidden loads
  bool reset = false;            // a reset was applied
  bool instruments_redrawn = false;  // the model's instruments changed
  RegistrationAnalysis::Outcome analysis;  // adopted at the start of the frame or made in it
  std::string capsule_error;     // a capsule change the model refused at last (the one before kept)
  enum class Live { None, Applied, Refused } live = Live::None;  // a LiveOptions change
  std::string fault;             // a fault met applying the inputs
  // The one-shot registration: started on this frame's cloud, adopted in this frame (`cloud`
  // is its hand-over's registration), or refused (told as a refusal).
  enum class OneShot { None, Started, Adopted, Refused } one_shot = OneShot::None;
};

class TrackingSession {
 public:
  // Builds the model from `mesh` and `scene`; throws std::invalid_argument naming the problem.
  TrackingSession(TetMesh mesh, const Scene& scene, SessionOptions options, Notices::Sink sink = nullptr);

  // --- Any thread: the latest input of each kind, applied at the start of the next frame.
  bool submit(const InstrumentRequest& c);  // false: refused
  void submit(const InstrumentPose& p);
  void submit(const FramePose& p);
  void submit(Cloud cloud);
  void submit(const Reset& reset);       // drops a cloud not yet registered and an alignment asked for
  void submit(const AlignRigidly&);      // applies to the next cloud
  void submit(const LiveOptions& live);  // reported by FrameReport::live
  // A capsule change, validated now and applied at the next frame; `capsule`: the capsule the
  // model will have (the one in force or pending, when refused). Returns "" or the refusal.
  std::string submit(const CapsuleEdit& edit, CapsuleOptions& capsule);
  // An input the caller holds until the frame's start (the node's reconfigure request): the
  // frame wait is woken as by a submitted one.
  void wake() { input_.notify(); }
  // A refusal met outside the session (a message that could not be converted).
  void refuse(const std::string& why) { notices_.refuse(why); }

  // --- Simulation thread.
  // Until an input is submitted (true; at once when one was since the last advance() took the
  // inputs) or the deadline (false).
  bool wait_for_input(InputSignal::Clock::time_point deadline) { return input_.wait_until(deadline); }
  FrameReport advance();
  // A fault met outside advance() (publishing): counted, and the state says so.
  void count_fault(const std::string& text);
  // In frame analyses only: the next analysis also makes the targets' covariances.
  void want_covariances() { analysis_.want_covariances(); }

  const LiverModel& model() const { return *model_; }
  const SurfaceRegistration& registration() const { return *registration_; }
  const RegistrationFrame& registered() const { return registered_; }  // the fit shown: the last cloud's or refinement's
  uint64_t clouds_registered() const { return clouds_registered_; }
  bool one_shot_running() const { return one_shot_ && one_shot_->running(); }  // any thread
  const std::vector<TargetUncertainty::Covariance>& covariances() const { return analysis_.covariances(); }
  Stamp analysis_stamp() const { return analysis_.stamp(); }
  double analysis_cpu_time() const { return analysis_.cpu_time(); }
  const StepResult& last_step() const { return last_; }
  uint64_t steps() const { return steps_; }                    // since start or reset
  uint64_t factorizations() const { return factorizations_; }  // in those steps
  uint64_t steps_past_cap() const { return steps_past_cap_; }  // of those, far from equilibrium at their cap
  uint64_t faults() const { return guard_.faults(); }
  const std::string& last_fault() const { return guard_.last_fault(); }
  SessionState state() const { return state_; }
  Stamp reflected_stamp() const { return reflected_stamp_; }   // of the newest input the shape reflects
  LiveOptions live_options() const;                            // in force
  // Any thread.
  std::vector<InstrumentSlots::Slot> instruments() const { return slots_.slots(); }
  Notices& notices() { return notices_; }

 private:
  // The pending inputs into the model; true when the model must step.
  bool apply_inputs(FrameReport& report);
  // All of it or nothing: none when refused, else whether the model changed.
  std::optional<bool> apply_live(const LiveOptions& live);
  void apply_reset(const Reset& reset);
  // Registers the latest cloud, if one came since the last call (or starts its one-shot
  // registration, or leaves it for after the one running).
  std::optional<RegistrationFrame> register_pending_cloud(FrameReport& report);
  // A one-shot registration done handed to the registration; a cloud it refused is tracked.
  std::optional<RegistrationFrame> adopt_one_shot(FrameReport& report);
  // The tracker's registration of `cloud`; none when refused. A refused cloud, or one it kept
  // under one_shot_below_inliers of, calls for a one-shot registration of the next.
  std::optional<RegistrationFrame> track(const Cloud& cloud);
  void count_registered(const RegistrationFrame& f, Stamp stamp);
  // The step that follows the inputs, behind the barrier, and the analysis after it.
  void simulate(FrameReport& report);
  void start_analysis(FrameReport& report);

  SessionOptions options_;
  Notices notices_;
  std::unique_ptr<LiverModel> model_;
  std::unique_ptr<SurfaceRegistration> registration_;
  RegistrationAnalysis analysis_;
  InstrumentSlots slots_;
  std::unique_ptr<OneShotWorker> one_shot_;
  StepGuard guard_;
  double pose_timeout_;  // s, as the instruments have it
  bool hold_stale_;

  // Simulation thread only.
  bool must_step_ = true;  // the first step brings the scene's loads to equilibrium
  StepResult last_;
  uint64_t steps_ = 0, factorizations_ = 0, steps_past_cap_ = 0;
  SessionState state_ = SessionState::Idle;
  Stamp reflected_stamp_ = 0;
  uint64_t clouds_registered_ = 0;
  bool registering_ = false;       // the model is converging on the last cloud
  bool one_shot_wanted_ = false;   // the next cloud is registered in one shot
  Eigen::VectorXd one_shot_reference_forces_;  // the instruments' on the tissue when the one running started
  RegistrationFrame registered_;

  // Shared with the submitting threads, under mutex_.
  mutable std::mutex mutex_;
  std::optional<Reset> pending_reset_;
  bool align_requested_ = false;
  std::optional<Cloud> pending_cloud_;
  std::optional<CapsuleOptions> pending_capsule_;
  CapsuleOptions capsule_;  // the model's, or the request the simulation thread is applying
  std::optional<LiveOptions> pending_live_;
  InputSignal input_;
};

const char* state_word(SessionState s);  // "idle", "converged", "iterating", "diverged", "fault"

}  // namespace liver_sim
