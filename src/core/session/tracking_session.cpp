#include "liver_sim/session/tracking_session.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace liver_sim {
namespace {

std::unique_ptr<LiverModel> build_model(TetMesh mesh, const Scene& scene, const Eigen::VectorXd& start) {
  auto model = std::make_unique<LiverModel>(std::move(mesh), scene);
  if (start.size() == 0) return model;
  if (start.size() != model->positions().size() || !start.allFinite())
    throw std::invalid_argument("the start positions must be finite, three per node");
  model->set_positions(start);
  return model;
}

}  // namespace

const char* state_word(SessionState s) {
  switch (s) {
    case SessionState::Idle: return "idle";
    case SessionState::Converged: return "converged";
    case SessionState::Iterating: return "iterating";
    case SessionState::Diverged: return "diverged";
    case SessionState::Fault: return "fault";
  }
  return "";
}

TrackingSession::TrackingSession(TetMesh mesh, const Scene& scene, SessionOptions options, Notices::Sink sink)
    : options_(std::move(options)),
      notices_(std::move(sink)),
      model_(build_model(std::move(mesh), scene, options_.start)),
      registration_(std::make_unique<SurfaceRegistration>(*model_, scene.registration)),
      analysis_(*model_, scene, options_.analysis, options_.analysis_period),
      slots_(*model_, options_.instruments, notices_),
      pose_timeout_(options_.instruments.pose_timeout),
      hold_stale_(options_.instruments.hold_stale),
      capsule_(scene.capsule) {
  guard_.set_test_fault_every(options_.test_fault_every);
  if (options_.one_shot) {
    if (!(options_.one_shot_below_inliers >= 0 && options_.one_shot_below_inliers <= 1))
      throw std::invalid_argument("one_shot_below_inliers must be in [0, 1]");
    one_shot_ = std::make_unique<OneShotWorker>(model_->mesh(), scene, *options_.one_shot);
    one_shot_wanted_ = true;
  }
  if (!options_.helper_processors.empty()) {
    std::string refused = model_->stepper().place_background(options_.helper_processors);
    if (refused.empty()) refused = analysis_.place(options_.helper_processors);
    if (refused.empty() && one_shot_) refused = one_shot_->place(options_.helper_processors);
    if (!refused.empty()) notices_.tell("background work not placed (" + refused + "); it runs beside the frames");
  }
}

bool TrackingSession::submit(const InstrumentRequest& c) {
  const bool accepted = slots_.command(c);
  if (accepted) input_.notify();
  return accepted;
}

void TrackingSession::submit(const InstrumentPose& p) {
  slots_.pose(p);
  input_.notify();
}

void TrackingSession::submit(const FramePose& p) {
  slots_.frame_pose(p, options_.clock().stamp);
  input_.notify();
}

void TrackingSession::submit(Cloud cloud) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_cloud_ = std::move(cloud);  // replaced, never queued: the latest cloud wins
  }
  input_.notify();
}

void TrackingSession::submit(const Reset& reset) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_reset_ = reset;
    align_requested_ = false;
    pending_cloud_.reset();
  }
  input_.notify();
}

void TrackingSession::submit(const AlignRigidly&) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    align_requested_ = true;
  }
  input_.notify();
}

void TrackingSession::submit(const LiveOptions& live) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_live_ = live;
  }
  input_.notify();
}

std::string TrackingSession::submit(const CapsuleEdit& edit, CapsuleOptions& capsule) {
  std::unique_lock<std::mutex> lock(mutex_);
  CapsuleOptions c = pending_capsule_ ? *pending_capsule_ : capsule_;
  c.enabled = edit.enabled;
  if (edit.young_modulus != 0) c.young_modulus = edit.young_modulus;
  if (edit.thickness != 0) c.thickness = edit.thickness;
  if (edit.poisson_ratio != 0) c.poisson_ratio = edit.poisson_ratio;
  const std::string error = validate(c);
  if (error.empty())
    pending_capsule_ = c;
  else
    c = pending_capsule_ ? *pending_capsule_ : capsule_;
  capsule = c;
  lock.unlock();
  if (!error.empty())
    notices_.refuse("set_capsule: " + error);
  else
    input_.notify();
  return error;
}

LiveOptions TrackingSession::live_options() const {
  LiveOptions live;
  const SolverOptions& solver = model_->solver_options();
  live.strategy = solver.strategy;
  live.max_iterations = solver.max_iterations;
  live.tolerance = solver.tolerance;
  live.time_budget = solver.time_budget;
  live.friction = model_->contact().options().friction;
  live.registration_stiffness = registration_->options().stiffness;
  live.pose_timeout = pose_timeout_;
  live.hold_stale = hold_stale_;
  return live;
}

void TrackingSession::count_fault(const std::string& text) {
  guard_.count(text);
  state_ = SessionState::Fault;
}

FrameReport TrackingSession::advance() {
  FrameReport report;
  input_.take();  // what comes from now on wakes the next wait
  // A value beyond its bounds (std::invalid_argument) is a refused input, anything else a
  // fault; the model stays as it was.
  try {
    must_step_ |= apply_inputs(report);
  } catch (const std::invalid_argument& e) {
    notices_.refuse(e.what());
    must_step_ = true;
  } catch (const std::exception& e) {
    report.fault = std::string("applying the inputs: ") + e.what();
  } catch (...) {
    report.fault = "applying the inputs: exception of unknown type";
  }
  if (!report.fault.empty()) {
    count_fault(report.fault);
    must_step_ = true;
  }
  simulate(report);
  report.instruments_redrawn = slots_.take_redrawn();
  return report;
}

bool TrackingSession::apply_inputs(FrameReport& report) {
  std::optional<Reset> reset;
  std::optional<CapsuleOptions> capsule;
  CapsuleOptions capsule_before;
  std::optional<LiveOptions> live;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    reset.swap(pending_reset_);
    capsule.swap(pending_capsule_);
    capsule_before = capsule_;
    if (capsule) capsule_ = *capsule;  // taken up now: a change meanwhile builds on it
    live.swap(pending_live_);
  }
  bool changed = reset || capsule;
  if (reset) {
    apply_reset(*reset);
    report.reset = true;
  }
  if (capsule) {
    const std::string error = model_->set_capsule(*capsule);  // validated already
    if (error.empty()) {
      analysis_.set_capsule(*capsule);
      analysis_.void_started();  // one running has the old capsule
      if (clouds_registered_ > 0) analysis_.due();
    } else {
      report.capsule_error = error;
      std::lock_guard<std::mutex> lock(mutex_);
      capsule_ = capsule_before;
    }
  }
  if (live) {
    const std::optional<bool> model_changed = apply_live(*live);
    report.live = model_changed ? FrameReport::Live::Applied : FrameReport::Live::Refused;
    changed |= model_changed.value_or(false);
  }
  if (slots_.apply(*model_, options_.clock().stamp)) {
    if (slots_.reflected_stamp() != 0) reflected_stamp_ = slots_.reflected_stamp();
    changed = true;
  }
  return changed;
}

void TrackingSession::apply_reset(const Reset& reset) {
  model_->reset();  // also removes the registration's springs
  registration_->clear();
  if (reset.positions) {
    if (reset.positions->size() != model_->positions().size() || !reset.positions->allFinite())
      throw std::invalid_argument("reset: the positions must be finite, three per node");
    model_->set_positions(*reset.positions);
  }
  slots_.release_all(*model_);
  registering_ = false;
  if (one_shot_) {
    one_shot_->cancel();  // it registers the organ before the reset
    one_shot_wanted_ = true;
  }
  clouds_registered_ = 0;
  registered_ = RegistrationFrame();
  analysis_.reset();  // an analysis still running describes the state before
  steps_ = factorizations_ = steps_past_cap_ = 0;
  reflected_stamp_ = 0;
}

std::optional<bool> TrackingSession::apply_live(const LiveOptions& live) {
  const SolverOptions solver_before = model_->solver_options();
  const ContactOptions contact_before = model_->contact().options();
  const double stiffness_before = registration_->options().stiffness;
  SolverOptions solver = solver_before;
  solver.strategy = live.strategy;
  solver.max_iterations = live.max_iterations;
  solver.tolerance = live.tolerance;
  if (live.time_budget) solver.time_budget = *live.time_budget;
  ContactOptions contact = contact_before;
  contact.friction = live.friction;
  std::string error = model_->set_solver_options(solver);
  if (error.empty()) error = model_->set_contact_options(contact);
  if (error.empty()) error = registration_->set_stiffness(live.registration_stiffness);
  if (!error.empty()) {
    model_->set_solver_options(solver_before);
    model_->set_contact_options(contact_before);
    registration_->set_stiffness(stiffness_before);
    notices_.refuse("reconfigure: " + error);
    return std::nullopt;
  }
  pose_timeout_ = live.pose_timeout;
  hold_stale_ = live.hold_stale;
  slots_.set_staleness(pose_timeout_, hold_stale_);
  return solver.strategy != solver_before.strategy || solver.max_iterations != solver_before.max_iterations ||
         solver.tolerance != solver_before.tolerance || contact.friction != contact_before.friction;
}

void TrackingSession::count_registered(const RegistrationFrame& f, Stamp stamp) {
  if (f.step.status == StepResult::Status::Diverged) return;  // rolled back: the state is the last one
  ++clouds_registered_;
  registered_ = f;
  reflected_stamp_ = stamp;
}

std::optional<RegistrationFrame> TrackingSession::register_pending_cloud(FrameReport& report) {
  std::optional<Cloud> cloud;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (one_shot_ && one_shot_->running()) return std::nullopt;  // the latest cloud waits for it
    cloud.swap(pending_cloud_);
    if (cloud && align_requested_) {
      registration_->request_rigid_alignment();
      align_requested_ = false;
    }
  }
  if (!cloud) return std::nullopt;
  if (one_shot_wanted_) {
    // A cloud too small to track is too small to register in one shot: refused alike, the one-shot
    // kept for the next.
    const int min_points = registration_->options().min_points;
    const long finite = std::count_if(cloud->points.begin(), cloud->points.end(), [](const pcl::PointXYZ& p) {
      return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
    });
    if (finite < min_points) {
      notices_.refuse("points: " + std::to_string(finite) + " finite points, too few to register in one shot (registration.min_points: " +
                      std::to_string(min_points) + ")");
      return std::nullopt;
    }
    one_shot_wanted_ = false;
    one_shot_reference_forces_ = model_->contact().forces(model_->positions());
    one_shot_->start(std::move(*cloud), registration_->alignment(), model_->positions());
    report.one_shot = FrameReport::OneShot::Started;
    notices_.tell("one-shot registration of a cloud started");
    return std::nullopt;
  }
  return track(*cloud);
}

std::optional<RegistrationFrame> TrackingSession::track(const Cloud& cloud) {
  try {
    const RegistrationFrame f = registration_->register_cloud(cloud.points, cloud.viewpoint);
    count_registered(f, cloud.stamp);
    if (one_shot_ && f.inlier_fraction < options_.one_shot_below_inliers) one_shot_wanted_ = true;
    return f;
  } catch (const std::invalid_argument& e) {
    notices_.refuse(std::string("points: ") + e.what());
    if (one_shot_) one_shot_wanted_ = true;
    return std::nullopt;
  }
}

std::optional<RegistrationFrame> TrackingSession::adopt_one_shot(FrameReport& report) {
  std::optional<OneShotWorker::Result> done = one_shot_ ? one_shot_->take() : std::nullopt;
  if (!done) return std::nullopt;
  try {
    if (!done->solved) throw std::invalid_argument(done->error);
    const RegistrationFrame f = registration_->adopt_one_shot(*done->solved, done->cloud.points, done->cloud.viewpoint,
                                                                  one_shot_reference_forces_);
    count_registered(f, done->cloud.stamp);
    report.one_shot = FrameReport::OneShot::Adopted;
    notices_.tell("one-shot registration adopted (" + std::to_string(static_cast<int>(1e3 * done->cpu_time)) +
                  " ms of processor time)");
    return f;
  } catch (const std::invalid_argument& e) {
    // A cloud too sparse or small for the one-shot's patches (a few square centimetres of
    // surface) may still be one the tracker follows: tracked, and refused only if it refuses it.
    report.one_shot = FrameReport::OneShot::Refused;
    notices_.tell(std::string("one-shot registration refused (") + e.what() + "): the cloud tracked instead");
    return track(done->cloud);
  }
}

void TrackingSession::simulate(FrameReport& report) {
  bool stepped = false;
  int factorized = 0;  // in this frame's steps (a cloud's: up to three updates, each tried twice)
  const StepResult r = guard_.step(*model_, [&] {
    report.analysis = analysis_.adopt(*registration_);
    std::optional<RegistrationFrame> registered = adopt_one_shot(report);
    if (!registered) registered = register_pending_cloud(report);
    if (registered) {
      registering_ = true;
      analysis_.due();
    }
    stepped = registered || must_step_ || report.analysis.model_changed;
    // While clouds come, the model converges on the last one in the registration's short
    // steps, so that the next cloud waits for one iteration, not a full solve.
    if (registered) {
      factorized = registered->factorizations;
      report.cloud = registered;
      report.hidden_loads_reverted = registered->hidden_loads_reverted;
      return registered->step;
    }
    if (!stepped) return StepResult();
    if (registering_) {
      registered_ = registration_->refine();  // a later update of the cloud may have moved the fit
      factorized = registered_.factorizations;
      report.hidden_loads_reverted = registered_.hidden_loads_reverted;
      return registered_.step;
    }
    const StepResult step = model_->step();
    registration_->note_step(step);
    factorized = step.factorizations;
    return step;
  });
  if (guard_.last_step_faulted()) {
    // Retried at the next frame: the fault may have been passing (memory, an injected one).
    ++steps_;
    factorizations_ += factorized;  // a step that threw tells none
    last_ = r;
    state_ = SessionState::Fault;
    report.stepped = true;
    report.step = r;
    report.factorizations = factorized;
    report.state = state_;
    report.converging = must_step_ = true;
    return;
  }
  if (!stepped) {
    if (state_ != SessionState::Diverged && state_ != SessionState::Fault) state_ = SessionState::Idle;
    start_analysis(report);  // one due while the last ran
    report.state = state_;
    report.converging = must_step_ = false;
    return;
  }
  if (r.status != StepResult::Status::NotConverged && !registration_->updates_pending()) registering_ = false;
  if (r.status != StepResult::Status::Diverged) start_analysis(report);
  ++steps_;
  factorizations_ += factorized;
  steps_past_cap_ += r.past_cap;
  last_ = r;
  state_ = r.status == StepResult::Status::Diverged ? SessionState::Diverged
           : r.converged()                           ? SessionState::Converged
                                                     : SessionState::Iterating;
  report.stepped = true;
  report.step = r;
  report.factorizations = factorized;
  report.state = state_;
  // Continue next frame while iterating; a diverged step waits for new input.
  report.converging = must_step_ = r.status == StepResult::Status::NotConverged || (r.converged() && r.iterations > 0) ||
                                   (registering_ && registration_->updates_pending());
}

void TrackingSession::start_analysis(FrameReport& report) {
  const RegistrationAnalysis::Outcome started = analysis_.start(options_.clock(), *registration_);
  if (started.adopted)
    report.analysis = started;
  else if (!started.error.empty())
    report.analysis.error = started.error;
}

}  // namespace liver_sim
