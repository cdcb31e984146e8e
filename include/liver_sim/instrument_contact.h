// Contact between the tissue and rigid instruments (instrument.h), ROS-free: the instruments
// (poses, trajectories, staging of large moves, grasping, the tubes' suction), contact detection
// against the surface nodes, the contact rows, the compliance (Delassus) operator from the
// stepper's factor, the frictional contact problem (contact_solver.h), the constrained Newton
// update and the reactions on each instrument.
//
// It reads the mechanical model's surface and supports and sets only its tubes' suction loads;
// the stepper hands it the factor, the Jacobian and the residual of the iteration. It may not
// touch the Newton loop, the element sets or the factorisation.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <string>
#include <vector>

#include "liver_sim/cholmod_solver.h"
#include "liver_sim/gmres.h"
#include "liver_sim/instrument.h"
#include "liver_sim/mechanical_model.h"

namespace liver_sim {

struct InstrumentReaction {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();   // N, exerted by the tissue on the instrument
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();  // N m, about the instrument's tip
  int contacts = 0;                                  // nodes pressing on it or held by it
};

class InstrumentContact {
 public:
  // Throws std::invalid_argument for invalid options (validate(ContactOptions)).
  InstrumentContact(MechanicalModel& mechanics, const ContactOptions& options);

  // Instruments are rigid and pose-driven, in unilateral contact with Coulomb friction with the
  // boundary nodes, or holding them (a closed grasper). add/update throw std::invalid_argument
  // naming the field at fault (validate(InstrumentOptions)); a change acts at the next step.
  // `time` places an instrument with a trajectory.
  int add_instrument(const InstrumentOptions& o, double time);
  void update_instrument(int i, const InstrumentOptions& o);
  int num_instruments() const { return static_cast<int>(instruments_.size()); }
  const InstrumentOptions& instrument(int i) const { return instruments_[i].options; }
  int find_instrument(const std::string& name) const;  // -1 when there is none
  const Eigen::Isometry3d& pose(int i) const { return instruments_[i].pose; }  // at the last step
  const InstrumentReaction& reaction(int i) const { return instruments_[i].reaction; }
  const ContactOptions& options() const { return options_; }
  // Contact force on the tissue per DOF (N), from the last step.
  const Eigen::VectorXd& forces() const { return force_; }
  // Work counters since construction: contact problems solved and compliance columns A^-1 e_i
  // computed. Both stay 0 while no instrument comes within the alarm distance.
  long solves() const { return solves_; }
  long compliance_columns() const { return compliance_columns_; }

  // A step, as the stepper drives it:
  //   begin_step(t, x)              instruments to their pose at time t; returns the stages the
  //                                 step needs (an instrument moving more than a quarter of its
  //                                 size, or appearing, is moved there in stages, each solved,
  //                                 so that no node is caught deep inside it)
  //   begin_stage(k, stages, x)     the poses of stage k (1-based); slips are measured from x
  //   detect(x), violation(x), newton_update(...) within the Newton iterations
  //   end_step(rolled_back, x)      the forces of the step's start again when it was rolled
  //                                 back; the reactions at x
  int begin_step(double t, const Eigen::VectorXd& x);
  void begin_stage(int k, int stages, const Eigen::VectorXd& x);
  // The contacts at x: nodes within the alarm distance of an instrument and held nodes, with
  // their forces carried over from the previous contacts. True when a dropped contact carried force.
  bool detect(const Eigen::VectorXd& x);
  bool active() const { return !contacts_.empty(); }
  // Largest violation of Signorini, sticking and holding at x with the current forces (m).
  double violation(const Eigen::VectorXd& x) const;
  // The Newton update dx with contacts: the frictional contact problem on the Delassus operator
  // W = H A^-1 H^T (A: the factorised matrix) decides which contacts stick, slide or separate;
  // then GMRES solves the Jacobian system with those contact rows, with residual r (the free
  // forces plus the current contact forces). Sets the contacts' forces.
  struct Update {
    int krylov = 0;                // GMRES iterations
    double relative_residual = 0;  // GMRES's at the end
    int sweeps = 0;                // Gauss-Seidel sweeps
  };
  Update newton_update(CholmodSolver& factor, const Gmres::Operator& jacobian, const Eigen::VectorXd& r,
                       double forcing, Eigen::VectorXd& dx);
  void end_step(bool rolled_back, const Eigen::VectorXd& x);
  int loaded_contacts() const;  // contacts carrying force

  // No contact, no force; graspers let go (they grasp again at the next step if still closed).
  void reset();

 private:
  struct Instrument {
    InstrumentOptions options;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();        // at the end of the step
    Eigen::Isometry3d pose_start = Eigen::Isometry3d::Identity();  // at its start
    bool closed = false;
    bool was_enabled = false;                  // at the last step
    std::vector<int> held;                     // grasper: held nodes
    std::vector<Eigen::Vector3d> held_local;   // and where, in the grasper's frame
    int suction_load = -1;                     // tube: its pressure load in the mechanical model
    InstrumentReaction reaction;
  };
  struct Contact {
    int instrument;
    int node;
    bool bilateral;
    Eigen::Matrix3d frame;  // columns: normal, tangent, tangent (bilateral: identity)
    Eigen::Vector3d rows;   // contact_rows at the current iterate
    Eigen::Vector3d force;  // N on the tissue node, world frame
  };
  // Normal gap and tangential slips (bilateral: position error) of contact c at x (m), and
  // its frame (columns: normal, tangents).
  Eigen::Vector3d contact_rows(int c, const Eigen::VectorXd& x, Eigen::Matrix3d* frame) const;

  MechanicalModel& mechanics_;
  ContactOptions options_;
  std::vector<Instrument> instruments_;
  std::vector<Eigen::Isometry3d> stage_from_, stage_to_;
  Eigen::VectorXd x_stage_;  // positions at the start of the stage: slips are measured from them
  std::vector<Contact> contacts_, contacts_next_;
  Eigen::VectorXd force_, force_start_;  // per DOF (N), now and at the step's start
  std::vector<int> compliance_slot_;  // per node: its 3 columns in compliance_, or -1
  Eigen::MatrixXd compliance_;        // A^-1 columns of contact nodes, for factor compliance_factor_
  std::vector<int> compliance_nodes_; // nodes stored, by slot
  int compliance_factor_ = -1;
  long solves_ = 0, compliance_columns_ = 0;
  Eigen::MatrixXd delassus_, rhs_columns_, new_columns_;
  Eigen::VectorXd free_dx_, contact_delta_, contact_lambda_;
  std::vector<char> contact_bilateral_;
  std::vector<int> missing_nodes_;
  struct ContactUnknown {  // one force unknown of the Newton update with contacts
    int contact;
    Eigen::Vector3d row;     // its constraint row at the node (dx . row = target)
    Eigen::Vector3d force;   // the force per unit unknown on the node
    double target;
  };
  std::vector<ContactUnknown> unknown_rows_;
  Eigen::MatrixXd schur_;
  Eigen::PartialPivLU<Eigen::MatrixXd> schur_lu_;
  Eigen::VectorXd augmented_rhs_, augmented_solution_, augmented_dx_, augmented_out_, schur_rhs_, schur_solution_;
  Gmres gmres_;
};

}  // namespace liver_sim
