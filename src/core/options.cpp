#include "liver_sim/options.h"

#include <cmath>
#include <sstream>

#include "liver_sim/worker_pool.h"

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
  return first_error({positive("parenchyma.young_modulus", o.young_modulus),
                      poisson("parenchyma.poisson_ratio", o.poisson_ratio),
                      positive("parenchyma.density", o.density)});
}

std::string validate(const CapsuleOptions& o) {
  std::string region;
  if (o.region) {
    region = validate(*o.region);
    if (!region.empty()) region = "capsule.region: " + region;
  }
  return first_error({positive("capsule.young_modulus", o.young_modulus),
                      positive("capsule.thickness", o.thickness),
                      poisson("capsule.poisson_ratio", o.poisson_ratio), region});
}

std::string validate(const SolverOptions& o) {
  return first_error({positive("solver.dt", o.dt),
                      o.steps >= 1 ? "" : message("solver.steps", ">= 1", o.steps),
                      o.max_iterations >= 1 ? "" : message("solver.max_iterations", ">= 1", o.max_iterations),
                      positive("solver.tolerance", o.tolerance),
                      non_negative("solver.rayleigh_mass", o.rayleigh_mass),
                      non_negative("solver.rayleigh_stiffness", o.rayleigh_stiffness),
                      o.threads >= 1 && o.threads <= WorkerPool::kMaxThreads
                          ? ""
                          : message("solver.threads", ("in [1, " + std::to_string(WorkerPool::kMaxThreads) + "]").c_str(),
                                    o.threads)});
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
  auto pose_ok = [](const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
    return p.allFinite() && q.coeffs().allFinite() && q.norm() > 1e-6;
  };
  std::string shape;
  switch (o.type) {
    case Type::Probe: shape = positive(k + "radius", o.radius); break;
    case Type::Grasper: shape = positive(k + "radius", o.radius); break;
    case Type::Shaft: shape = first_error({positive(k + "radius", o.radius), positive(k + "length", o.length)}); break;
    case Type::Tube:
      shape = first_error({positive(k + "inner_radius", o.inner_radius),
                           o.outer_radius > o.inner_radius && std::isfinite(o.outer_radius)
                               ? ""
                               : message(k + "outer_radius", "finite and > inner_radius", o.outer_radius),
                           positive(k + "length", o.length), non_negative(k + "suction", o.suction)});
      break;
  }
  std::string path;
  for (size_t i = 0; i < o.trajectory.size() && path.empty(); ++i) {
    const InstrumentOptions::Keyframe& f = o.trajectory[i];
    const std::string ki = k + "trajectory." + std::to_string(i);
    if (!std::isfinite(f.t) || (i > 0 && !(f.t > o.trajectory[i - 1].t)))
      path = ki + ".t must be finite and increase along the trajectory";
    else if (!pose_ok(f.position, f.orientation))
      path = ki + ": position and orientation must be finite, the quaternion non-zero";
  }
  return first_error({o.name.empty() ? "instruments: a name is required" : "", shape,
                      pose_ok(o.position, o.orientation) ? ""
                                                         : k + "pose: position and orientation must be finite, the quaternion non-zero",
                      path});
}

std::string validate(const ContactOptions& o) {
  return first_error({non_negative("contact.friction", o.friction),
                      non_negative("contact.alarm_distance", o.alarm_distance),
                      positive("contact.tolerance", o.tolerance),
                      o.max_iterations >= 1 ? "" : message("contact.max_iterations", ">= 1", o.max_iterations)});
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
      {positive("registration.stiffness", o.stiffness), non_negative("registration.voxel_size", o.voxel_size),
       o.max_points >= 1 ? "" : message("registration.max_points", ">= 1", o.max_points),
       positive("registration.max_distance", o.max_distance),
       std::isfinite(o.trim_fraction) && o.trim_fraction >= 0 && o.trim_fraction < 0.9
           ? ""
           : message("registration.trim_fraction", "in [0, 0.9)", o.trim_fraction),
       positive("registration.huber_width", o.huber_width),
       o.correspondence_updates >= 1 ? "" : message("registration.correspondence_updates", ">= 1", o.correspondence_updates),
       o.newton_iterations >= 1 ? "" : message("registration.newton_iterations", ">= 1", o.newton_iterations),
       o.min_points >= 1 ? "" : message("registration.min_points", ">= 1", o.min_points),
       o.min_coverage >= 0 && o.min_coverage <= 1 ? "" : message("registration.min_coverage", "in [0, 1]", o.min_coverage),
       o.full_coverage > 0 && o.full_coverage <= 1 ? "" : message("registration.full_coverage", "in (0, 1]", o.full_coverage),
       candidate_error(o.candidate_supports), positive("registration.support_stiffness", o.support_stiffness),
       o.support_gain > 0 && o.support_gain < 1 ? "" : message("registration.support_gain", "in (0, 1)", o.support_gain),
       std::isfinite(o.max_tissue_stiffness_factor) && o.max_tissue_stiffness_factor >= 1
           ? ""
           : message("registration.max_tissue_stiffness_factor", ">= 1", o.max_tissue_stiffness_factor),
       positive("registration.uncertainty.patch_spacing", o.uncertainty.patch_spacing),
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
