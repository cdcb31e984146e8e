#include "liver_sim/scene/options.h"

#include <cmath>
#include <sstream>

#include "liver_sim/runtime/worker_pool.h"

namespace liver_sim {
namespace {

std::string message(const std::string& field, const char* rule, double value) {
  std::ostringstream s;
  s << field << " must be " << rule << " (got " << value << ")";
  return s.str();
}

std::string positive(const std::string& field, double v) {
  return (std::isfinite(v) && v > 0) ? "" : message(field, "finite and > 0", v);
}

std::string non_negative(const std::string& field, double v) {
  return (std::isfinite(v) && v >= 0) ? "" : message(field, "finite and >= 0", v);
}

// In (0, max] (open below) or [min, max].
std::string positive_up_to(const std::string& field, double v, double max, const char* rule) {
  return (std::isfinite(v) && v > 0 && v <= max) ? "" : message(field, rule, v);
}
std::string within(const std::string& field, double v, double min, double max, const char* rule) {
  return (std::isfinite(v) && v >= min && v <= max) ? "" : message(field, rule, v);
}
std::string count_within(const std::string& field, long v, long min, long max, const char* rule) {
  return v >= min && v <= max ? "" : message(field, rule, static_cast<double>(v));
}

std::string poisson(const std::string& field, double v) {
  return (std::isfinite(v) && v > -1 && v < 0.5) ? "" : message(field, "in (-1, 0.5)", v);
}

std::string first_error(std::initializer_list<std::string> errors) {
  for (const std::string& e : errors)
    if (!e.empty()) return e;
  return "";
}

}  // namespace

std::string validate(const ParenchymaOptions& o) {
  return first_error({positive_up_to("parenchyma.young_modulus", o.young_modulus, 1e9, "in (0, 1e9] Pa"),
                      poisson("parenchyma.poisson_ratio", o.poisson_ratio),
                      positive_up_to("parenchyma.density", o.density, 1e5, "in (0, 1e5] kg/m^3")});
}

std::string validate(const CapsuleOptions& o) {
  std::string region;
  if (o.region) {
    region = validate(*o.region);
    if (!region.empty()) region = "capsule.region: " + region;
  }
  return first_error({positive_up_to("capsule.young_modulus", o.young_modulus, 1e10, "in (0, 1e10] Pa"),
                      positive_up_to("capsule.thickness", o.thickness, 1e-3, "in (0, 1e-3] m"),
                      poisson("capsule.poisson_ratio", o.poisson_ratio), region});
}

const char* strategy_word(SolverOptions::Strategy s) {
  using S = SolverOptions::Strategy;
  switch (s) {
    case S::NewtonKrylov: return "newton_krylov";
    case S::FullNewton: return "full_newton";
    case S::FullNewtonEigen: return "full_newton_eigen";
    case S::ReusedFactorCG: return "reused_factor_cg";
    case S::CG: return "cg";
    case S::ModifiedNewton: return "modified_newton";
  }
  return "";
}

std::optional<SolverOptions::Strategy> parse_strategy(const std::string& word) {
  using S = SolverOptions::Strategy;
  for (S s : {S::NewtonKrylov, S::FullNewton, S::FullNewtonEigen, S::ReusedFactorCG, S::CG, S::ModifiedNewton})
    if (word == strategy_word(s)) return s;
  return std::nullopt;
}

std::string validate(const SolverOptions& o) {
  return first_error({positive_up_to("solver.dt", o.dt, 10, "in (0, 10] s"),
                      count_within("solver.steps", o.steps, 1, 1000000, "in [1, 1e6]"),
                      count_within("solver.max_iterations", o.max_iterations, 1, 10000, "in [1, 10000]"),
                      positive("solver.tolerance", o.tolerance),
                      non_negative("solver.rayleigh_mass", o.rayleigh_mass),
                      non_negative("solver.rayleigh_stiffness", o.rayleigh_stiffness),
                      o.threads >= 1 && o.threads <= WorkerPool::kMaxThreads
                          ? ""
                          : message("solver.threads", ("in [1, " + std::to_string(WorkerPool::kMaxThreads) + "]").c_str(),
                                    o.threads),
                      o.time_budget > 0 ? "" : message("solver.time_budget", "in (0, inf] s", o.time_budget),
                      o.capped_residual > 0 ? "" : message("solver.capped_residual", "in (0, inf]", o.capped_residual)});
}

std::string validate(const VesselOptions& o) {
  const std::string k = "vessels." + o.name + ".";
  return first_error({o.file.empty() ? k + "file is required" : "", positive(k + "scale", o.scale),
                      positive(k + "young_modulus", o.young_modulus), poisson(k + "poisson_ratio", o.poisson_ratio),
                      non_negative(k + "snap_tolerance", o.snap_tolerance)});
}

std::string validate(const InstrumentOptions& o) {
  const std::string k = "instruments." + o.name + ".";
  using Type = InstrumentOptions::Type;
  constexpr double kReach = 100;  // m: largest coordinate of a position
  auto pose_ok = [](const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
    return p.allFinite() && p.cwiseAbs().maxCoeff() <= kReach && q.coeffs().allFinite() && q.norm() > 1e-6;
  };
  const char* kPoseRule = "position and orientation must be finite, each coordinate within [-100, 100] m, the quaternion non-zero";
  auto size = [&](const char* field, double v) { return within(k + field, v, 1e-4, 0.05, "in [1e-4, 0.05] m"); };
  auto length = [&] { return within(k + "length", o.length, 1e-4, 0.5, "in [1e-4, 0.5] m"); };
  std::string shape;
  switch (o.type) {
    case Type::Probe: shape = size("radius", o.radius); break;
    case Type::Grasper: shape = size("radius", o.radius); break;
    case Type::Shaft: shape = first_error({size("radius", o.radius), length()}); break;
    case Type::Tube:
      shape = first_error({size("inner_radius", o.inner_radius), size("outer_radius", o.outer_radius),
                           o.outer_radius > o.inner_radius ? "" : message(k + "outer_radius", "> inner_radius", o.outer_radius),
                           length(), within(k + "suction", o.suction, 0, 101325, "in [0, 101325] Pa (vacuum)")});
      break;
  }
  std::string path = count_within(k + "trajectory", static_cast<long>(o.trajectory.size()), 0, 10000,
                                  "at most 10000 keyframes long");
  for (size_t i = 0; i < o.trajectory.size() && path.empty(); ++i) {
    const InstrumentOptions::Keyframe& f = o.trajectory[i];
    const std::string ki = k + "trajectory." + std::to_string(i);
    if (!std::isfinite(f.t) || (i > 0 && !(f.t > o.trajectory[i - 1].t)))
      path = ki + ".t must be finite and increase along the trajectory";
    else if (!pose_ok(f.position, f.orientation))
      path = ki + ": " + kPoseRule;
  }
  return first_error({o.name.empty() ? "instruments: a name is required" : "", shape,
                      pose_ok(o.position, o.orientation) ? "" : k + "pose: " + kPoseRule,
                      path});
}

std::string validate(const ContactOptions& o) {
  return first_error({within("contact.friction", o.friction, 0, 10, "in [0, 10]"),
                      within("contact.alarm_distance", o.alarm_distance, 0, 0.01, "in [0, 0.01] m"),
                      positive("contact.tolerance", o.tolerance),
                      count_within("contact.max_iterations", o.max_iterations, 1, 1000000, "in [1, 1e6]")});
}

static std::string candidate_error(const std::vector<Region>& regions) {
  for (size_t i = 0; i < regions.size(); ++i) {
    const std::string error = validate(regions[i]);
    if (!error.empty()) return "registration.candidate_supports." + std::to_string(i) + ": " + error;
  }
  return "";
}

std::string validate(const RegistrationOptions& o) {
  return first_error(
      {positive("registration.stiffness", o.stiffness),
       within("registration.voxel_size", o.voxel_size, 0, 0.1, "in [0, 0.1] m"),
       count_within("registration.max_points", o.max_points, 1, 100000, "in [1, 100000]"),
       positive("registration.max_distance", o.max_distance),
       std::isfinite(o.trim_fraction) && o.trim_fraction >= 0 && o.trim_fraction < 0.9
           ? ""
           : message("registration.trim_fraction", "in [0, 0.9)", o.trim_fraction),
       positive("registration.huber_width", o.huber_width),
       count_within("registration.correspondence_updates", o.correspondence_updates, 1, 100, "in [1, 100]"),
       count_within("registration.frame_updates", o.frame_updates, 1, 100, "in [1, 100]"),
       count_within("registration.newton_iterations", o.newton_iterations, 1, 100, "in [1, 100]"),
       o.min_points >= 1 ? "" : message("registration.min_points", ">= 1", o.min_points),
       o.min_coverage >= 0 && o.min_coverage <= 1 ? "" : message("registration.min_coverage", "in [0, 1]", o.min_coverage),
       o.full_coverage > 0 && o.full_coverage <= 1 ? "" : message("registration.full_coverage", "in (0, 1]", o.full_coverage),
       candidate_error(o.candidate_supports), positive("registration.support_stiffness", o.support_stiffness),
       o.support_gain > 0 && o.support_gain < 1 ? "" : message("registration.support_gain", "in (0, 1)", o.support_gain),
       o.min_tissue_stiffness_factor > 0 && o.min_tissue_stiffness_factor <= 1
           ? ""
           : message("registration.min_tissue_stiffness_factor", "in (0, 1]", o.min_tissue_stiffness_factor),
       std::isfinite(o.max_tissue_stiffness_factor) && o.max_tissue_stiffness_factor >= 1
           ? ""
           : message("registration.max_tissue_stiffness_factor", ">= 1", o.max_tissue_stiffness_factor),
       within("registration.hidden_load_damping", o.hidden_load_damping, 1e-6, 1e3, "in [1e-6, 1e3]"),
       // Each estimate takes the same pull away on the same factor: together they would
       // correct it twice (not measured together).
       o.estimate_hidden_loads && (o.estimates_tissue_stiffness() || !o.candidate_supports.empty())
           ? "registration.estimate_hidden_loads: not with the tissue's stiffness estimated or candidate supports (set it false to use them)"
           : "",
       within("registration.uncertainty.patch_spacing", o.uncertainty.patch_spacing, 1e-3, 1, "in [1e-3, 1] m"),
       non_negative("registration.uncertainty.force_ratio", o.uncertainty.force_ratio),
       non_negative("registration.uncertainty.stiffness_log_sd", o.uncertainty.stiffness_log_sd)});
}

std::string validate(const Region& r) {
  if (!r.min.allFinite() || !r.max.allFinite() || !r.center.allFinite() || !r.normal.allFinite())
    return "region coordinates must be finite";
  switch (r.kind) {
    case Region::Kind::Box:
      return (r.min.array() < r.max.array()).all() ? "" : "box: min must be below max on every axis";
    case Region::Kind::Sphere:
      return positive("sphere.radius", r.radius);
    case Region::Kind::Disc:
      return first_error({positive("disc.radius", r.radius),
                          (r.inner_radius >= 0 && r.inner_radius < r.radius)
                              ? ""
                              : message("disc.inner_radius", "in [0, radius)", r.inner_radius),
                          r.normal.norm() > 0 ? "" : "disc.normal must be non-zero",
                          std::isfinite(r.depth) ? "" : message("disc.depth", "finite", r.depth)});
  }
  return "";
}

}  // namespace liver_sim
