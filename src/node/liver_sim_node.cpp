// liver_sim_node: hosts the liver model in an OR guidance stack. Callbacks only validate and
// store the latest input; the simulation loop (main thread) owns the model, steps it at ~rate
// when there is something to do, and publishes.
#include <diagnostic_updater/diagnostic_updater.h>
#include <boost/thread/recursive_mutex.hpp>
#include <dynamic_reconfigure/server.h>
#include <geometry_msgs/PoseArray.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl_conversions/pcl_conversions.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_geometry_msgs/tf2_geometry_msgs.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/Marker.h>
#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "liver_sim/LiverSimConfig.h"
#include "liver_sim/SetCapsule.h"
#include "liver_sim/SimulationStatus.h"
#include "liver_sim/TargetCovariances.h"
#include "liver_sim/runtime/frame_clock.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/simulation/step_guard.h"
#include "liver_sim/registration/target_uncertainty.h"
#include "liver_sim/registration/uncertainty_worker.h"
#include "liver_sim/runtime/worker_pool.h"
#include "mesh_marker.h"
#include "ros_instruments.h"

namespace liver_sim {
namespace {

// The loop's rates, checked where they are set (parameters, dynamic_reconfigure, whose clamp lets
// NaN through): empty when valid.
std::string rates_error(double rate, double publish_rate) {
  if (rate >= 1 && rate <= 1000 && publish_rate >= 0.1 && publish_rate <= 100) return "";
  return "rate must be in [1, 1000] Hz, publish_rate in [0.1, 100] Hz";
}

// The display and staleness values the node keeps itself (the model checks the rest), checked
// likewise against the bounds of cfg/LiverSim.cfg: empty when valid.
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

std::string scalar_text(const XmlRpc::XmlRpcValue& v) {
  std::ostringstream s;
  s.precision(17);
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean: s << (static_cast<bool>(const_cast<XmlRpc::XmlRpcValue&>(v)) ? "true" : "false"); break;
    case XmlRpc::XmlRpcValue::TypeInt: s << static_cast<int>(const_cast<XmlRpc::XmlRpcValue&>(v)); break;
    case XmlRpc::XmlRpcValue::TypeDouble: s << static_cast<double>(const_cast<XmlRpc::XmlRpcValue&>(v)); break;
    case XmlRpc::XmlRpcValue::TypeString: s << static_cast<std::string>(const_cast<XmlRpc::XmlRpcValue&>(v)); break;
    default: throw std::invalid_argument("only scalar parameters can override scene values");
  }
  return s.str();
}

Eigen::Isometry3d to_eigen(const geometry_msgs::Transform& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(t.translation.x, t.translation.y, t.translation.z);
  return T;
}

}  // namespace

class LiverSimNode {
 public:
  LiverSimNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) : tf_listener_(tf_buffer_), updater_(nh, pnh) {
    std::string scene_path;
    pnh.param<std::string>("scene", scene_path, LIVER_SIM_DEFAULT_SCENE);
    pnh.param<std::string>("frame_id", frame_id_, "liver");
    pnh.param("rate", rate_, 30.0);
    pnh.param("publish_rate", publish_rate_, 15.0);
    pnh.param("color_scale_max", color_scale_max_, 0.005);
    pnh.param("surface_alpha", surface_alpha_, 1.0);
    if (const std::string error = rates_error(rate_, publish_rate_); !error.empty()) throw std::invalid_argument("~" + error);
    // A step stops at its time budget (SolverOptions::time_budget), one frame by default, so that
    // the loop keeps its rate whatever the solver does.
    double step_time_budget = 1.0 / rate_;
    budget_follows_rate_ = !pnh.getParam("step_time_budget", step_time_budget) && !pnh.hasParam("solver/time_budget");
    if (!(step_time_budget > 0)) throw std::invalid_argument("~step_time_budget must be > 0 s");
    int test_fault_every = 0;
    pnh.param("test_fault_every", test_fault_every, 0);
    if (test_fault_every < 0) throw std::invalid_argument("~test_fault_every must be >= 0");
    guard_.set_test_fault_every(test_fault_every);
    // ~parenchyma/*, ~capsule/*, ~solver/*, ~contact/*, ~registration/* override the scalars of the
    // scene file; ~threads is solver.threads. The node steps in real-time frames by default: modified Newton on a reused
    // factor (contacts carried in the same solve), two iterations a frame, a step that has not
    // converged continuing in the next frame, a cloud's correspondence updates one a frame;
    // ~solver/strategy, ~solver/max_iterations and ~registration/frame_updates change that.
    std::ostringstream budget;
    budget.precision(17);
    budget << "solver.time_budget=" << step_time_budget;
    std::vector<std::string> overrides = {"solver.strategy=modified_newton", "solver.max_iterations=2", budget.str(),
                                          "registration.frame_updates=1"};
    for (const char* section : {"parenchyma", "capsule", "solver", "contact", "registration"}) {
      XmlRpc::XmlRpcValue values;
      if (!pnh.getParam(section, values)) continue;
      if (values.getType() != XmlRpc::XmlRpcValue::TypeStruct)
        throw std::invalid_argument(std::string("~") + section + " must be a map of scalars");
      for (auto& kv : values) overrides.push_back(std::string(section) + "." + kv.first + "=" + scalar_text(kv.second));
    }
    int threads = 0;
    if (pnh.getParam("threads", threads)) {
      if (threads < 1 || threads > WorkerPool::kMaxThreads)
        throw std::invalid_argument("~threads must be in [1, " + std::to_string(WorkerPool::kMaxThreads) + "] (got " +
                                    std::to_string(threads) + ")");
      overrides.push_back("solver.threads=" + std::to_string(threads));
    }
    const Scene scene = load_scene(scene_path, overrides);
    try {
      model_ = std::make_unique<LiverModel>(load_scene_mesh(scene), scene);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(scene_path + ": " + e.what());
    }
    capsule_ = scene.capsule;
    registration_ = std::make_unique<SurfaceRegistration>(*model_, scene.registration);
    Scene analysis_scene = scene;
    analysis_scene.solver.threads = 1;  // see UncertaintyWorker
    analysis_ = std::make_unique<UncertaintyWorker>(
        std::make_unique<LiverModel>(load_scene_mesh(analysis_scene), analysis_scene), scene.registration.uncertainty);
    pnh.param("uncertainty_period", uncertainty_period_, 1.0);
    if (!(uncertainty_period_ >= 0)) throw std::invalid_argument("~uncertainty_period must be >= 0");
    // Clouds are cropped in the callback to the rest shape's box grown by the registration's
    // reach and ~cloud_margin for the liver's own motion.
    pnh.param("cloud_margin", cloud_margin_, 0.05);
    if (!(cloud_margin_ >= 0)) throw std::invalid_argument("~cloud_margin must be >= 0");
    for (int i = 0; i < model_->positions().size(); i += 3) cloud_box_.extend(model_->positions().segment<3>(i));
    cloud_box_.min().array() -= scene.registration.max_distance + cloud_margin_;
    cloud_box_.max().array() += scene.registration.max_distance + cloud_margin_;
    const std::string too_fine = voxel_grid_error(scene.registration.voxel_size, cloud_box_);
    if (!too_fine.empty()) throw std::invalid_argument("registration.voxel_size with ~cloud_margin: " + too_fine);
    // The default instrument `tool` and one per ~instrument_frames: rods with a hemispherical tip
    // (a sphere alone pressed deeper than its radius would let the tissue close over it).
    RosInstruments::Settings instruments;
    instruments.frame_id = frame_id_;
    instruments.tool.type = InstrumentOptions::Type::Shaft;
    pnh.param("instrument_radius", instruments.tool.radius, 0.003);
    pnh.param("instrument_length", instruments.tool.length, 0.1);
    pnh.param("instrument_frames", instruments.frames, std::vector<std::string>{});
    pnh.param("instrument_tf_timeout", instruments.tf_timeout, 0.1);
    pnh.param("pose_timeout", instruments.pose_timeout, 1.0);
    pnh.param("hold_stale_instruments", instruments.hold_stale, false);
    if (const std::string error = view_error(color_scale_max_, surface_alpha_, instruments.pose_timeout); !error.empty())
      throw std::invalid_argument("~" + error);
    instruments_ = std::make_unique<RosInstruments>(nh, pnh, tf_buffer_, *model_, instruments,
                                                    [this](const std::string& why) { reject(why); },
                                                    [this](const std::string& what) { warn(what); });
    ROS_INFO("liver_sim: %s: %ld nodes, %ld tetrahedra, %d capsule triangles, %d vessel beams, %s mode",
             scene_path.c_str(), static_cast<long>(model_->mesh().V.rows()), static_cast<long>(model_->mesh().T.rows()),
             model_->capsule_triangles(), model_->num_beams(),
             scene.solver.mode == SolverOptions::Mode::Static ? "static" : "dynamic");

    place_in_tf_tree(pnh);
    mesh_pub_ = pnh.advertise<visualization_msgs::Marker>("mesh", 1, true);
    vessel_pub_ = pnh.advertise<visualization_msgs::Marker>("vessels", 1, true);
    status_pub_ = pnh.advertise<SimulationStatus>("status", 10);
    target_marker_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("targets", 1, true);
    target_pose_pub_ = pnh.advertise<geometry_msgs::PoseArray>("target_poses", 1, true);
    covariance_pub_ = pnh.advertise<TargetCovariances>("target_covariances", 1, true);
    ellipsoid_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("target_ellipsoids", 1, true);
    cloud_sub_ = nh.subscribe("points", 1, &LiverSimNode::on_cloud, this);
    reset_srv_ = pnh.advertiseService("reset", &LiverSimNode::on_reset, this);
    capsule_srv_ = pnh.advertiseService("set_capsule", &LiverSimNode::on_set_capsule, this);
    align_srv_ = pnh.advertiseService("align_rigidly", &LiverSimNode::on_align_rigidly, this);
    updater_.setHardwareID("liver_sim");
    updater_.add("liver model", this, &LiverSimNode::diagnose);
    // Live tuning: the server starts from the node's values, within the config's bounds (a value
    // outside them is clamped now, and said, not at the first unrelated change).
    pose_timeout_ = instruments.pose_timeout;
    hold_stale_ = instruments.hold_stale;
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<LiverSimConfig>>(reconfigure_mutex_, pnh);
    const LiverSimConfig config = current_config();
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
    if (changed.tellp() > 0) warn("clamped to the live-tuning bounds (cfg/LiverSim.cfg): " + changed.str());
    reconfigure_->updateConfig(clamped);
    reconfigure_->setCallback([this](LiverSimConfig& c, uint32_t) {
      std::lock_guard<std::mutex> lock(mutex_);
      pending_config_ = c;
    });
  }

  ~LiverSimNode() {
    stop_heartbeat_ = true;
    if (heartbeat_.joinable()) heartbeat_.join();
  }

  // The heartbeat's thread of its own, which neither message callbacks nor roscpp's timer
  // thread can delay. Called from the thread that starts the callbacks' spinner (its processors
  // and priority).
  void start_heartbeat() {
    heartbeat_ = std::thread([this] {
      while (!stop_heartbeat_ && ros::ok()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
        heartbeat();
      }
    });
  }

  // ~parent_frame and ~parent_transform put the model frame in the OR's tf tree (a static
  // transform, parent to model frame), so that rviz and the OR's tools agree on where it is.
  void place_in_tf_tree(ros::NodeHandle& pnh) {
    std::string parent;
    std::vector<double> t{0, 0, 0, 0, 0, 0, 1};
    pnh.param<std::string>("parent_frame", parent, "");
    pnh.param("parent_transform", t, t);
    if (parent.empty()) return;
    if (t.size() != 7 || !std::all_of(t.begin(), t.end(), [](double v) { return std::isfinite(v); }) ||
        !(std::abs(Eigen::Vector4d(t[3], t[4], t[5], t[6]).norm() - 1) < 1e-3))
      throw std::invalid_argument("~parent_transform must be [x, y, z, qx, qy, qz, qw] (m; a unit quaternion)");
    if (parent == frame_id_) throw std::invalid_argument("~parent_frame must differ from ~frame_id");
    geometry_msgs::TransformStamped s;
    s.header.stamp = ros::Time::now();
    s.header.frame_id = parent;
    s.child_frame_id = frame_id_;
    s.transform.translation.x = t[0];
    s.transform.translation.y = t[1];
    s.transform.translation.z = t[2];
    s.transform.rotation.x = t[3];
    s.transform.rotation.y = t[4];
    s.transform.rotation.z = t[5];
    s.transform.rotation.w = t[6];
    static_broadcaster_.sendTransform(s);
  }

  void run() {
    FrameClock loop(1.0 / rate_, FrameClock::kCatchUp);
    ros::WallTime next_publish = ros::WallTime::now();
    bool must_step = true;  // the first step brings the scene's loads to equilibrium
    while (ros::ok()) {
      // The last line of the barrier: a fault the frame's own guards did not catch (publishing,
      // diagnostics) is counted, and the loop goes on.
      {
        std::lock_guard<std::mutex> lock(status_mutex_);
        frame_start_ = ros::WallTime::now();
      }
      try {
        must_step |= guarded_inputs(loop);
        must_step = simulate_frame(must_step);
        const ros::WallTime now = ros::WallTime::now();
        if (now >= next_publish) {
          const ros::WallDuration publish_period(1.0 / publish_rate_);
          publish_mesh();
          if (!must_step) publish_status(last_);
          next_publish += publish_period;
          if (next_publish < now) next_publish = now + publish_period;  // fell behind: no burst
        }
        updater_.update();
      } catch (const std::exception& e) {
        fault(std::string("in the loop: ") + e.what());
      } catch (...) {
        fault("in the loop: exception of unknown type");
      }
      {
        std::lock_guard<std::mutex> lock(status_mutex_);
        frame_start_ = ros::WallTime();
      }
      loop.sleep();
    }
  }

 private:
  // apply_inputs behind the barrier: a value beyond its bounds (std::invalid_argument) is a
  // refused input, anything else a fault; the model stays as it was.
  bool guarded_inputs(FrameClock& loop) {
    try {
      return apply_inputs(loop);
    } catch (const std::invalid_argument& e) {
      reject(e.what());
    } catch (const std::exception& e) {
      fault(std::string("applying the inputs: ") + e.what());
    } catch (...) {
      fault("applying the inputs: exception of unknown type");
    }
    return true;
  }

  void fault(const std::string& text) {  // simulation thread
    guard_.count(text);
    state_ = "fault";
    ROS_ERROR_THROTTLE(1.0, "liver_sim: fault %s; the model keeps its last good state", text.c_str());
  }

  // One frame's simulation: the registration's last analysis adopted, the latest cloud
  // registered, a step, all behind the barrier (step_guard.h); then the next analysis started.
  // Returns whether the next frame must step.
  bool simulate_frame(bool must_step) {
    bool stepped = false;
    int factorized = 0;  // in this frame's steps (a cloud's: up to three updates, each tried twice)
    const StepResult r = guard_.step(*model_, [&] {
      const bool estimates_changed = adopt_analysis();
      std::optional<RegistrationFrame> registered = register_pending_cloud();
      if (registered) registering_ = analysis_due_ = true;
      stepped = registered || must_step || estimates_changed;
      // While clouds come, the model converges on the last one in the registration's short
      // steps, so that the next cloud waits for one iteration, not a full solve.
      if (registered) {
        factorized = registered->factorizations;
        return warn_on_reverted_loads(*registered).step;
      }
      if (!stepped) return StepResult();
      if (registering_) {
        registered_ = registration_->refine();  // a later update of the cloud may have moved the fit
        factorized = registered_.factorizations;
        return warn_on_reverted_loads(registered_).step;
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
      step_times_.push_back(ros::WallTime::now());
      last_ = r;
      state_ = "fault";
      ROS_ERROR_THROTTLE(1.0, "liver_sim: %s; the model keeps its last good state", r.message.c_str());
      publish_status(r);
      return true;
    }
    if (!stepped) {
      if (state_ != "diverged" && state_ != "fault") state_ = "idle";
      start_analysis();  // one due while the last ran
      return false;
    }
    if (r.status != StepResult::Status::NotConverged && !registration_->updates_pending()) registering_ = false;
    if (r.status != StepResult::Status::Diverged) start_analysis();
    ++steps_;
    factorizations_ += factorized;
    step_times_.push_back(ros::WallTime::now());
    last_ = r;
    state_ = r.status == StepResult::Status::Diverged ? "diverged"
             : r.converged()                            ? "converged"
                                                        : "iterating";
    if (r.status == StepResult::Status::Diverged)
      ROS_WARN_THROTTLE(1.0, "liver_sim: step diverged (%s); kept the last good state", r.message.c_str());
    publish_status(r);
    // Continue next frame while iterating; a diverged step waits for new input.
    return r.status == StepResult::Status::NotConverged || (r.converged() && r.iterations > 0) ||
           (registering_ && registration_->updates_pending());
  }

  // Moves pending inputs into the model; true when something changed. The node's lock is not
  // held while the instruments apply theirs (they report refusals through reject()).
  bool apply_inputs(FrameClock& loop) {
    bool reset = false;
    std::optional<CapsuleOptions> capsule;
    CapsuleOptions capsule_before;
    std::optional<LiverSimConfig> config;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      std::swap(reset, reset_requested_);
      capsule.swap(pending_capsule_);
      capsule_before = capsule_;
      if (capsule) capsule_ = *capsule;  // taken up now: a set_capsule call meanwhile builds on it
      config.swap(pending_config_);
    }
    bool changed = reset || capsule.has_value();
    if (reset) {
      model_->reset();  // also removes the registration's springs
      registration_->clear();
      reference_.resize(0);
      instruments_->release_all(*model_);
      registering_ = false;
      clouds_registered_ = 0;
      registered_ = RegistrationFrame();
      covariances_.clear();
      analysis_due_ = false;
      ++analysis_generation_;  // an analysis still running describes the state before
      steps_ = factorizations_ = 0;
      reflected_stamp_ = ros::Time();
    }
    if (capsule) {
      const std::string error = model_->set_capsule(*capsule);  // validated already
      if (error.empty()) {
        analysis_->set_capsule(*capsule);
        ++analysis_generation_;  // one running has the old capsule
        analysis_due_ |= clouds_registered_ > 0;
      } else {
        ROS_ERROR("liver_sim: capsule change failed: %s", error.c_str());
        std::lock_guard<std::mutex> lock(mutex_);
        capsule_ = capsule_before;
      }
    }
    if (config) changed |= reconfigure(*config, loop);
    if (instruments_->apply(*model_)) {
      if (!instruments_->reflected_stamp().isZero()) reflected_stamp_ = instruments_->reflected_stamp();
      changed = true;
    }
    return changed;
  }

  // The values in force, as dynamic_reconfigure shows them.
  LiverSimConfig current_config() const {
    LiverSimConfig config;
    config.strategy = strategy_word(model_->solver_options().strategy);
    config.max_iterations = model_->solver_options().max_iterations;
    config.tolerance = model_->solver_options().tolerance;
    config.rate = rate_;
    config.publish_rate = publish_rate_;
    config.friction = model_->contact().options().friction;
    config.registration_stiffness = registration_->options().stiffness;
    config.color_scale_max = color_scale_max_;
    config.surface_alpha = surface_alpha_;
    config.pose_timeout = pose_timeout_;
    config.hold_stale_instruments = hold_stale_;
    return config;
  }

  // A dynamic_reconfigure change (bounded by the config's limits): all of it, or nothing when the
  // model refuses a part (the server then shows the values in force). True when the model changed.
  bool reconfigure(const LiverSimConfig& c, FrameClock& loop) {
    const std::optional<SolverOptions::Strategy> strategy = parse_strategy(c.strategy);
    std::string error = rates_error(c.rate, c.publish_rate);
    if (error.empty()) error = view_error(c.color_scale_max, c.surface_alpha, c.pose_timeout);
    if (error.empty() && !strategy) error = "unknown strategy '" + c.strategy + "'";
    if (!error.empty()) {
      reject("reconfigure: " + error);
      reconfigure_->updateConfig(current_config());
      return false;
    }
    const SolverOptions solver_before = model_->solver_options();
    const ContactOptions contact_before = model_->contact().options();
    const double stiffness_before = registration_->options().stiffness;
    SolverOptions solver = solver_before;
    solver.strategy = *strategy;
    solver.max_iterations = c.max_iterations;
    solver.tolerance = c.tolerance;
    if (budget_follows_rate_) solver.time_budget = 1.0 / c.rate;
    ContactOptions contact = contact_before;
    contact.friction = c.friction;
    error = model_->set_solver_options(solver);
    if (error.empty()) error = model_->set_contact_options(contact);
    if (error.empty()) error = registration_->set_stiffness(c.registration_stiffness);
    if (!error.empty()) {
      model_->set_solver_options(solver_before);
      model_->set_contact_options(contact_before);
      registration_->set_stiffness(stiffness_before);
      reject("reconfigure: " + error);
      reconfigure_->updateConfig(current_config());
      return false;
    }
    const bool model_changed = solver.strategy != solver_before.strategy ||
                               solver.max_iterations != solver_before.max_iterations ||
                               solver.tolerance != solver_before.tolerance || contact.friction != contact_before.friction;
    loop.set_period(1.0 / c.rate);
    rate_ = c.rate;
    publish_rate_ = c.publish_rate;
    display_due_ |= color_scale_max_ != c.color_scale_max || surface_alpha_ != c.surface_alpha;
    color_scale_max_ = c.color_scale_max;
    surface_alpha_ = c.surface_alpha;
    pose_timeout_ = c.pose_timeout;
    hold_stale_ = c.hold_stale_instruments;
    instruments_->set_staleness(pose_timeout_, hold_stale_);
    ROS_INFO("liver_sim: reconfigured: %s, %d iterations a frame, tolerance %g, %g Hz, friction %g",
             c.strategy.c_str(), c.max_iterations, c.tolerance, c.rate, c.friction);
    return model_changed;
  }

  void reject(const std::string& why) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++rejected_;
    last_rejection_ = fresh_text_ = why;
    ROS_WARN_THROTTLE(1.0, "liver_sim: refused input: %s", why.c_str());
  }

  // An event the next status tells (not a refused input).
  void warn(const std::string& what) {
    std::lock_guard<std::mutex> lock(mutex_);
    fresh_text_ = what;
    ROS_WARN("liver_sim: %s", what.c_str());
  }

  // Why a cloud cannot be converted, or "" (PCL's conversion indexes an empty cloud and trusts
  // the layout fields, so they are checked first).
  static std::string cloud_layout_error(const sensor_msgs::PointCloud2& c) {
    if (static_cast<uint64_t>(c.width) * c.height == 0) return "empty cloud";
    const std::string too_large = cloud_size_error(static_cast<uint64_t>(c.width) * c.height);
    if (!too_large.empty()) return too_large;
    if (static_cast<uint64_t>(c.point_step) * c.width > c.row_step ||
        static_cast<uint64_t>(c.row_step) * c.height > c.data.size())
      return "data shorter than width, height and steps say";
    unsigned axes = 0;  // a bit for each of x, y, z met
    for (const auto& f : c.fields) {
      const int axis = f.name == "x" ? 0 : f.name == "y" ? 1 : f.name == "z" ? 2 : -1;
      if (axis < 0) continue;
      if (axes & (1u << axis)) return "field " + f.name + " given twice";
      // 64 bits: an offset near 2^32 would wrap past the check and PCL would read outside the data.
      // A count of 0 is PCL's legacy spelling of 1.
      if (f.datatype != sensor_msgs::PointField::FLOAT32 || f.count > 1 ||
          static_cast<uint64_t>(f.offset) + 4 > c.point_step)
        return "field " + f.name + " is not one float32 within point_step";
      axes |= 1u << axis;
    }
    return axes == 7 ? "" : "no float32 x, y, z fields";
  }

  // Clouds are validated, moved into the model frame (tf2, at their stamp), cropped and
  // downsampled here, off the simulation thread (a 1M cloud becomes a few thousand points); the
  // loop registers the latest one (and crops it again, cheaply, to the model's current shape).
  void on_cloud(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    const ros::WallTime t0 = ros::WallTime::now();
    const std::string layout = cloud_layout_error(*msg);
    if (!layout.empty()) return reject("points: " + layout);
    Eigen::Isometry3d to_model = Eigen::Isometry3d::Identity();
    if (!msg->header.frame_id.empty() && msg->header.frame_id != frame_id_) {
      try {
        to_model = to_eigen(
            tf_buffer_.lookupTransform(frame_id_, msg->header.frame_id, msg->header.stamp, ros::Duration(0.1)).transform);
      } catch (const tf2::TransformException& e) {
        return reject("points in frame '" + msg->header.frame_id + "': " + e.what());
      }
      if (!to_model.matrix().allFinite())
        return reject("points: non-finite transform from frame '" + msg->header.frame_id + "'");
    }
    // Conversion and preparation behind one barrier: a malformed message, memory a huge cloud
    // does not find (the voxel grid fits the crop box: checked at start).
    pcl::PointCloud<pcl::PointXYZ> cloud;
    PendingCloud pending;
    const RegistrationOptions& o = registration_->options();
    int finite_points = 0;
    try {
      pcl::fromROSMsg(*msg, cloud);
      finite_points = prepare_cloud(cloud, to_model, cloud_box_, o.voxel_size, o.max_points, pending.points);
    } catch (const std::exception& e) {
      return reject(std::string("points: ") + e.what());
    }
    // A cloud in a sensor's frame is seen from that frame's origin; one already in the model
    // frame says nothing about where the sensor is.
    if (!msg->header.frame_id.empty() && msg->header.frame_id != frame_id_) pending.viewpoint = to_model.translation();
    pending.stamp = msg->header.stamp;
    const double filter_s = (ros::WallTime::now() - t0).toSec();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      last_cloud_filter_s_ = filter_s;
      last_cloud_points_ = cloud.size();
    }
    if (finite_points == 0) return reject("points: no finite point");
    if (pending.points.empty()) return reject("points: no point near the model");
    std::lock_guard<std::mutex> lock(mutex_);
    pending_cloud_ = std::move(pending);  // replaced, never queued: the latest cloud wins
    ++clouds_;
  }

  const RegistrationFrame& warn_on_reverted_loads(const RegistrationFrame& f) {
    if (f.hidden_loads_reverted)
      ROS_WARN_THROTTLE(5.0, "liver_sim: a registration step diverged while new hidden loads acted; the loads before them act again");
    return f;
  }

  // Registers the latest cloud, if one came since the last call. (simulation thread)
  std::optional<RegistrationFrame> register_pending_cloud() {
    std::optional<PendingCloud> cloud;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      cloud.swap(pending_cloud_);
      if (cloud && align_requested_) {
        registration_->request_rigid_alignment();
        align_requested_ = false;
      }
    }
    if (!cloud) return std::nullopt;
    try {
      const RegistrationFrame f = registration_->register_cloud(cloud->points, cloud->viewpoint);
      if (f.step.status != StepResult::Status::Diverged) {  // rolled back: the state is the last one
        ++clouds_registered_;
        registered_ = f;
        reflected_stamp_ = cloud->stamp;
      }
      return f;
    } catch (const std::invalid_argument& e) {
      reject(std::string("points: ") + e.what());
      return std::nullopt;
    }
  }

  // At most once per ~uncertainty_period, after a cloud was registered: the targets'
  // covariances and the candidate supports the clouds call for, from one factorisation of the
  // registered model's stiffness, on the analysis's own thread (uncertainty_worker.h) while the
  // frames go on. One runs at a time; a cloud registered meanwhile is analysed after it.
  // (simulation thread, after a step that kept its state)
  void start_analysis() {
    const ros::WallTime now = ros::WallTime::now();
    if (!analysis_due_ || now < next_analysis_) return;
    try {
      if (!analysis_->start(*model_, registration_->cloud_springs(), analysis_generation_, registration_.get())) return;
    } catch (const std::exception& e) {  // out of memory copying the state, a capsule refused
      ROS_WARN_THROTTLE(5.0, "liver_sim: no target uncertainty: %s", e.what());
      return;
    }
    analysis_due_ = false;
    next_analysis_ = now + ros::WallDuration(uncertainty_period_);
    analysis_started_at_ = ros::Time::now();
  }

  // A finished analysis, if one is: its covariances shown, the registration's estimates
  // (candidate supports, the tissue's stiffness) solved on its factor with the springs it was
  // made with, and the step of the hidden loads' fit the analysis made. (simulation thread)
  // Returns whether the estimates changed the model (a support held, the tissue's stiffness, the
  // hidden loads): then it must step, clouds or not.
  bool adopt_analysis() {
    std::optional<UncertaintyWorker::Result> result = analysis_->take();
    if (!result || result->tag != analysis_generation_) return false;
    analysis_cpu_time_ = result->cpu_time;
    if (!result->error.empty()) {
      ROS_WARN_THROTTLE(5.0, "liver_sim: no target uncertainty: %s", result->error.c_str());
      return false;
    }
    covariances_.clear();
    for (const TargetUncertainty::Covariance& c : result->covariances) covariances_.push_back(c.total);
    display_due_ = true;
    analysis_stamp_ = analysis_started_at_;
    try {
      const int held = registration_->estimate_supports(analysis_->compliance(), result->cloud_springs);
      if (held >= 0) ROS_INFO("liver_sim: the clouds call for candidate support %d: held from the next step", held);
      const double stiffness = model_->stiffness_scale();
      const std::vector<Eigen::Vector3d> loads = registration_->hidden_loads();
      registration_->estimate_tissue_stiffness(analysis_->compliance(), result->cloud_springs);  // both registration.*_tissue_stiffness_factor 1: off
      registration_->apply_hidden_loads(result->hidden_loads);  // fitted on the worker's thread; empty when off
      return held >= 0 || model_->stiffness_scale() != stiffness || registration_->hidden_loads() != loads;
    } catch (const std::runtime_error& e) {
      ROS_WARN_THROTTLE(5.0, "liver_sim: no support, stiffness or hidden loads estimate: %s", e.what());
    }
    return false;
  }

  bool on_reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    reset_requested_ = true;
    align_requested_ = false;
    pending_cloud_.reset();
    res.success = true;
    res.message = "back to the rest shape at the next step; instruments released until their next pose";
    return true;
  }

  bool on_align_rigidly(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    align_requested_ = true;
    res.success = true;
    res.message = "the next cloud is rigidly aligned (ICP) before it is registered";
    return true;
  }

  bool on_set_capsule(SetCapsule::Request& req, SetCapsule::Response& res) {
    std::unique_lock<std::mutex> lock(mutex_);
    CapsuleOptions c = pending_capsule_ ? *pending_capsule_ : capsule_;
    c.enabled = req.enabled;
    if (req.young_modulus != 0) c.young_modulus = req.young_modulus;
    if (req.thickness != 0) c.thickness = req.thickness;
    if (req.poisson_ratio != 0) c.poisson_ratio = req.poisson_ratio;
    res.message = validate(c);
    res.success = res.message.empty();
    if (res.success) {
      pending_capsule_ = c;
      res.message = "applied at the next step";
    } else {
      c = pending_capsule_ ? *pending_capsule_ : capsule_;
    }
    res.enabled = c.enabled;
    res.young_modulus = c.young_modulus;
    res.thickness = c.thickness;
    res.poisson_ratio = c.poisson_ratio;
    lock.unlock();
    if (!res.success) reject("set_capsule: " + res.message);
    return true;
  }

  void publish_status(const StepResult& r) {
    SimulationStatus s;
    s.header.frame_id = frame_id_;
    s.step = steps_;
    const ros::WallTime now = ros::WallTime::now();
    while (!step_times_.empty() && step_times_.front() < now - ros::WallDuration(1.0)) step_times_.pop_front();
    s.rate = static_cast<double>(step_times_.size());  // steps in the last second
    s.step_time = r.timing.total_ms / 1000.0;
    s.iterations = r.iterations;
    s.residual = r.residual;
    s.max_displacement = model_->max_displacement();
    s.active_contacts = r.contacts;
    s.state = state_;
    s.registration_rms = registered_.rms;
    s.correspondences = registered_.correspondences;
    s.clouds_registered = clouds_registered_;
    s.registration_coverage = registered_.coverage;
    s.registration_inlier_fraction = registered_.inlier_fraction;
    s.registration_rms_all = registered_.rms_all;
    s.target_radius_95 = largest_radius_95();
    s.faults = guard_.faults();
    for (bool held : registration_->supports_held()) s.supports_held += held;
    instruments_->fill_status(*model_, s);
    const Eigen::Isometry3d& a = registration_->alignment();
    s.rigid_alignment_active = a.matrix() != Eigen::Matrix4d::Identity();
    const Eigen::Quaterniond q(a.linear());
    s.rigid_alignment.translation.x = a.translation().x();
    s.rigid_alignment.translation.y = a.translation().y();
    s.rigid_alignment.translation.z = a.translation().z();
    s.rigid_alignment.rotation.x = q.x();
    s.rigid_alignment.rotation.y = q.y();
    s.rigid_alignment.rotation.z = q.z();
    s.rigid_alignment.rotation.w = q.w();
    {
      // A refusal or an event is told in the next status only: later ones say how the model is.
      std::lock_guard<std::mutex> lock(mutex_);
      s.rejected_inputs = rejected_;
      s.text = r.message.empty() ? fresh_text_ : fresh_text_.empty() ? r.message : r.message + "; " + fresh_text_;
      fresh_text_.clear();
    }
    {
      // Stamped and published under the heartbeat's lock: it never sends an older step after a
      // newer one, nor an earlier stamp after a later one.
      std::lock_guard<std::mutex> lock(status_mutex_);
      s.header.stamp = ros::Time::now();
      // When it was stamped, not when the publish returned: the heartbeat keeps the stamps (and
      // so the arrivals) within a frame of each other, however long sending took.
      last_status_time_ = ros::WallTime::now();
      status_pub_.publish(s);
      last_status_ = s;
      frame_period_ = 1.0 / rate_;
    }
    instruments_->publish(*model_, s.header);
  }

  // While a long frame runs (a factorisation, a part of the analysis) and no status went out for
  // one frame, ~status keeps the loop's rate: the last step's status again, state "busy", every
  // frame, so that a guidance stack watching it sees a live node whose mesh is its last good
  // state. (heartbeat thread)
  void heartbeat() {
    std::lock_guard<std::mutex> lock(status_mutex_);
    const ros::WallTime now = ros::WallTime::now();
    const ros::WallDuration period(frame_period_);
    // One frame since the last status, counted from that status: from the frame's start, a frame
    // that starts after the loop slept out its slot leaves up to two frames without one. The
    // frame must have run a quarter of a frame, so that a short frame (one that only takes
    // inputs, its status due at ~publish_rate) is not called busy; a longer wait would hold the
    // status back for it after a frame that started late in its slot.
    if (frame_start_.isZero() || last_status_time_.isZero() || now - last_status_time_ < period ||
        now - frame_start_ < period * 0.25)
      return;
    SimulationStatus s = last_status_;
    s.header.stamp = ros::Time::now();
    s.state = "busy";
    std::ostringstream text;
    text << "a frame in progress for " << static_cast<int>((now - frame_start_).toSec() * 1000)
         << " ms; the mesh is the last step's";
    s.text = text.str();
    status_pub_.publish(s);
    last_status_time_ = now;
  }

  // The surface, targets and vessels, when the shape, the display settings or the targets'
  // uncertainty changed since they were last sent (latched: a late subscriber has them).
  void publish_mesh() {
    // Displacements from the pre-operative equilibrium: the first converged state after start or
    // reset; taking it recolours the mesh.
    if (reference_.size() == 0 && last_.converged()) {
      reference_ = model_->positions();
      display_due_ = true;
    }
    if (!display_due_ && published_positions_.size() == model_->positions().size() &&
        published_positions_ == model_->positions())
      return;
    published_positions_ = model_->positions();
    display_due_ = false;
    marker_.header.frame_id = frame_id_;
    // The stamp of the instrument pose the shape reflects, so that latency can be measured.
    marker_.header.stamp = reflected_stamp_.isZero() ? ros::Time::now() : reflected_stamp_;
    marker_.ns = "liver";
    marker_.id = 0;
    fill_mesh_marker(*model_, reference_.size() ? reference_ : model_->positions(), color_scale_max_, surface_alpha_,
                     marker_);
    mesh_pub_.publish(marker_);
    publish_targets(marker_.header);
    if (model_->num_beams() > 0) {
      vessel_marker_.header = marker_.header;
      vessel_marker_.ns = "vessels";
      fill_vessel_marker(*model_, vessel_marker_);
      vessel_pub_.publish(vessel_marker_);
    }
  }

  // The tumour probes and vessel bifurcations where the model has them now: spheres (tumour
  // red, bifurcations blue; namespace "probes" or "bifurcations", id = the target's index, as in
  // the poses) and their poses (orientation: identity); their names in markers of their own
  // (rviz flags text on a sphere) and the colour legend.
  void publish_targets(const std_msgs::Header& header) {
    const std::vector<TrackedTarget> targets = tracked_targets(*model_);
    visualization_msgs::MarkerArray markers;
    geometry_msgs::PoseArray poses;
    poses.header = header;
    for (size_t i = 0; i < targets.size(); ++i) {
      visualization_msgs::Marker m;
      m.header = header;
      const bool vessel = targets[i].kind == TrackedTarget::Kind::Bifurcation;
      m.ns = vessel ? "bifurcations" : "probes";
      m.id = static_cast<int>(i);
      m.type = visualization_msgs::Marker::SPHERE;
      m.action = visualization_msgs::Marker::ADD;
      m.pose.position.x = targets[i].position.x();
      m.pose.position.y = targets[i].position.y();
      m.pose.position.z = targets[i].position.z();
      m.pose.orientation.w = 1;
      m.scale.x = m.scale.y = m.scale.z = vessel ? 0.004 : 0.003;
      m.color.r = vessel ? 0.2f : 1.0f;
      m.color.g = 0.2f;
      m.color.b = vessel ? 1.0f : 0.2f;
      m.color.a = 1.0f;
      markers.markers.push_back(m);
      poses.poses.push_back(m.pose);
    }
    append_target_names(targets, header, markers);
    const Eigen::MatrixX3d& rest = model_->mesh().V;
    append_colour_legend(Eigen::AlignedBox3d(rest.colwise().minCoeff().transpose(), rest.colwise().maxCoeff().transpose()),
                         color_scale_max_, header, markers);
    target_marker_pub_.publish(markers);
    target_pose_pub_.publish(poses);
    if (covariances_.size() != targets.size()) return;  // no analysis since the last reset
    TargetCovariances covariance;
    covariance.header = header;
    covariance.analysis_stamp = analysis_stamp_;
    visualization_msgs::MarkerArray ellipsoids;
    for (size_t i = 0; i < targets.size(); ++i) {
      covariance.names.push_back(targets[i].name);
      geometry_msgs::PoseWithCovariance p;
      p.pose = poses.poses[i];
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) p.covariance[6 * a + b] = covariances_[i](a, b);
        p.covariance[6 * (a + 3) + a + 3] = 1e6;  // the rotations are unknown
      }
      covariance.poses.push_back(p);
      // The 95% ellipsoid: a sphere scaled along the covariance's eigenvectors.
      const Ellipsoid e = ellipsoid_95(covariances_[i]);
      const Eigen::Quaterniond q(e.axes);
      visualization_msgs::Marker m = markers.markers[i];
      m.ns = markers.markers[i].ns + "_95";
      m.pose.orientation.x = q.x();
      m.pose.orientation.y = q.y();
      m.pose.orientation.z = q.z();
      m.pose.orientation.w = q.w();
      m.scale.x = std::max(2 * e.semi_axes.x(), 1e-4);  // rviz draws no zero-size marker
      m.scale.y = std::max(2 * e.semi_axes.y(), 1e-4);
      m.scale.z = std::max(2 * e.semi_axes.z(), 1e-4);
      m.color.a = 0.3f;
      ellipsoids.markers.push_back(m);
    }
    covariance_pub_.publish(covariance);
    ellipsoid_pub_.publish(ellipsoids);
  }

  // The largest semi-axis of the targets' 95% ellipsoids (m), 0 before the first analysis.
  double largest_radius_95() const {
    double largest = 0;
    for (const Eigen::Matrix3d& c : covariances_) largest = std::max(largest, ellipsoid_95(c).semi_axes.z());
    return largest;
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    using diagnostic_msgs::DiagnosticStatus;
    const unsigned char level = state_ == "diverged" || state_ == "fault" ? DiagnosticStatus::ERROR
                                : state_ == "iterating" ? DiagnosticStatus::WARN
                                                        : DiagnosticStatus::OK;
    stat.summary(level, state_);
    stat.add("steps", steps_);
    stat.add("factorisations in the steps", factorizations_);  // the frames' largest cost (33-38 ms each on the phantom)
    stat.add("last step time (s)", last_.timing.total_ms / 1000.0);
    stat.add("residual", last_.residual);
    stat.add("active contacts", last_.contacts);
    stat.add("faults", guard_.faults());
    stat.add("last fault", guard_.last_fault());
    std::lock_guard<std::mutex> lock(mutex_);
    stat.add("rejected inputs", rejected_);
    stat.add("point clouds received", clouds_);
    stat.add("point clouds registered", clouds_registered_);
    stat.add("registration RMS (m)", registered_.rms);
    stat.add("registration coverage", registered_.coverage);
    stat.add("registration inlier fraction", registered_.inlier_fraction);
    stat.add("registration RMS of all points (m)", registered_.rms_all);
    stat.add("target 95% radius, largest (m)", largest_radius_95());
    stat.add("last analysis processor time (s)", analysis_cpu_time_);
    stat.add("tissue stiffness factor", model_->stiffness_scale());
    stat.add("hidden loads, sum of magnitudes (N)", registration_->hidden_load_total());
    stat.add("last cloud size", last_cloud_points_);
    stat.add("last cloud filter time (s)", last_cloud_filter_s_);
    stat.add("last rejection", last_rejection_);
  }

  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
  diagnostic_updater::Updater updater_;
  std::unique_ptr<LiverModel> model_;
  std::unique_ptr<RosInstruments> instruments_;
  std::string frame_id_;
  double rate_, publish_rate_, color_scale_max_, surface_alpha_;
  double pose_timeout_ = 1.0;  // s, as the instruments have it
  bool budget_follows_rate_ = true;  // neither ~step_time_budget nor ~solver/time_budget: one frame of ~rate
  bool hold_stale_ = false;
  ros::Publisher mesh_pub_, vessel_pub_, status_pub_, target_marker_pub_, target_pose_pub_;
  ros::Publisher covariance_pub_, ellipsoid_pub_;
  std::unique_ptr<SurfaceRegistration> registration_;
  std::unique_ptr<UncertaintyWorker> analysis_;
  double uncertainty_period_ = 1.0;  // s
  double cloud_margin_ = 0.05;  // m
  Eigen::AlignedBox3d cloud_box_;  // model frame: where cloud points can matter
  ros::Subscriber cloud_sub_;
  ros::ServiceServer reset_srv_, capsule_srv_, align_srv_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<LiverSimConfig>> reconfigure_;
  visualization_msgs::Marker marker_, vessel_marker_;

  // Simulation thread only.
  Eigen::VectorXd published_positions_;  // of the last mesh sent
  bool display_due_ = true;
  StepGuard guard_;
  StepResult last_;
  uint64_t steps_ = 0;
  uint64_t factorizations_ = 0;  // in the steps since start or reset
  std::string state_ = "idle";
  std::deque<ros::WallTime> step_times_;  // of the steps in the last second
  ros::Time reflected_stamp_;
  Eigen::VectorXd reference_;  // m, 3 #V: the pre-operative equilibrium; empty until known
  uint64_t clouds_registered_ = 0;
  bool registering_ = false;  // the model is converging on the last cloud
  RegistrationFrame registered_;  // the fit shown: the last registered cloud's, or its last refinement's
  std::vector<Eigen::Matrix3d> covariances_;  // of the targets, m^2, at the last analysis
  bool analysis_due_ = false;  // a cloud was registered since the last analysis started
  ros::WallTime next_analysis_;
  ros::Time analysis_started_at_;  // the state the running analysis describes
  ros::Time analysis_stamp_;       // the state covariances_ describe
  double analysis_cpu_time_ = 0;   // s, on the analysis's thread, of the last one adopted
  uint64_t analysis_generation_ = 0;  // a reset or a new capsule: analyses started before are void

  // Shared with the heartbeat, under status_mutex_.
  std::mutex status_mutex_;
  SimulationStatus last_status_;  // as last published by the loop
  ros::WallTime last_status_time_, frame_start_;  // frame_start_: zero between frames
  double frame_period_ = 1.0 / 30;  // s, at the last status

  // Shared with callbacks, under mutex_.
  std::mutex mutex_;
  bool reset_requested_ = false, align_requested_ = false;
  std::optional<LiverSimConfig> pending_config_;
  std::optional<CapsuleOptions> pending_capsule_;
  CapsuleOptions capsule_;  // the model's, or the request the simulation thread is applying
  struct PendingCloud {
    pcl::PointCloud<pcl::PointXYZ> points;  // model frame, cropped and downsampled
    std::optional<Eigen::Vector3d> viewpoint;  // the sensor's origin, model frame, when known
    ros::Time stamp;
  };
  std::optional<PendingCloud> pending_cloud_;
  double last_cloud_filter_s_ = 0;
  size_t last_cloud_points_ = 0;
  uint32_t rejected_ = 0;
  uint64_t clouds_ = 0;
  std::string last_rejection_, fresh_text_;

  std::thread heartbeat_;
  std::atomic<bool> stop_heartbeat_{false};
};

}  // namespace liver_sim

int main(int argc, char** argv) {
  ros::init(argc, argv, "liver_sim");
  // The clouds and the analyses free and allocate the same blocks again, frame after frame.
  if (!liver_sim::keep_freed_memory()) ROS_WARN("liver_sim: the allocator keeps handing freed memory back to the system");
  ros::NodeHandle nh, pnh("~");
  // The simulation thread (this one): its processors and its scheduling, set before the model
  // is built so that the model's helper threads inherit them. Refused settings leave it as it was.
  const std::vector<int> processors = liver_sim::processors_of_calling_thread();
  std::vector<int> cpu_affinity;
  int realtime_priority = 0;
  double thread_slice = 1e-4;
  pnh.param("cpu_affinity", cpu_affinity, std::vector<int>{});
  pnh.param("realtime_priority", realtime_priority, 0);
  pnh.param("thread_slice", thread_slice, thread_slice);
  for (int cpu : cpu_affinity)
    if (std::find(processors.begin(), processors.end(), cpu) == processors.end()) {
      ROS_FATAL("liver_sim: ~cpu_affinity: processor %d is not one this process may use", cpu);
      return 1;
    }
  if (realtime_priority < 0 || realtime_priority > 99) {
    ROS_FATAL("liver_sim: ~realtime_priority must be in [0, 99] (got %d)", realtime_priority);
    return 1;
  }
  if (!(thread_slice == 0 || (thread_slice >= 1e-4 && thread_slice <= 0.1))) {
    ROS_FATAL("liver_sim: ~thread_slice must be 0 or in [1e-4, 0.1] s (got %g)", thread_slice);
    return 1;
  }
  if (!cpu_affinity.empty()) {
    const std::string refused = liver_sim::pin_calling_thread(cpu_affinity);
    if (!refused.empty()) ROS_WARN("liver_sim: ~cpu_affinity refused (%s); the simulation runs on any processor", refused.c_str());
  }
  if (realtime_priority != 0) {
    const std::string refused = liver_sim::set_realtime_priority(realtime_priority);
    if (!refused.empty())
      ROS_WARN("liver_sim: ~realtime_priority %d refused (%s); the simulation runs at normal priority",
               realtime_priority, refused.c_str());
  }
  std::unique_ptr<liver_sim::LiverSimNode> node;
  try {
    node = std::make_unique<liver_sim::LiverSimNode>(nh, pnh);
  } catch (const std::exception& e) {
    ROS_FATAL("liver_sim: %s", e.what());
    return 1;
  }
  // Callbacks and services run beside the simulation loop, at normal priority, on the processors
  // the simulation leaves (all of them when it leaves none): their threads inherit both from the
  // thread that starts them.
  ros::AsyncSpinner spinner(2);
  std::thread([&] {
    std::vector<int> others;
    for (int cpu : processors)
      if (std::find(cpu_affinity.begin(), cpu_affinity.end(), cpu) == cpu_affinity.end()) others.push_back(cpu);
    liver_sim::set_realtime_priority(0);
    liver_sim::pin_calling_thread(others.empty() ? processors : others);
    spinner.start();
    node->start_heartbeat();
  }).join();
  // The threads that wake to pass messages on run at once on a core the simulation keeps busy:
  // without it, on one core shared with 100,000-point clouds, ~status went out up to 93 ms late
  // (doc/robustness.md, node soak).
  if (thread_slice > 0) {
    const std::string refused = liver_sim::set_slice_of_other_threads(thread_slice);
    if (!refused.empty()) ROS_WARN("liver_sim: ~thread_slice refused (%s); the kernel's slice stays", refused.c_str());
  }
  node->run();
  return 0;
}
