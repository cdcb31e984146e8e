#include "reconfigure_bridge.h"

#include <cmath>
#include <sstream>

#include "msg_conversion.h"

namespace liver_sim {

ReconfigureBridge::ReconfigureBridge(ros::NodeHandle& pnh, TrackingSession& session, const NodeOptions& options)
    : pnh_(pnh), session_(session), budget_follows_rate_(options.budget_follows_rate) {
  node_values_.rate = options.rate;
  node_values_.publish_rate = options.publish_rate;
  node_values_.color_scale_max = options.color_scale_max;
  node_values_.surface_alpha = options.surface_alpha;
  descriptions_pub_ = pnh_.advertise<dynamic_reconfigure::ConfigDescription>("parameter_descriptions", 1, true);
  descriptions_pub_.publish(LiverSimConfig::__getDescriptionMessage__());
  updates_pub_ = pnh_.advertise<dynamic_reconfigure::Config>("parameter_updates", 1, true);
  // A start value outside the config's bounds is clamped now, and said, not at the first unrelated change.
  show(clamped(current(), " at start"));
  set_service_ = pnh_.advertiseService("set_parameters", &ReconfigureBridge::on_set, this);
}

LiverSimConfig ReconfigureBridge::current() const {
  LiverSimConfig c = node_values_;
  fill_config(session_.live_options(), c);
  return c;
}

LiverSimConfig ReconfigureBridge::clamped(const LiverSimConfig& asked, const std::string& when) {
  LiverSimConfig c = asked;
  c.__clamp__();
  dynamic_reconfigure::Config a, k;
  asked.__toMessage__(a);
  c.__toMessage__(k);
  std::ostringstream told;
  auto note = [&](const std::string& name, double from, double to) {
    if (from != to && !(std::isnan(from) && std::isnan(to)))  // NaN is refused at the frame, not clamped
      told << (told.tellp() > 0 ? ", " : "") << name << " " << from << " -> " << to;
  };
  for (size_t i = 0; i < a.doubles.size() && i < k.doubles.size(); ++i) note(a.doubles[i].name, a.doubles[i].value, k.doubles[i].value);
  for (size_t i = 0; i < a.ints.size() && i < k.ints.size(); ++i) note(a.ints[i].name, a.ints[i].value, k.ints[i].value);
  if (told.tellp() > 0)
    session_.notices().tell("reconfigure" + when + ": clamped to the bounds of cfg/LiverSim.cfg: " + told.str());
  return c;
}

void ReconfigureBridge::show(const LiverSimConfig& c) {
  dynamic_reconfigure::Config m;
  c.__toMessage__(m);
  c.__toServer__(pnh_);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    shown_ = c;
  }
  updates_pub_.publish(m);
}

// A service thread: the request over the values shown, clamped, kept for the next frame; the
// reply gives the values as they will be taken (a refusal at the frame shows the old ones again).
bool ReconfigureBridge::on_set(dynamic_reconfigure::Reconfigure::Request& req,
                               dynamic_reconfigure::Reconfigure::Response& res) {
  LiverSimConfig asked;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    asked = shown_;
  }
  asked.__fromMessage__(req.config);
  const LiverSimConfig c = clamped(asked, "");
  show(c);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_ = c;
  }
  session_.wake();
  c.__toMessage__(res.config);
  return true;
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
    show(current());
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
    show(current());
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
