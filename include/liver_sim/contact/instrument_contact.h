// Contact between the tissue and rigid instruments (instrument.h), ROS-free: the instruments
// (poses, trajectories, staging of large moves, grasping, the tubes' suction), contact detection
// against the surface triangles, the contact rows, the Delassus operator from the stepper's
// factor (node_compliance.h), the frictional contact problem (contact_solver.h), the Newton
// update with the contact forces and the reactions on each instrument.
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
#include <Eigen/QR>
#include <array>
#include <string>
#include <vector>

#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/linalg/gmres.h"
#include "liver_sim/contact/instrument.h"
#include "liver_sim/model/mechanical_model.h"
#include "liver_sim/contact/node_compliance.h"

namespace liver_sim {

struct InstrumentReaction {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();   // N, exerted by the tissue on the instrument
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();  // N m, about the instrument's tip
  int contacts = 0;                                  // surface points pressing on it or held by it
};

// A material point of the surface: on a boundary triangle (three nodes), an edge (two) or at a
// node, with barycentric weights; nodes in increasing order and `sample` numbering the points of
// one triangle or edge, so that a point found from two triangles has one description.
struct SurfacePoint {
  std::array<int, 3> nodes{-1, -1, -1};
  Eigen::Vector3d weights = Eigen::Vector3d::Zero();
  int count = 0;
  int sample = 0;
  Eigen::Vector3d at(const Eigen::VectorXd& x) const;
  // The point of triangle `nodes` with weights w (weights below 1e-9 dropped).
  static SurfacePoint on_triangle(const Eigen::Vector3i& nodes, const Eigen::Vector3d& w);
};

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
  long compliance_columns() const { return compliance_.columns(); }

  // A contact of the last detection: where, and with what force.
  struct Contact {
    int instrument;
    SurfacePoint point;
    int held;               // bilateral: its index in the grasper's held points; -1: unilateral
    Eigen::Matrix3d frame;  // columns: normal, tangent, tangent (bilateral: identity), at the last detection
    Eigen::Vector3d rows;   // gap and slips there (m)
    Eigen::Vector3d lambda; // N on the tissue at the point, in the frame (normal first)
  };
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
    int sweeps = 0;                // Gauss-Seidel sweeps
  };
  // The contact problem is solved until its gaps carry a force error below force_tolerance (N),
  // and to 1% of options().tolerance at least.
  Update direct_update(CholmodSolver& factor, const Eigen::VectorXd& r, double force_tolerance, Eigen::VectorXd& dx);
  Update krylov_update(CholmodSolver& factor, const Gmres::Operator& jacobian, const Eigen::VectorXd& r, double forcing,
                       double force_tolerance, Eigen::VectorXd& dx);
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
  struct State;
  void save(State& s) const;
  void restore(const State& s);

  // No contact, no force; graspers let go (they grasp again at the next step if still closed).
  void reset();

 private:
  struct Instrument {
    InstrumentOptions options;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();        // at the end of the step
    Eigen::Isometry3d pose_start = Eigen::Isometry3d::Identity();  // at its start
    bool closed = false;
    bool was_enabled = false;                  // at the last step
    std::vector<SurfacePoint> held;            // grasper: held points
    std::vector<Eigen::Vector3d> held_local;   // and where, in the grasper's frame
    int suction_load = -1;                     // tube: its pressure load in the mechanical model
    InstrumentReaction reaction;
  };

 public:
  struct State {
    std::vector<Instrument> instruments;
    std::vector<Contact> contacts;
    std::vector<PressureLoad> suction;  // of the tubes, in instrument order
    Eigen::VectorXd x_stage;
    std::vector<Eigen::Isometry3d> stage_from, stage_to;
  };

 private:
  // Normal gap and tangential slips (bilateral: position error) of contact c at x (m), and
  // its frame (columns: normal, tangents).
  Eigen::Vector3d contact_rows(const Contact& c, const Eigen::VectorXd& x, Eigen::Matrix3d* frame) const;
  // A new instrument of options o in slot `in`, posed at `time`; a tube gets a pressure load.
  void place(Instrument& in, const InstrumentOptions& o, double time);
  // Instrument k's size: the length a stage may travel is a quarter of it.
  static double size(const InstrumentOptions& o);
  // The triangles that may come within `reach` of an instrument of shape o at pose at x, by a
  // bound on their distance (the distance function grows no faster than the distance).
  template <typename Visit>
  void near_triangles(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::VectorXd& x, double reach,
                      const Visit& visit) const;
  // The samples of boundary triangle t at most `spacing` apart in the rest shape (infinite: its
  // nodes), each a SurfacePoint given to visit().
  template <typename Visit>
  void sample_triangle(int t, double spacing, const Visit& visit) const;
  // The gap tolerance of the contact problem for a force tolerance (N): see direct_update.
  double gap_tolerance(double force_tolerance) const;
  // The Delassus operator of the contacts in W_, the predicted rows after the update A^-1 r in
  // delta_ and the current forces in lambda_ (contact frames); z_ = L^-1 P r.
  void contact_problem(CholmodSolver& factor, const Eigen::VectorXd& r);
  // contact_problem, then projected Gauss-Seidel to the force tolerance: the new forces in
  // lambda_ (contact frames). Returns the sweeps.
  int solve_contact_problem(CholmodSolver& factor, const Eigen::VectorXd& r, double force_tolerance);
  // The contacts' forces are an update's: kept for scale_update, gathered.
  void keep_update();
  // z_ += the forward half of the contact force changes `change` (3 per contact, world frame).
  void add_forward(const std::vector<Eigen::Vector3d>& change);

  MechanicalModel& mechanics_;
  ContactOptions options_;
  std::vector<Instrument> instruments_;
  std::vector<Eigen::Isometry3d> stage_from_, stage_to_;
  Eigen::VectorXd x_stage_;  // positions at the start of the stage: slips are measured from them
  std::vector<Contact> contacts_, contacts_next_;
  std::vector<Eigen::Vector3d> lambda_before_update_, lambda_of_update_;  // per contact
  NodeCompliance compliance_;
  long solves_ = 0;
  // Work of the contact updates, kept between them.
  std::vector<int> free_nodes_;                 // the contacts' nodes not held by the scene
  std::vector<Eigen::Vector3d> node_vector_;    // per node: E^T A^-1 r, or a force change
  std::vector<char> node_marked_;
  Eigen::VectorXd z_;
  Eigen::MatrixXd W_;
  Eigen::VectorXd delta_, lambda_;
  std::vector<char> bilateral_;
  std::vector<Eigen::Vector3d> change_;
  struct ContactUnknown {  // one force unknown of the Krylov update
    int contact;
    Eigen::Vector3d row;     // its constraint row at the point (dx . row = target)
    Eigen::Vector3d force;   // the force per unit unknown at the point
    double target;
  };
  std::vector<ContactUnknown> unknowns_;
  Eigen::MatrixXd schur_;
  // Points close together on few nodes (a shaft lying along a face) make dependent rows: the
  // least-norm solution of the Schur system.
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> schur_solver_;
  Eigen::VectorXd augmented_rhs_, augmented_solution_, augmented_dx_, augmented_out_, schur_rhs_, schur_solution_;
  Gmres gmres_;
};

}  // namespace liver_sim
