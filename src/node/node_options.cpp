#include "node_options.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "liver_sim/LiverSimConfig.h"
#include "liver_sim/runtime/worker_pool.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

std::string rates_error(double rate, double publish_rate) {
  if (rate >= 1 && rate <= 1000 && publish_rate >= 0.1 && publish_rate <= 100) return "";
  return "rate must be in [1, 1000] Hz, publish_rate in [0.1, 100] Hz";
}

std::string view_error(double color_scale_max, double surface_alpha, double pose_timeout) {
  const LiverSimConfig& low = LiverSimConfig::__getMin__();
  const LiverSimConfig& high = LiverSimConfig::__getMax__();
  std::ostringstream error;
  auto check = [&](const char* name, double v, double lo, double hi, const char* unit) {
    if (error.tellp() == 0 && !(v >= lo && v <= hi)) error << name << " must be in [" << lo << ", " << hi << "]" << unit << " (got " << v << ")";
  };
  check("color_scale_max", color_scale_max, low.color_scale_max, high.color_scale_max, " m");
  check("surface_alpha", surface_alpha, low.surface_alpha, high.surface_alpha, "");
  check("pose_timeout", pose_timeout, low.pose_timeout, high.pose_timeout, " s");
  return error.str();
}

std::string scalar_text(const XmlRpc::XmlRpcValue& value) {
  XmlRpc::XmlRpcValue& v = const_cast<XmlRpc::XmlRpcValue&>(value);  // XmlRpc's casts are not const
  std::ostringstream s;
  s.precision(17);
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean: s << (static_cast<bool>(v) ? "true" : "false"); break;
    case XmlRpc::XmlRpcValue::TypeInt: s << static_cast<int>(v); break;
    case XmlRpc::XmlRpcValue::TypeDouble: s << static_cast<double>(v); break;
    case XmlRpc::XmlRpcValue::TypeString: s << static_cast<std::string>(v); break;
    default: throw std::invalid_argument("only scalar parameters can override scene values");
  }
  return s.str();
}

std::string options_error(const NodeOptions& o) {
  if (const std::string error = rates_error(o.rate, o.publish_rate); !error.empty()) return "~" + error;
  if (!(o.step_time_budget > 0)) return "~step_time_budget must be > 0 s";
  if (o.test_fault_every < 0) return "~test_fault_every must be >= 0";
  if (o.threads != -1 && (o.threads < 1 || o.threads > WorkerPool::kMaxThreads))
    return "~threads must be in [1, " + std::to_string(WorkerPool::kMaxThreads) + "] (got " + std::to_string(o.threads) + ")";
  if (!(o.uncertainty_period >= 0)) return "~uncertainty_period must be >= 0";
  if (!(o.cloud_margin >= 0)) return "~cloud_margin must be >= 0";
  if (const std::string error = view_error(o.color_scale_max, o.surface_alpha, o.pose_timeout); !error.empty())
    return "~" + error;
  if (!(o.instrument_tf_timeout >= 0 && o.instrument_tf_timeout <= 1)) return "~instrument_tf_timeout must be in [0, 1] s";
  InstrumentOptions tool;
  tool.name = "tool";
  tool.type = InstrumentOptions::Type::Shaft;
  tool.radius = o.instrument_radius;
  tool.length = o.instrument_length;
  if (const std::string error = validate(tool); !error.empty()) return "~instrument_radius, ~instrument_length: " + error;
  if (o.parent_frame.empty()) return "";
  const std::vector<double>& t = o.parent_transform;
  if (t.size() != 7 || !std::all_of(t.begin(), t.end(), [](double v) { return std::isfinite(v); }) ||
      !(std::abs(Eigen::Vector4d(t[3], t[4], t[5], t[6]).norm() - 1) < 1e-3))
    return "~parent_transform must be [x, y, z, qx, qy, qz, qw] (m; a unit quaternion)";
  if (o.parent_frame == o.frame_id) return "~parent_frame must differ from ~frame_id";
  return "";
}

std::string scheduling_error(const NodeOptions& o, const std::vector<int>& processors) {
  for (int cpu : o.cpu_affinity)
    if (std::find(processors.begin(), processors.end(), cpu) == processors.end())
      return "~cpu_affinity: processor " + std::to_string(cpu) + " is not one this process may use";
  if (o.realtime_priority < 0 || o.realtime_priority > 99)
    return "~realtime_priority must be in [0, 99] (got " + std::to_string(o.realtime_priority) + ")";
  if (!(o.thread_slice == 0 || (o.thread_slice >= 1e-4 && o.thread_slice <= 0.1))) {
    std::ostringstream s;
    s << "~thread_slice must be 0 or in [1e-4, 0.1] s (got " << o.thread_slice << ")";
    return s.str();
  }
  return "";
}

NodeOptions read_node_options(const ros::NodeHandle& pnh, const std::string& default_scene) {
  NodeOptions o;
  pnh.param<std::string>("scene", o.scene, default_scene);
  pnh.param<std::string>("frame_id", o.frame_id, o.frame_id);
  pnh.param<std::string>("parent_frame", o.parent_frame, "");
  pnh.param("parent_transform", o.parent_transform, o.parent_transform);
  pnh.param("rate", o.rate, o.rate);
  pnh.param("publish_rate", o.publish_rate, o.publish_rate);
  // A step stops at its time budget (SolverOptions::time_budget), one frame by default, so that
  // the loop keeps its rate whatever the solver does.
  o.step_time_budget = 1.0 / o.rate;
  o.budget_follows_rate = !pnh.getParam("step_time_budget", o.step_time_budget) && !pnh.hasParam("solver/time_budget");
  pnh.param("test_fault_every", o.test_fault_every, 0);
  if (!pnh.getParam("threads", o.threads)) o.threads = -1;
  pnh.param("uncertainty_period", o.uncertainty_period, o.uncertainty_period);
  pnh.param("one_shot", o.one_shot, o.one_shot);
  // Clouds are cropped to the rest shape's box grown by the registration's reach and
  // ~cloud_margin for the liver's own motion.
  pnh.param("cloud_margin", o.cloud_margin, o.cloud_margin);
  // The default instrument `tool` and one per ~instrument_frames: rods with a hemispherical tip
  // (a sphere alone pressed deeper than its radius would let the tissue close over it).
  pnh.param("instrument_radius", o.instrument_radius, o.instrument_radius);
  pnh.param("instrument_length", o.instrument_length, o.instrument_length);
  pnh.param("instrument_frames", o.instrument_frames, std::vector<std::string>{});
  pnh.param("instrument_tf_timeout", o.instrument_tf_timeout, o.instrument_tf_timeout);
  pnh.param("pose_timeout", o.pose_timeout, o.pose_timeout);
  pnh.param("hold_stale_instruments", o.hold_stale_instruments, false);
  pnh.param("color_scale_max", o.color_scale_max, o.color_scale_max);
  pnh.param("surface_alpha", o.surface_alpha, o.surface_alpha);
  pnh.param("cpu_affinity", o.cpu_affinity, std::vector<int>{});
  pnh.param("realtime_priority", o.realtime_priority, 0);
  pnh.param("thread_slice", o.thread_slice, o.thread_slice);
  if (const std::string error = options_error(o); !error.empty()) throw std::invalid_argument(error);
  // The node steps in real-time frames by default: modified Newton on a reused factor (contacts
  // carried in the same solve) refreshed in the background, two iterations a frame, a step that
  // has not converged continuing in the next frame, a cloud's correspondence updates one a frame;
  // ~solver/strategy, ~solver/max_iterations and ~registration/frame_updates change that.
  std::ostringstream budget;
  budget.precision(17);
  budget << "solver.time_budget=" << o.step_time_budget;
  o.scene_overrides = {"solver.strategy=modified_newton", "solver.max_iterations=2", "solver.background_refresh=true",
                       budget.str(), "registration.frame_updates=1"};
  for (const char* section : {"parenchyma", "capsule", "solver", "contact", "registration"}) {
    XmlRpc::XmlRpcValue values;
    if (!pnh.getParam(section, values)) continue;
    if (values.getType() != XmlRpc::XmlRpcValue::TypeStruct)
      throw std::invalid_argument(std::string("~") + section + " must be a map of scalars");
    for (auto& kv : values) o.scene_overrides.push_back(std::string(section) + "." + kv.first + "=" + scalar_text(kv.second));
  }
  if (o.threads != -1) o.scene_overrides.push_back("solver.threads=" + std::to_string(o.threads));
  return o;
}

}  // namespace liver_sim
