#include "one_shot_session.h"

#include <cmath>
#include <cstdlib>
#include <map>
#include <stdexcept>

#include "liver_sim/io/scene_files.h"
#include "liver_sim/registration/target_uncertainty.h"

namespace liver_sim {
namespace {

void set_one_shot_option(OneShotOptions& o, const std::string& assignment) {
  const size_t eq = assignment.find('=');
  if (eq == std::string::npos) throw std::invalid_argument("expected KEY=VALUE, got " + assignment);
  const std::string key = assignment.substr(0, eq), text = assignment.substr(eq + 1);
  const std::map<std::string, double*> reals = {
      {"voxel_size", &o.voxel_size},         {"start_gate", &o.start_gate},           {"end_gate", &o.end_gate},
      {"max_normal_angle", &o.max_normal_angle}, {"trim_fraction", &o.trim_fraction}, {"huber_width", &o.huber_width},
      {"patch_spacing", &o.patch_spacing},   {"start_damping", &o.start_damping},     {"load_damping", &o.load_damping},
      {"foundation", &o.foundation},         {"support", &o.support},                 {"posterior_scale", &o.posterior_scale}, {"damping_error", &o.damping_error},
      {"model_error_floor", &o.model_error_floor}, {"displacement_error", &o.displacement_error}};
  const std::map<std::string, int*> counts = {{"max_points", &o.max_points},
                                              {"normal_neighbours", &o.normal_neighbours},
                                              {"rigid_iterations", &o.rigid_iterations},
                                              {"rounds", &o.rounds},
                                              {"iterations", &o.iterations}};
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0') throw std::invalid_argument(key + ": '" + text + "' is not a number");
  if (reals.count(key)) {
    *reals.at(key) = v;
  } else if (counts.count(key)) {
    if (v != std::floor(v) || std::abs(v) > 1e9) throw std::invalid_argument(key + ": '" + text + "' is not a whole number");
    *counts.at(key) = static_cast<int>(v);
  } else {
    throw std::invalid_argument("no one-shot option " + key);
  }
}

}  // namespace

void set_one_shot_options(OneShotOptions& options, const std::vector<std::string>& assignments) {
  for (const std::string& a : assignments) set_one_shot_option(options, a);
  const std::string error = validate(options);
  if (!error.empty()) throw std::invalid_argument(error);
}

void add_one_shot_sets(CLI::App& app, OneShotOptions* options, const std::string& keys) {
  const auto set = [options](const std::vector<std::string>& assignments) {
    try {
      set_one_shot_options(*options, assignments);
    } catch (const std::invalid_argument& e) {
      throw CLI::ValidationError("--set", e.what());
    }
  };
  app.add_option_function<std::vector<std::string>>(
         "--set", set, "a one-shot option in SI units (registration/one_shot.h: " + keys + ", ...; repeatable)")
      ->option_text("KEY=VALUE")
      ->allow_extra_args(false);
}

OneShotSession::OneShotSession(const Scene& scene, const OneShotOptions& options) {
  const TetMesh mesh = load_scene_mesh(scene);
  model_ = std::make_unique<LiverModel>(mesh, scene);
  registration_ = std::make_unique<SurfaceRegistration>(*model_, scene.registration);
  one_shot_ = std::make_unique<OneShotRegistration>(mesh, scene, options);
}

void OneShotSession::set_targets(const std::vector<Eigen::Vector3d>& rest_positions) {
  targets_ = embed_points(model_->mesh().T, model_->mechanics().rest_positions(), rest_positions);
}

OneShotSession::Result OneShotSession::register_cloud(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                                      const std::optional<Eigen::Vector3d>& viewpoint) {
  Result result;
  registration_->clear();
  model_->reset();
  result.report = registration_->register_one_shot(*one_shot_, cloud, viewpoint);
  const Eigen::Isometry3d to_cloud = registration_->alignment().inverse();
  result.uncertainty = one_shot_->uncertainty(targets_);
  for (const EmbeddedPoint& e : targets_) result.positions.push_back(to_cloud * interpolate(model_->mesh().T, model_->positions(), e));
  return result;
}

}  // namespace liver_sim
