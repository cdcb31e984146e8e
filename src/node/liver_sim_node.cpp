#include "liver_sim_node.h"

#include <chrono>

#include "msg_conversion.h"

namespace liver_sim {
namespace {

// The node's log of what the session refused and told.
void log_notice(Notices::Kind kind, const std::string& text) {
  if (kind == Notices::Kind::Refusal)
    ROS_WARN_THROTTLE(1.0, "liver_sim: refused input: %s", text.c_str());
  else
    ROS_WARN("liver_sim: %s", text.c_str());
}

// The node's log of what a frame met.
void log_frame(const FrameReport& r) {
  if (!r.fault.empty()) ROS_ERROR_THROTTLE(1.0, "liver_sim: fault %s; the model keeps its last good state", r.fault.c_str());
  if (!r.capsule_error.empty()) ROS_ERROR("liver_sim: capsule change failed: %s", r.capsule_error.c_str());
  if (r.hidden_loads_reverted)
    ROS_WARN_THROTTLE(5.0, "liver_sim: a registration step diverged while new hidden loads acted; the loads before them act again");
  if (!r.analysis.error.empty()) ROS_WARN_THROTTLE(5.0, "liver_sim: no target uncertainty: %s", r.analysis.error.c_str());
  if (!r.analysis.estimate_error.empty())
    ROS_WARN_THROTTLE(5.0, "liver_sim: no support, stiffness or hidden loads estimate: %s", r.analysis.estimate_error.c_str());
  if (r.analysis.support_held >= 0)
    ROS_INFO("liver_sim: the clouds call for candidate support %d: held from the next step", r.analysis.support_held);
  if (!r.stepped) return;
  if (r.state == SessionState::Fault)
    ROS_ERROR_THROTTLE(1.0, "liver_sim: %s; the model keeps its last good state", r.step.message.c_str());
  if (r.state == SessionState::Diverged)
    ROS_WARN_THROTTLE(1.0, "liver_sim: step diverged (%s); kept the last good state", r.step.message.c_str());
  if (r.step.recovery)
    ROS_WARN_THROTTLE(1.0, "liver_sim: recovery step after steps rolled back in a row: %d iterations, %.0f ms",
                      r.step.iterations, r.step.timing.total_ms);
}

SessionOptions session_options(const NodeOptions& o) {
  SessionOptions s;
  s.analysis_period = o.uncertainty_period;
  if (o.one_shot) s.one_shot = OneShotOptions();
  s.test_fault_every = o.test_fault_every;
  s.helper_processors = o.helper_processors;
  // The default instrument `tool` and one per ~instrument_frames: rods with a hemispherical tip
  // (a sphere alone pressed deeper than its radius would let the tissue close over it).
  InstrumentOptions tool;
  tool.type = InstrumentOptions::Type::Shaft;
  tool.radius = o.instrument_radius;
  tool.length = o.instrument_length;
  s.instruments.tool = tool;
  s.instruments.frames = o.instrument_frames;
  s.instruments.pose_timeout = o.pose_timeout;
  s.instruments.hold_stale = o.hold_stale_instruments;
  s.clock = [] {
    const auto wall = std::chrono::steady_clock::now().time_since_epoch();
    return FrameTime{to_stamp(ros::Time::now()), std::chrono::duration<double>(wall).count()};
  };
  return s;
}

}  // namespace

LiverSimNode::LiverSimNode(ros::NodeHandle& nh, ros::NodeHandle& pnh, const NodeOptions& options)
    : options_(options), tf_listener_(tf_buffer_), pacing_(options.rate, options.publish_rate) {
  const Scene scene = load_scene(options_.scene, options_.scene_overrides);
  try {
    session_ = std::make_unique<TrackingSession>(load_scene_mesh(scene), scene, session_options(options_), log_notice);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(options_.scene + ": " + e.what());
  }
  const LiverModel& model = session_->model();
  // Clouds are cropped to the rest shape's box grown by the registration's reach and
  // ~cloud_margin for the liver's own motion.
  Eigen::AlignedBox3d cloud_box;
  for (int i = 0; i < model.positions().size(); i += 3) cloud_box.extend(model.positions().segment<3>(i));
  cloud_box.min().array() -= scene.registration.max_distance + options_.cloud_margin;
  cloud_box.max().array() += scene.registration.max_distance + options_.cloud_margin;
  instruments_ = std::make_unique<InstrumentBridge>(nh, pnh, tf_buffer_, *session_, options_.frame_id,
                                                    options_.instrument_tf_timeout);
  ROS_INFO("liver_sim: %s: %ld nodes, %ld tetrahedra, %d capsule triangles, %d vessel beams, %s mode",
           options_.scene.c_str(), static_cast<long>(model.mesh().V.rows()), static_cast<long>(model.mesh().T.rows()),
           model.capsule_triangles(), model.num_beams(), scene.solver.mode == SolverOptions::Mode::Static ? "static" : "dynamic");
  place_in_tf_tree();
  scene_ = std::make_unique<ScenePublisher>(pnh, *session_, options_.frame_id, options_.color_scale_max, options_.surface_alpha);
  clouds_ = std::make_unique<CloudBridge>(nh, tf_buffer_, *session_, options_.frame_id, cloud_box);
  status_ = std::make_unique<StatusPublisher>(nh, pnh, *session_, [this] { return clouds_->counts(); }, options_.frame_id);
  services_ = std::make_unique<Services>(pnh, *session_);
  reconfigure_ = std::make_unique<ReconfigureBridge>(pnh, *session_, options_);
}

void LiverSimNode::place_in_tf_tree() {
  if (options_.parent_frame.empty()) return;
  const std::vector<double>& t = options_.parent_transform;  // checked by read_node_options
  geometry_msgs::TransformStamped s;
  s.header.stamp = ros::Time::now();
  s.header.frame_id = options_.parent_frame;
  s.child_frame_id = options_.frame_id;
  s.transform.translation.x = t[0];
  s.transform.translation.y = t[1];
  s.transform.translation.z = t[2];
  s.transform.rotation.x = t[3];
  s.transform.rotation.y = t[4];
  s.transform.rotation.z = t[5];
  s.transform.rotation.w = t[6];
  static_broadcaster_.sendTransform(s);
}

void LiverSimNode::run() {
  while (ros::ok()) {
    status_->frame_started();
    try {
      frame();
    } catch (const std::exception& e) {
      fault(std::string("in the loop: ") + e.what());
    } catch (...) {
      fault("in the loop: exception of unknown type");
    }
    status_->frame_ended();
    pacing_.until_next_frame([this](FramePacing::Clock::time_point deadline) { return session_->wait_for_input(deadline); });
  }
}

// One frame: the inputs taken, the session's frame (inputs applied, a step when there is
// something to do, behind its barrier), then what it did published.
void LiverSimNode::frame() {
  instruments_->poll_frames();
  reconfigure_->before_frame();
  const FrameReport report = session_->advance();
  log_frame(report);
  instruments_->after_frame(report.instruments_redrawn);
  scene_->note(report);
  if (const std::optional<LiverSimConfig> c = reconfigure_->after_frame(report)) {
    pacing_.set_rates(c->rate, c->publish_rate);
    scene_->set_display(c->color_scale_max, c->surface_alpha);
  }
  if (report.stepped) {
    status_->note_step();
    publish_status(report.step);
  }
  if (pacing_.mesh_due() && scene_->publish()) pacing_.mesh_sent();
  if (!report.converging && pacing_.idle_status_due()) publish_status(session_->last_step());
  status_->update_diagnostics();
}

void LiverSimNode::publish_status(const StepResult& r) {
  instruments_->publish(status_->publish(r, pacing_.rate()));
}

void LiverSimNode::fault(const std::string& text) {
  session_->count_fault(text);
  ROS_ERROR_THROTTLE(1.0, "liver_sim: fault %s; the model keeps its last good state", text.c_str());
}

}  // namespace liver_sim
