// Contact between the tissue and rigid instruments, ROS-free: the instruments (instrument_slot.h:
// poses, trajectories, staging of large moves; what each shape does besides pushing is its own,
// instrument_shape.h), contact detection against the surface triangles, the contacts and their
// rows (surface_contact.h), the frictional contact problem on the Delassus operator from the
// stepper's factor (contact_problem.h), the two Newton updates with the contact forces (direct;
// Krylov, krylov_contact_update.h) and the reactions on each instrument.
//
// A contact acts at a material point of the surface, carried by its triangle's nodes with its
// barycentric weights: the surface is sampled, in the triangles near an instrument, at most half
// the instrument's radius apart (the nodes, points on the edges, points inside), so that a tip
// smaller than the triangles cannot pass between nodes: it sinks between samples by at most
// 1/32 of its radius. The points are fixed on the surface, as nodes are: only which of them are
// in contact changes from one iteration to the next.
//
// It reads the mechanical model's surface and supports and sets only its tubes' suction loads;
// the stepper hands it the factor, the Jacobian and the residual of the iteration. It may not
// touch the Newton loop, the element sets or the factorisation.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "liver_sim/contact/contact_problem.h"
#include "liver_sim/contact/instrument.h"
#include "liver_sim/contact/instrument_slot.h"
#include "liver_sim/contact/krylov_contact_update.h"
#include "liver_sim/contact/surface_contact.h"
#include "liver_sim/contact/surface_point.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/linalg/gmres.h"
#include "liver_sim/model/mechanical_model.h"

namespace liver_sim {

class InstrumentContact {
 public:
  // Throws std::invalid_argument for invalid options (validate(ContactOptions)).
  InstrumentContact(MechanicalModel& mechanics, const ContactOptions& options);

  // Instruments are rigid and pose-driven, in unilateral contact with Coulomb friction with the
  // surface, or holding it (a closed grasper). add/update throw std::invalid_argument naming the
  // field at fault (validate(InstrumentOptions)), or, beyond kMaxInstruments, the count; a change
  // acts at the next step. `time` places an instrument with a trajectory.
  int add_instrument(const InstrumentOptions& o, double time);
  void update_instrument(int i, const InstrumentOptions& o);
  // Slot i, out of the scene now and at the last step, becomes a new instrument, name and type
  // included, as add_instrument makes it: a model full of withdrawn instruments takes new ones.
  // Throws std::invalid_argument as add_instrument does, or when slot i is or was in the scene.
  void replace_instrument(int i, const InstrumentOptions& o, double time);
  int num_instruments() const { return static_cast<int>(instruments_.size()); }
  // Out of the scene (disabled) and out of it at the last step: replace_instrument takes it.
  bool withdrawn(int i) const { return !instruments_[i].options.enabled && !instruments_[i].was_enabled; }
  const InstrumentOptions& instrument(int i) const { return instruments_[i].options; }
  int find_instrument(const std::string& name) const;  // -1 when there is none
  const Eigen::Isometry3d& pose(int i) const { return instruments_[i].pose; }  // at the last step
  const InstrumentReaction& reaction(int i) const { return instruments_[i].reaction; }
  const ContactOptions& options() const { return options_; }
  std::string set_options(const ContactOptions& o);  // "" or the validation message (nothing changed)
  // The contact forces on the tissue at positions x, added to f / per DOF (N): each contact's
  // force in the frame of the instrument's surface at its point, which turns as the point moves.
  void add_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;
  Eigen::VectorXd forces(const Eigen::VectorXd& x) const;
  // Work counters since construction: contact problems solved and compliance columns
  // (L^-1 P e_i) computed. Both stay 0 while no instrument comes within the alarm distance.
  long solves() const { return solves_; }
  long compliance_columns() const { return problem_.compliance_columns(); }

  // A contact of the last detection: where, and with what force.
  using Contact = SurfaceContact;
  const std::vector<Contact>& contacts() const { return contacts_; }

  // A step, as the stepper drives it:
  //   begin_step(t, x)              instruments to their pose at time t; returns the stages the
  //                                 step needs (an instrument moving more than a quarter of its
  //                                 size, or appearing, is moved there in stages, each solved,
  //                                 so that no surface point is caught deep inside it)
  //   begin_stage(k, stages, x)     the poses of stage k (1-based); slips are measured from x
  //   detect(x), violation(x), direct_update(...) or krylov_update(...) within the Newton iterations
  //   end_step(x)                   the reactions at x
  // A step that is rolled back restores what save() took before it instead (restore).
  int begin_step(double t, const Eigen::VectorXd& x);
  void begin_stage(int k, int stages, const Eigen::VectorXd& x);
  // The contacts at x: the surface points within the alarm distance of an instrument and the
  // held points, with their forces carried over from the previous contacts at the same points.
  // True when a dropped contact carried force.
  bool detect(const Eigen::VectorXd& x);
  bool active() const { return !contacts_.empty(); }
  // True when some contact point at x lies deeper in its instrument than a quarter of the
  // instrument's size (a predicted state that would catch the surface on the wrong side).
  bool deep(const Eigen::VectorXd& x) const;
  // Largest violation of Signorini, sticking and holding at x with the current forces (m).
  double violation(const Eigen::VectorXd& x) const;

  // The Newton update dx with the contact forces, for the residual r (the free forces plus the
  // current contact forces): the frictional contact problem on the Delassus operator
  // W = H A^-1 H^T of the factorised matrix A decides which contacts stick, slide or separate.
  // Direct: dx = A^-1 (r + H^T (lambda - lambda_now)), one solve (modified and full Newton).
  // Krylov: GMRES on the true Jacobian with the contact rows of that decision, preconditioned
  // by the same system with A (Newton-Krylov). Sets the contacts' forces.
  struct Update {
    int krylov = 0;                // GMRES iterations
    double relative_residual = 0;  // GMRES's at the end
    bool out_of_time = false;      // GMRES stopped at the deadline short of its tolerance
    int sweeps = 0;                // Gauss-Seidel sweeps
  };
  // The contact problem is solved until its gaps carry a force error below force_tolerance (N),
  // and to 1% of options().tolerance at least.
  Update direct_update(CholmodSolver& factor, const Eigen::VectorXd& r, double force_tolerance, Eigen::VectorXd& dx);
  // GMRES stops at the deadline with its iterate so far (Gmres::solve).
  Update krylov_update(CholmodSolver& factor, const Gmres::Operator& jacobian, const Eigen::VectorXd& r, double forcing,
                       double force_tolerance, Gmres::Clock::time_point deadline, Eigen::VectorXd& dx);
  // The forces of the last update scaled along the step, l_before + alpha (l_update - l_before):
  // a line search's trial point alpha dx carries alpha of the force change (0: the update undone).
  void scale_update(double alpha);
  // Adds to f the change of the contact forces the last update made, in the detection frames;
  // false when it made none.
  bool add_force_change(Eigen::VectorXd& f) const;
  void end_step(const Eigen::VectorXd& x);
  int loaded_contacts() const;  // contacts carrying force

  // Everything a step changes here: each instrument (pose, staging, grasp, reaction), the
  // contacts (the active set, forces, frames, rows), the tubes' suction loads. The stepper saves
  // it before a step and restores it when the step is rolled back.
  struct State {
    std::vector<InstrumentSlot> instruments;
    std::vector<Contact> contacts;
    std::vector<PressureLoad> suction;  // of the tubes, in instrument order
    Eigen::VectorXd x_stage;
    std::vector<Eigen::Isometry3d> stage_from, stage_to;
  };
  void save(State& s) const;
  void restore(const State& s);

  // No contact, no force; graspers let go (they grasp again at the next step if still closed).
  void reset();

 private:
  // A new instrument of options o in slot `in`, posed at `time`; a tube gets a pressure load.
  void place(InstrumentSlot& in, const InstrumentOptions& o, double time);
  // Where an instrument that appears at its pose starts its move: back along its axis from
  // where it touches the surface at x nowhere.
  Eigen::Isometry3d entry_pose(const InstrumentSlot& in, const Eigen::VectorXd& x) const;
  // The contact problem for the residual r (contact_problem.h), solved: the new forces in
  // problem_.lambda(), the current ones kept for scale_update. Returns the sweeps.
  int solve_contact_problem(CholmodSolver& factor, const Eigen::VectorXd& r, double force_tolerance);
  // The contact forces are an update's: kept for scale_update.
  void keep_update();

  MechanicalModel& mechanics_;
  ContactOptions options_;
  std::vector<InstrumentSlot> instruments_;
  std::vector<Eigen::Isometry3d> stage_from_, stage_to_;
  Eigen::VectorXd x_stage_;  // positions at the start of the stage: slips are measured from them
  std::vector<Contact> contacts_, contacts_next_;
  std::vector<Eigen::Vector3d> lambda_before_update_, lambda_of_update_;  // per contact
  ContactProblem problem_;
  KrylovContactUpdate krylov_;
  std::vector<Eigen::Vector3d> change_;  // the direct update's force changes
  long solves_ = 0;
};

}  // namespace liver_sim
