#include "liver_sim/simulation/liver_model.h"

#include "liver_sim/io/scene_files.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace liver_sim {

LiverModel::LiverModel(TetMesh mesh, const Scene& scene)
    : mechanics_(std::move(mesh), scene, load_vessel_trees(scene)), contact_(mechanics_, scene.contact), stepper_(mechanics_, contact_, scene.solver) {
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

void LiverModel::set_surface_loads(Eigen::VectorXd loads) {
  mechanics_.set_surface_loads(std::move(loads));
  stepper_.model_changed(/*refactorize=*/false);  // dead loads: the tangent stays
}

void LiverModel::reset() {
  mechanics_.reset();
  contact_.reset();
  stepper_.reset();
}

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

std::vector<double> LiverModel::observable_state() const {
  std::vector<double> s;
  const auto add = [&s](const auto& values) {
    for (Eigen::Index i = 0; i < values.size(); ++i) s.push_back(values.data()[i]);
  };
  add(stepper_.positions());
  add(stepper_.velocities());
  add(stepper_.step_start());
  s.push_back(stepper_.time());
  for (int i = 0; i < contact_.num_instruments(); ++i) {
    add(contact_.pose(i).matrix());
    add(contact_.reaction(i).force);
    add(contact_.reaction(i).torque);
    s.push_back(contact_.reaction(i).contacts);
  }
  for (const InstrumentContact::Contact& c : contact_.contacts()) {
    s.push_back(c.instrument);
    s.push_back(c.held);
    for (int j = 0; j < 3; ++j) s.push_back(c.point.nodes[j]);
    add(c.point.weights);
    s.push_back(c.point.sample);
    add(c.frame);
    add(c.rows);
    add(c.lambda);
  }
  for (int i = 0; i < mechanics_.num_pressure_loads(); ++i) {
    const PressureLoad& p = mechanics_.pressure_load(i);
    s.push_back(p.pressure);
    s.insert(s.end(), p.triangles.begin(), p.triangles.end());
  }
  const CorotationalTetra& tetra = mechanics_.tetrahedra();
  for (int e = 0; e < tetra.size(); ++e) {
    add(tetra.rotation(e));
    add(tetra.rotation_guess(e).coeffs());
  }
  return s;
}

bool LiverModel::finite_state() const {
  bool finite = positions().allFinite() && stepper_.velocities().allFinite();
  for (int i = 0; i < num_instruments(); ++i)
    finite &= instrument_reaction(i).force.allFinite() && instrument_reaction(i).torque.allFinite();
  return finite;
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
