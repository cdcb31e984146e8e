#include "liver_sim/liver_model.h"

#include <algorithm>
#include <cmath>

namespace liver_sim {

TetMesh load_scene_mesh(const Scene& scene) {
  if (scene.mesh.file.empty()) return make_box_mesh(scene.mesh.box_size, scene.mesh.box_divisions);
  return read_mesh(scene.mesh.file, scene.mesh.scale);
}

LiverModel::LiverModel(TetMesh mesh, const Scene& scene)
    : mechanics_(std::move(mesh), scene), contact_(mechanics_, scene.contact), stepper_(mechanics_, contact_, scene.solver) {
  for (const InstrumentOptions& o : scene.instruments) add_instrument(o);
  mechanics_.snapshot_damping(stepper_.step_start());  // so that any residual before the first step finds one
}

std::string LiverModel::set_capsule(const CapsuleOptions& capsule) {
  const std::string error = mechanics_.set_capsule(capsule);
  if (!error.empty()) return error;
  stepper_.model_changed(/*refactorize=*/true);
  // The membranes' frames for the damping, should a residual be evaluated before the next step.
  mechanics_.snapshot_damping(stepper_.step_start());
  return "";
}

void LiverModel::set_stiffness_scale(double s) {
  if (s == mechanics_.stiffness_scale()) return;
  mechanics_.set_stiffness_scale(s);
  stepper_.model_changed(/*refactorize=*/true);
}

void LiverModel::set_surface_targets(std::vector<SurfaceTarget> targets) {
  // A factor without springs (or with far weaker ones) preconditions badly; frame-to-frame
  // changes of the same cloud's springs keep it.
  const double before = mechanics_.spring_stiffness();
  mechanics_.set_surface_targets(std::move(targets));
  const double after = mechanics_.spring_stiffness();
  stepper_.model_changed(/*refactorize=*/std::abs(after - before) > 0.5 * std::max(after, before));
}

void LiverModel::reset() {
  mechanics_.reset();
  contact_.reset();
  stepper_.reset();
}

double LiverModel::max_displacement() const {
  const Eigen::VectorXd& x = positions();
  const Eigen::VectorXd& X = mechanics_.rest_positions();
  double max_u = 0;
  for (int i = 0; i < x.size(); i += 3) max_u = std::max(max_u, (x.segment<3>(i) - X.segment<3>(i)).norm());
  return max_u;
}

Eigen::Vector3d LiverModel::probe_displacement(int i) const {
  return mechanics_.probe_position(positions(), i) - mechanics_.probe_position(mechanics_.rest_positions(), i);
}

}  // namespace liver_sim
