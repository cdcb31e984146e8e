#include "status_publisher.h"

#include <algorithm>
#include <chrono>
#include <sstream>

#include "msg_conversion.h"

namespace liver_sim {

StatusPublisher::StatusPublisher(ros::NodeHandle& nh, ros::NodeHandle& pnh, TrackingSession& session,
                                 std::function<CloudBridge::Counts()> clouds, const std::string& frame_id)
    : session_(session), clouds_(std::move(clouds)), frame_id_(frame_id), updater_(nh, pnh) {
  status_pub_ = pnh.advertise<SimulationStatus>("status", 10);
  updater_.setHardwareID("liver_sim");
  updater_.add("liver model", this, &StatusPublisher::diagnose);
}

StatusPublisher::~StatusPublisher() {
  stop_heartbeat_ = true;
  if (heartbeat_.joinable()) heartbeat_.join();
}

void StatusPublisher::start_heartbeat() {
  heartbeat_ = std::thread([this] {
    while (!stop_heartbeat_ && ros::ok()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      heartbeat();
    }
  });
}

void StatusPublisher::frame_started() {
  std::lock_guard<std::mutex> lock(status_mutex_);
  frame_start_ = ros::WallTime::now();
}

void StatusPublisher::frame_ended() {
  std::lock_guard<std::mutex> lock(status_mutex_);
  frame_start_ = ros::WallTime();
}

void StatusPublisher::note_step() { step_times_.push_back(ros::WallTime::now()); }

double StatusPublisher::largest_radius_95() const {
  double largest = 0;
  for (const TargetUncertainty::Covariance& c : session_.covariances())
    largest = std::max(largest, ellipsoid_95(c.total).semi_axes.z());
  return largest;
}

std_msgs::Header StatusPublisher::publish(const StepResult& r, double rate) {
  const LiverModel& model = session_.model();
  const RegistrationFrame& registered = session_.registered();
  SimulationStatus s;
  s.header.frame_id = frame_id_;
  s.step = session_.steps();
  const ros::WallTime now = ros::WallTime::now();
  while (!step_times_.empty() && step_times_.front() < now - ros::WallDuration(1.0)) step_times_.pop_front();
  s.rate = static_cast<double>(step_times_.size());  // steps in the last second
  s.step_time = r.timing.total_ms / 1000.0;
  s.iterations = r.iterations;
  s.residual = r.residual;
  s.max_displacement = model.max_displacement();
  s.active_contacts = r.contacts;
  s.state = state_word(session_.state());
  s.registration_rms = registered.rms;
  s.correspondences = registered.correspondences;
  s.clouds_registered = session_.clouds_registered();
  s.registration_coverage = registered.coverage;
  s.registration_inlier_fraction = registered.inlier_fraction;
  s.registration_rms_all = registered.rms_all;
  s.target_radius_95 = largest_radius_95();
  s.faults = session_.faults();
  for (bool held : session_.registration().supports_held()) s.supports_held += held;
  std::string waiting;  // instruments whose tf frame has not appeared yet
  for (const InstrumentSlots::Slot& slot : session_.instruments()) {
    if (slot.waiting) waiting += (waiting.empty() ? "" : ", ") + slot.name + " (frame '" + slot.frame + "')";
    if (slot.index < 0 || !model.instrument(slot.index).enabled) continue;
    s.instrument_names.push_back(slot.name);
    s.instrument_contacts.push_back(model.instrument_reaction(slot.index).contacts);
  }
  const Eigen::Isometry3d& a = session_.registration().alignment();
  s.rigid_alignment_active = a.matrix() != Eigen::Matrix4d::Identity();
  s.rigid_alignment = to_transform(a);
  // A refusal or an event is told in the next status only: later ones say how the model is.
  const std::string fresh = session_.notices().take_fresh(&s.rejected_inputs);
  s.text = r.message;
  const std::string one_shot = session_.one_shot_running() ? "one-shot registration of a cloud running" : "";
  for (const std::string& part : {fresh, one_shot, waiting.empty() ? "" : "waiting for tf, out of the scene: " + waiting})
    if (!part.empty()) s.text += (s.text.empty() ? "" : "; ") + part;
  // Stamped and published under the heartbeat's lock: it never sends an older step after a newer
  // one, nor an earlier stamp after a later one.
  std::lock_guard<std::mutex> lock(status_mutex_);
  s.header.stamp = ros::Time::now();
  // When it was stamped, not when the publish returned: the heartbeat keeps the stamps (and so
  // the arrivals) within a frame of each other, however long sending took.
  last_status_time_ = ros::WallTime::now();
  status_pub_.publish(s);
  last_status_ = s;
  frame_period_ = 1.0 / rate;
  return s.header;
}

// While a long frame runs (a factorisation, a part of the analysis) and no status went out for
// one frame, ~status keeps the loop's rate: the last step's status again, state "busy", every
// frame, so that a guidance stack watching it sees a live node whose mesh is its last good state.
void StatusPublisher::heartbeat() {
  std::lock_guard<std::mutex> lock(status_mutex_);
  const ros::WallTime now = ros::WallTime::now();
  const ros::WallDuration period(frame_period_);
  // One frame since the last status, counted from that status: from the frame's start, a frame
  // that starts after the loop slept out its slot leaves up to two frames without one. The frame
  // must have run a quarter of a frame, so that a short frame (one that only takes inputs, its
  // status due at ~publish_rate) is not called busy; a longer wait would hold the status back for
  // it after a frame that started late in its slot.
  if (frame_start_.isZero() || last_status_time_.isZero() || now - last_status_time_ < period ||
      now - frame_start_ < period * 0.25)
    return;
  SimulationStatus s = last_status_;
  s.header.stamp = ros::Time::now();
  s.state = kBusyWord;
  std::ostringstream text;
  text << "a frame in progress for " << static_cast<int>((now - frame_start_).toSec() * 1000)
       << " ms; the mesh is the last step's";
  s.text = text.str();
  status_pub_.publish(s);
  last_status_time_ = now;
}

void StatusPublisher::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  using diagnostic_msgs::DiagnosticStatus;
  const SessionState state = session_.state();
  const unsigned char level = state == SessionState::Diverged || state == SessionState::Fault ? DiagnosticStatus::ERROR
                              : state == SessionState::Iterating                               ? DiagnosticStatus::WARN
                                                                                               : DiagnosticStatus::OK;
  const StepResult& last = session_.last_step();
  const RegistrationFrame& registered = session_.registered();
  const CloudBridge::Counts clouds = clouds_();
  stat.summary(level, state_word(state));
  stat.add("steps", session_.steps());
  stat.add("factorisations in the steps", session_.factorizations());  // the frames' largest cost
  stat.add("steps iterated past their cap", session_.steps_past_cap());  // solver.capped_residual
  stat.add("last step time (s)", last.timing.total_ms / 1000.0);
  stat.add("residual", last.residual);
  stat.add("active contacts", last.contacts);
  stat.add("faults", session_.faults());
  stat.add("last fault", session_.last_fault());
  stat.add("rejected inputs", session_.notices().refused());
  stat.add("point clouds received", clouds.received);
  stat.add("point clouds registered", session_.clouds_registered());
  stat.add("registration RMS (m)", registered.rms);
  stat.add("registration coverage", registered.coverage);
  stat.add("registration inlier fraction", registered.inlier_fraction);
  stat.add("registration RMS of all points (m)", registered.rms_all);
  stat.add("target 95% radius, largest (m)", largest_radius_95());
  stat.add("last analysis processor time (s)", session_.analysis_cpu_time());
  stat.add("tissue stiffness factor", session_.model().stiffness_scale());
  stat.add("hidden loads, sum of magnitudes (N)", session_.registration().hidden_load_total());
  stat.add("last cloud size", clouds.last_points);
  stat.add("last cloud filter time (s)", clouds.last_filter_s);
  stat.add("last rejection", session_.notices().last_refusal());
}

}  // namespace liver_sim
