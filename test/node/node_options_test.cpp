// The node's parameter checks against cfg/LiverSim.cfg's bounds and the README's: each value
// beyond its bounds is refused naming its parameter, the bounds themselves pass. No master needed.
#include <gtest/gtest.h>

#include "liver_sim/LiverSimConfig.h"
#include "node_options.h"

namespace liver_sim {
namespace {

TEST(NodeOptions, EachValueBeyondItsBoundsIsRefusedByName) {
  // Guards against: the rate's upper bound dropped; NaN let through by a "v < lo" test.
  const NodeOptions valid;
  EXPECT_EQ(options_error(valid), "");
  const std::vector<std::pair<std::function<void(NodeOptions&)>, std::string>> cases = {
      {[](NodeOptions& o) { o.rate = 1001; }, "~rate"},
      {[](NodeOptions& o) { o.publish_rate = std::nan(""); }, "~rate"},
      {[](NodeOptions& o) { o.step_time_budget = 0; }, "~step_time_budget"},
      {[](NodeOptions& o) { o.test_fault_every = -1; }, "~test_fault_every"},
      {[](NodeOptions& o) { o.threads = 0; }, "~threads"},
      {[](NodeOptions& o) { o.uncertainty_period = -1; }, "~uncertainty_period"},
      {[](NodeOptions& o) { o.cloud_margin = std::nan(""); }, "~cloud_margin"},
      {[](NodeOptions& o) { o.color_scale_max = LiverSimConfig::__getMax__().color_scale_max * 2; }, "~color_scale_max"},
      {[](NodeOptions& o) { o.surface_alpha = -0.1; }, "~surface_alpha"},
      {[](NodeOptions& o) { o.pose_timeout = 61; }, "~pose_timeout"},
      {[](NodeOptions& o) { o.instrument_tf_timeout = 2; }, "~instrument_tf_timeout"},
      {[](NodeOptions& o) { o.instrument_radius = 0; }, "~instrument_radius"},
      {[](NodeOptions& o) { o.parent_frame = "or"; o.parent_transform = {0, 0, 0, 0, 0, 0, 2}; }, "~parent_transform"},
      {[](NodeOptions& o) { o.parent_frame = o.frame_id; }, "~parent_frame"},
  };
  for (const auto& [spoil, name] : cases) {
    NodeOptions o;
    spoil(o);
    EXPECT_EQ(options_error(o).rfind(name, 0), 0u) << name << ": " << options_error(o);
  }
  NodeOptions bounds;
  bounds.rate = 1000;
  bounds.publish_rate = 0.1;
  bounds.surface_alpha = 0;
  bounds.pose_timeout = 0;
  EXPECT_EQ(options_error(bounds), "");
}

TEST(NodeOptions, SchedulingIsCheckedAgainstTheProcessorsAllowed) {
  NodeOptions o;
  o.cpu_affinity = {1};
  EXPECT_EQ(scheduling_error(o, {0, 1}), "");
  EXPECT_EQ(scheduling_error(o, {0}).rfind("~cpu_affinity", 0), 0u);
  o.realtime_priority = 100;
  EXPECT_EQ(scheduling_error(o, {1}).rfind("~realtime_priority", 0), 0u);
  o.realtime_priority = 0;
  o.thread_slice = 0.5;
  EXPECT_EQ(scheduling_error(o, {1}).rfind("~thread_slice", 0), 0u);
  o.thread_slice = 0;
  EXPECT_EQ(scheduling_error(o, {1}), "");
}

TEST(NodeOptions, ScalarsBecomeSceneValuesExactly) {
  // 17 digits: a double comes back to the same bits (6, the stream's default, would not).
  EXPECT_EQ(scalar_text(XmlRpc::XmlRpcValue(0.1)), "0.10000000000000001");
  EXPECT_EQ(std::stod(scalar_text(XmlRpc::XmlRpcValue(1.0 / 3))), 1.0 / 3);
  EXPECT_EQ(scalar_text(XmlRpc::XmlRpcValue(true)), "true");
  EXPECT_EQ(scalar_text(XmlRpc::XmlRpcValue(7)), "7");
  EXPECT_EQ(scalar_text(XmlRpc::XmlRpcValue(std::string("full_newton"))), "full_newton");
  XmlRpc::XmlRpcValue list;
  list.setSize(1);
  EXPECT_THROW(scalar_text(list), std::invalid_argument);
}

}  // namespace
}  // namespace liver_sim
