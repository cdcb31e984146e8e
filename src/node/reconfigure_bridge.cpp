#include "reconfigure_bridge.h"

#include <sstream>

#include "msg_conversion.h"

namespace liver_sim {

ReconfigureBridge::ReconfigureBridge(ros::NodeHandle& pnh, TrackingSession& session, const NodeOptions& options)
    : session_(session), budget_follows_rate_(options.budget_follows_rate) {
  node_values_.rate = options.rate;
  node_values_.publish_rate = options.publish_rate;
  node_values_.color_scale_max = options.color_scale_max;
  node_values_.surface_alpha = options.surface_alpha;
  server_ = std::make_unique<dynamic_reconfigure::Server<LiverSimConfig>>(server_mutex_, pnh);
  // A value outside the config's bounds is clamped now, and said, not at the first unrelated change.
  const LiverSimConfig config = current();
  LiverSimConfig clamped = config;
  clamped.__clamp__();
  std::ostringstream changed;
  auto note = [&](const char* name, double from, double to) {
    if (from != to) changed << (changed.tellp() > 0 ? ", " : "") << name << " " << from << " -> " << to;
  };
  note("max_iterations", config.max_iterations, clamped.max_iterations);
  note("tolerance", config.tolerance, clamped.tolerance);
  note("friction", config.friction, clamped.friction);
  note("registration_stiffness", config.registration_stiffness, clamped.registration_stiffness);
  if (changed.tellp() > 0) session_.notices().tell("clamped to the live-tuning bounds (cfg/LiverSim.cfg): " + changed.str());
  server_->updateConfig(clamped);
  server_->setCallback([this](LiverSimConfig& c, uint32_t) {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_ = c;
  });
}

LiverSimConfig ReconfigureBridge::current() const {
  LiverSimConfig c = node_values_;
  fill_config(session_.live_options(), c);
  return c;
}

void ReconfigureBridge::before_frame() {
  std::optional<LiverSimConfig> c;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    c.swap(pending_);
  }
  if (!c) return;
  // The config's clamp lets NaN through: each value is checked again.
  const std::optional<SolverOptions::Strategy> strategy = parse_strategy(c->strategy);
  std::string error = rates_error(c->rate, c->publish_rate);
  if (error.empty()) error = view_error(c->color_scale_max, c->surface_alpha, c->pose_timeout);
  if (error.empty() && !strategy) error = "unknown strategy '" + c->strategy + "'";
  if (!error.empty()) {
    session_.refuse("reconfigure: " + error);
    server_->updateConfig(current());
    return;
  }
  session_.submit(to_live_options(*c, *strategy, budget_follows_rate_));
  submitted_ = c;
}

std::optional<LiverSimConfig> ReconfigureBridge::after_frame(const FrameReport& report) {
  std::optional<LiverSimConfig> c;
  c.swap(submitted_);
  if (!c || report.live == FrameReport::Live::None) return std::nullopt;
  if (report.live == FrameReport::Live::Refused) {
    server_->updateConfig(current());
    return std::nullopt;
  }
  node_values_.rate = c->rate;
  node_values_.publish_rate = c->publish_rate;
  node_values_.color_scale_max = c->color_scale_max;
  node_values_.surface_alpha = c->surface_alpha;
  ROS_INFO("liver_sim: reconfigured: %s, %d iterations a frame, tolerance %g, %g Hz, friction %g", c->strategy.c_str(),
           c->max_iterations, c->tolerance, c->rate, c->friction);
  return c;
}

}  // namespace liver_sim
