// The composite liver model as the node and the tools use it: a thin composition of its three
// parts, ROS-free.
//   MechanicalModel (mechanical_model.h)   force fields, loads, springs, supports: forces, tangent,
//                                           energy and damping products of a state
//   InstrumentContact (instrument_contact.h)  instruments, contact detection, the contact problem,
//                                           reactions
//   NewtonStepper (newton_stepper.h)       static and backward-Euler steps: Newton, strategies,
//                                           predictors, factor reuse, rollback; owns the state
// It builds them from a scene and routes changes that concern more than one part (a capsule
// change voids the stepper's factor); it holds no physics of its own.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "liver_sim/contact/instrument_contact.h"
#include "liver_sim/model/mechanical_model.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/io/scene_files.h"
#include "liver_sim/stepper/newton_stepper.h"
#include "liver_sim/scene/scene.h"

namespace liver_sim {

// a and b hold the same bits (NaN equals NaN, -0 differs from +0).
bool same_bits(const std::vector<double>& a, const std::vector<double>& b);

class LiverModel {
 public:
  // Builds the parts; throws std::invalid_argument naming the problem (invalid option, region
  // selecting nothing, probe outside the mesh, a static scene with nothing fixed, a vessel file
  // that does not load, a vessel node farther outside the mesh than its snap tolerance).
  LiverModel(TetMesh mesh, const Scene& scene);

  // One step of the scene's mode (NewtonStepper::step).
  StepResult step() { return stepper_.step(); }

  // Static load continuation: loads are multiplied by this factor (default 1).
  void set_load_scale(double s) { stepper_.set_load_scale(s); }
  double load_scale() const { return stepper_.load_scale(); }

  // Capsule on/off, E, h, nu, region: takes effect at the next step with no mesh reload and no
  // new symbolic analysis. Returns "" on success, else the validation message (nothing changed).
  std::string set_capsule(const CapsuleOptions& capsule);
  const CapsuleOptions& capsule() const { return mechanics_.capsule(); }
  int capsule_triangles() const { return mechanics_.capsule_triangles(); }

  // A factor on the tissue's stiffness (MechanicalModel::set_stiffness_scale), from the next
  // step on; the stepper's factor is made afresh. Throws std::invalid_argument unless finite, > 0.
  void set_stiffness_scale(double s);
  double stiffness_scale() const { return mechanics_.stiffness_scale(); }

  // Instruments (InstrumentContact); the scene's are added by the constructor.
  int add_instrument(const InstrumentOptions& o) { return contact_.add_instrument(o, stepper_.time()); }
  void update_instrument(int i, const InstrumentOptions& o) { contact_.update_instrument(i, o); }
  void replace_instrument(int i, const InstrumentOptions& o) { contact_.replace_instrument(i, o, stepper_.time()); }
  int num_instruments() const { return contact_.num_instruments(); }
  bool instrument_withdrawn(int i) const { return contact_.withdrawn(i); }
  const InstrumentOptions& instrument(int i) const { return contact_.instrument(i); }
  int find_instrument(const std::string& name) const { return contact_.find_instrument(name); }
  const InstrumentReaction& instrument_reaction(int i) const { return contact_.reaction(i); }
  const Eigen::Isometry3d& instrument_pose(int i) const { return contact_.pose(i); }  // at the last step
  // Friction, alarm distance, tolerance and sweeps of the contact solver from the next step on.
  // Returns "" on success, else the validation message (nothing changed).
  std::string set_contact_options(const ContactOptions& o) { return contact_.set_options(o); }

  // Surface springs (registration): replaces the set, acting at the next step; the factor is
  // refreshed when their total stiffness changed by over half. Throws std::invalid_argument for
  // a triangle out of range or non-finite values. reset() removes them.
  void set_surface_targets(std::vector<SurfaceTarget> targets);
  const std::vector<SurfaceTarget>& surface_targets() const { return mechanics_.surface_targets(); }
  // Surface loads the registration found (MechanicalModel::set_surface_loads), acting at the
  // next step with the springs; reset() removes them.
  void set_surface_loads(Eigen::VectorXd loads);
  const Eigen::VectorXd& surface_loads() const { return mechanics_.surface_loads(); }

  // The next Newton iteration factorises the matrix afresh (a retry after a step that stalled
  // on an older factor).
  void refactorize() { stepper_.refactorize(); }

  // Back to the state before the last step (NewtonStepper::undo_step): right after a step whose
  // result the caller cannot use. False, and nothing changed, when there is none.
  bool undo_step() { return stepper_.undo_step(); }

  // Every number of the state that a user or a test can read, in one vector: positions,
  // velocities, the last step's start, time, each instrument's pose and reaction, every contact
  // (point, force, frame, rows), the pressure loads (the tubes' suction), the element rotations
  // and their warm starts. A rolled-back step leaves it as it was, to the last bit
  // (same_bits). Gathered through the parts' accessors, apart from the rollback's own copy.
  std::vector<double> observable_state() const;
  // True when every value is finite (the node's check of a step's result).
  bool finite_state() const;

  // Back to the rest shape, zero velocity, time 0; parameters and instruments are kept (a
  // grasper lets go; it grasps again at the next step if it is still closed); no springs.
  void reset();

  const SolverOptions& solver_options() const { return stepper_.options(); }
  // Strategy, iteration cap, tolerance, line search, dt and damping, from the next step on (the
  // same scene run fast or exact). The mode and the threads cannot change. Returns "" on
  // success, else the validation message (nothing changed).
  std::string set_solver_options(const SolverOptions& solver) { return stepper_.set_options(solver); }

  const TetMesh& mesh() const { return mechanics_.mesh(); }
  const Eigen::MatrixX3i& boundary() const { return mechanics_.boundary(); }
  const Eigen::VectorXd& positions() const { return stepper_.positions(); }  // 3 #V, node-major (m)
  Eigen::VectorXd displacement() const { return positions() - mechanics_.rest_positions(); }
  double max_displacement() const;  // largest node displacement from the rest shape (m)
  double time() const { return stepper_.time(); }
  // Overwrites the current state (a tool or test starts from a given configuration).
  void set_positions(const Eigen::VectorXd& x) { stepper_.set_positions(x); }

  // Vessels: beam nodes, beams (node pairs), the vessel each beam belongs to, current positions.
  int num_vessel_nodes() const { return mechanics_.vessels().num_nodes(); }
  int num_beams() const { return mechanics_.vessels().num_beams(); }
  const Eigen::MatrixX2i& beam_segments() const { return mechanics_.vessels().segments(); }  // only when num_beams() > 0
  int beam_vessel(int e) const { return mechanics_.vessels().beam_vessel(e); }
  const std::string& vessel_name(int v) const { return mechanics_.vessels().vessel_name(v); }
  Eigen::Vector3d vessel_node_position(int k) const { return mechanics_.vessels().node_position(positions(), k); }

  // The scene's probes: tracked points of the tissue.
  int num_probes() const { return mechanics_.num_probes(); }
  const std::string& probe_name(int i) const { return mechanics_.probe_name(i); }
  Eigen::Vector3d probe_position(int i) const { return mechanics_.probe_position(positions(), i); }
  Eigen::Vector3d probe_displacement(int i) const;

  // The parts, for tests and tools that look inside.
  MechanicalModel& mechanics() { return mechanics_; }
  InstrumentContact& contact() { return contact_; }
  const InstrumentContact& contact() const { return contact_; }
  NewtonStepper& stepper() { return stepper_; }

 private:
  MechanicalModel mechanics_;
  InstrumentContact contact_;
  NewtonStepper stepper_;
};

}  // namespace liver_sim
