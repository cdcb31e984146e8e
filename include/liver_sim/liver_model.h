// The composite liver model: corotational tetrahedra (parenchyma) + corotational CST membranes
// on the boundary (Glisson's capsule) + corotational beams (vessels) embedded in the tetrahedra,
// in one stiffness matrix; fixed nodes, loads, and a Newton / backward-Euler solver on CHOLMOD.
// ROS-free.
//
// Vessels add no unknowns: a vessel node sits in a tetrahedron, its position is the barycentric
// interpolation of that tetrahedron's nodes and its rotation is the tetrahedron's rotation (polar
// decomposition of F), so the vessel is bonded to the tissue around it. Beam forces reach the
// tissue through J^T (J: the derivative of the beam-node positions and rotations with respect to
// the tetrahedron's nodes) and the beam stiffness as J^T K J.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/cholmod_solver.h"
#include "liver_sim/conjugate_gradient.h"
#include "liver_sim/corotational_beam.h"
#include "liver_sim/corotational_tetra.h"
#include "liver_sim/gmres.h"
#include "liver_sim/instrument.h"
#include "liver_sim/membrane_cst.h"
#include "liver_sim/mesh.h"
#include "liver_sim/scene.h"
#include "liver_sim/sparse_pattern.h"
#include "liver_sim/vessel_tree.h"

namespace liver_sim {

// Wall time of one step by phase (ms).
struct StepTiming {
  double assembly_ms = 0;       // rotation update, internal/external forces, tangent assembly
  double factorization_ms = 0;  // CHOLMOD numeric factorisations
  double solve_ms = 0;          // GMRES: triangular solves and Jacobian products
  double contact_ms = 0;        // detection, compliance columns, Delassus operator, Gauss-Seidel
  double total_ms = 0;
};

struct StepResult {
  enum class Status {
    Converged,     // residual below tolerance
    NotConverged,  // iteration cap reached closer to equilibrium; the state is kept (the next step
                   // continues from it)
    Diverged       // rolled back: non-finite values, a tangent that is not positive definite, a
                   // residual blow-up, a stall (the cap reached no closer to equilibrium than the
                   // step started), or (dynamic) mechanical energy growing beyond the work done
  };
  Status status = Status::Converged;
  int iterations = 0;         // Newton iterations (factorisations) in this step
  int linear_iterations = 0;  // GMRES iterations (preconditioned solves) in this step
  int factorizations = 0;     // numeric factorisations in this step (often 0: the factor is reused)
  int contacts = 0;           // instrument contacts carrying force at the end of the step
  int contact_sweeps = 0;     // Gauss-Seidel sweeps of the contact solves in this step
  double residual = 0;      // force residual relative to the load norm, at the end
  StepTiming timing;
  std::string message;      // why, when not converged
  bool converged() const { return status == Status::Converged; }
};

// Builds the mesh a scene asks for (box or file). Throws MeshError / SceneError.
TetMesh load_scene_mesh(const Scene& scene);

class LiverModel {
 public:
  // Precomputes element matrices, the matrix pattern, scatter maps and the CHOLMOD analysis.
  // Throws std::invalid_argument naming the problem (invalid option, region selecting nothing,
  // probe outside the mesh, a static scene with nothing fixed, a vessel file that does not load,
  // a vessel node farther outside the mesh than its snap tolerance).
  LiverModel(TetMesh mesh, const Scene& scene);

  // Static mode: Newton to equilibrium under the loads times load_scale(). Dynamic mode: one
  // backward-Euler time step of solver.dt. Both advance time() by solver.dt (in static mode a
  // pseudo-time that drives the instruments' trajectories). A diverging step restores the
  // state before it.
  StepResult step();

  // Static load continuation: loads are multiplied by this factor (default 1).
  void set_load_scale(double s) { load_scale_ = s; }
  double load_scale() const { return load_scale_; }

  // Capsule on/off, E, h, nu, region: takes effect at the next step with no mesh reload and no
  // new symbolic analysis. Returns "" on success, else the validation message (nothing changed).
  std::string set_capsule(const CapsuleOptions& capsule);
  const CapsuleOptions& capsule() const { return capsule_; }

  // Instruments (instrument.h): rigid and pose-driven, in unilateral contact with Coulomb
  // friction with the boundary nodes, or holding them (a closed grasper). The contact forces are
  // exact at convergence: each Newton iteration solves the frictional contact problem on the
  // Delassus operator W = H A^-1 H^T, with A the factorised Newton matrix (no penalty). The
  // scene's instruments are added by the constructor. add/update throw std::invalid_argument
  // naming the field at fault (validate(InstrumentOptions)); a change acts at the next step.
  int add_instrument(const InstrumentOptions& o);
  void update_instrument(int i, const InstrumentOptions& o);
  int num_instruments() const { return static_cast<int>(instruments_.size()); }
  const InstrumentOptions& instrument(int i) const { return instruments_[i].options; }
  int find_instrument(const std::string& name) const;  // -1 when there is none
  const Eigen::Isometry3d& instrument_pose(int i) const { return instruments_[i].pose; }  // at the last step
  struct InstrumentReaction {
    Eigen::Vector3d force = Eigen::Vector3d::Zero();   // N, exerted by the tissue on the instrument
    Eigen::Vector3d torque = Eigen::Vector3d::Zero();  // N m, about the instrument's tip
    int contacts = 0;                                  // nodes pressing on it or held by it
  };
  const InstrumentReaction& instrument_reaction(int i) const { return instruments_[i].reaction; }
  const ContactOptions& contact_options() const { return contact_; }
  // Work counters since construction: contact problems solved and compliance columns A^-1 e_i
  // computed. Both stay 0 while no instrument comes within the alarm distance.
  long contact_solves() const { return contact_solves_; }
  long compliance_columns() const { return compliance_columns_; }
  // Contact force on the tissue per DOF (N), from the last step.
  const Eigen::VectorXd& contact_forces() const { return contact_force_; }
  // Force the supports exert on the tissue at the scene's fixed DOFs (N; 0 elsewhere).
  Eigen::VectorXd support_forces();

  // Soft surface constraints (registration to a point cloud, registration.h): each target is a
  // zero-length spring of stiffness k (N/m) between a point fixed in space and a point on a
  // boundary triangle, given by barycentric weights (the triangle's nodes carry the force in
  // those proportions). Potential 1/2 k |P (sum_j w_j x_j - p)|^2 with P = n n^T for a unit
  // normal n (point-to-plane: the surface may slide along the plane) or P = I for n = 0
  // (point-to-point). It enters the residual and the tangent, not the load scale. Replaces the
  // previous set; throws std::invalid_argument for a triangle out of range or non-finite
  // values. Acts at the next step (refactorising when the total stiffness changed by over half);
  // reset() removes the targets.
  struct SurfaceTarget {
    int triangle = -1;                                   // row of boundary()
    Eigen::Vector3d weights = Eigen::Vector3d::Zero();   // barycentric, on the triangle's nodes
    Eigen::Vector3d point = Eigen::Vector3d::Zero();     // m
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();    // unit (point-to-plane) or zero (point-to-point)
    double stiffness = 0;                                // N/m, >= 0
  };
  void set_surface_targets(std::vector<SurfaceTarget> targets);
  const std::vector<SurfaceTarget>& surface_targets() const { return surface_targets_; }

  // The next Newton iteration factorises the matrix afresh (a retry after a step that stalled
  // on an older factor).
  void refactorize() { factor_valid_ = false; }

  // Back to the rest shape, zero velocity, time 0; parameters and instruments are kept (a
  // grasper lets go; it grasps again at the next step if it is still closed).
  void reset();

  const TetMesh& mesh() const { return mesh_; }
  const Eigen::MatrixX3i& boundary() const { return boundary_; }
  const Eigen::VectorXd& positions() const { return x_; }  // 3 #V, node-major (m)
  Eigen::VectorXd displacement() const { return x_ - X_; }
  double max_displacement() const;  // largest node displacement from the rest shape (m)
  double time() const { return time_; }
  int capsule_triangles() const;  // membrane triangles in use (0 when disabled)
  const SolverOptions& solver_options() const { return solver_; }
  // Strategy, iteration cap, tolerance, line search, dt and damping, from the next step on (the
  // same scene run fast or exact). The mode cannot change. Returns "" on success, else the
  // validation message (nothing changed).
  std::string set_solver_options(const SolverOptions& solver);

  // Vessels: beam nodes, beams (node pairs), the vessel each beam belongs to, current positions.
  int num_vessel_nodes() const { return static_cast<int>(vessel_nodes_.size()); }
  int num_beams() const { return beams_ ? beams_->size() : 0; }
  const Eigen::MatrixX2i& beam_segments() const { return beams_->segments(); }  // only when num_beams() > 0
  int beam_vessel(int e) const { return beam_vessel_[e]; }
  const std::string& vessel_name(int v) const { return vessel_names_[v]; }
  Eigen::Vector3d vessel_node_position(int k) const { return interpolate(x_, vessel_nodes_[k]); }

  int num_probes() const { return static_cast<int>(probes_.size()); }
  const std::string& probe_name(int i) const { return probes_[i].name; }
  Eigen::Vector3d probe_displacement(int i) const;
  Eigen::Vector3d probe_position(int i) const { return interpolate(x_, probes_[i].at); }

  // Internal elastic forces (tetrahedra + active membranes + beams) at state x; updates rotations.
  void internal_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f);
  // Strain energy of tetrahedra, active membranes and beams at positions x (J); updates rotations.
  double elastic_energy(const Eigen::VectorXd& x);
  // External forces at positions x (follower pressure on the current triangles), unscaled.
  void external_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;
  // Adds the surface targets' spring forces at positions x to f.
  void add_target_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;

  // Overwrites the current state (tests start from a given configuration).
  void set_positions(const Eigen::VectorXd& x) {
    x_ = x;
    state_energy_ = std::numeric_limits<double>::quiet_NaN();
  }

  const SparsePattern& pattern() const { return pattern_; }
  CholmodSolver& linear_solver() { return solver_cholmod_; }

 private:
  // A point that follows the tetrahedron containing it.
  struct EmbeddedPoint {
    int tet = -1;
    Eigen::Vector4d barycentric = Eigen::Vector4d::Zero();
  };
  struct Probe {
    std::string name;
    EmbeddedPoint at;
  };
  struct PressureLoad {
    double pressure;
    std::vector<int> triangles;  // rows of boundary_
  };
  struct NodalLoad {
    Eigen::Vector3d force;  // per node (N)
    std::vector<int> nodes;
  };

  // The tetrahedron that contains p best (largest smallest barycentric weight).
  EmbeddedPoint locate(const Eigen::Vector3d& p) const;
  Eigen::Vector3d interpolate(const Eigen::VectorXd& x, const EmbeddedPoint& q) const;
  // Loads and embeds the enabled vessel trees; returns the 8 tissue nodes each beam couples
  // (the 4 of each end's tetrahedron).
  std::vector<std::vector<int>> embed_vessels(const std::vector<VesselOptions>& vessels);
  // Host rotations and their derivatives, beam-node positions, then the beam forces.
  void add_beam_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f);
  // J of beam e: its [p_a theta_a p_b theta_b] with respect to its 8 tissue nodes.
  Eigen::Matrix<double, 12, 24> beam_mapping(int e) const;
  std::vector<int> select_nodes(const Region& r, const std::string& what) const;
  std::vector<int> select_triangles(const Region& r, const std::string& what) const;
  void set_fixed(const std::vector<int>& nodes);
  // Residual r = loads - internal - inertia - damping at x (dynamic terms use x_start_, v_).
  // Returns its free-DOF norm and the reference norm it is measured against.
  // With zero_fixed = false the entries at fixed DOFs are kept: minus the constraint forces.
  double residual(const Eigen::VectorXd& x, Eigen::VectorXd& r, double* reference, bool zero_fixed = true);
  // Line-search merit: the free residual norm and the contact violation, in newtons.
  double merit(double residual_norm, const Eigen::VectorXd& x) const;
  // Newton iterations from the current state; adds to result (iterations, timings, status).
  void newton(StepResult& result);
  // Instruments to their pose at time t; grasps and releases; the tubes' suction triangles.
  // Returns the stages the step needs: travel over a quarter of an instrument's size, each.
  int move_instruments(double t);
  // The contacts at x: nodes within the alarm distance of an instrument and held nodes, with
  // their forces carried over from the previous contacts. True when a dropped contact carried force.
  bool detect_contacts(const Eigen::VectorXd& x);
  // Normal gap and tangential slips (bilateral: position error) of contact c at x (m), and
  // its frame (columns: normal, tangents).
  Eigen::Vector3d contact_rows(int c, const Eigen::VectorXd& x, Eigen::Matrix3d* frame) const;
  // Largest violation of Signorini, sticking and holding at x with the current forces (m).
  double contact_violation(const Eigen::VectorXd& x) const;
  // The Newton update dx_ with instruments: the frictional contact problem on the Delassus
  // operator decides which contacts stick, slide or separate; then GMRES solves the Jacobian
  // system with those contact rows. Sets the contacts' forces; returns the GMRES iterations.
  int contact_update(const std::function<void(const Eigen::VectorXd&, Eigen::VectorXd&)>& jacobian, double forcing,
                     StepResult& result);
  void update_reactions();
  // Dynamic steps: the mechanical energy (kinetic + elastic) and the work of the loads and of
  // the constraints over the step that ended at x_ (J).
  double mechanical_energy(const Eigen::VectorXd& x, const Eigen::VectorXd& v);
  double work_over_step();
  // Tangent of -residual into system_ (fixed DOFs become identity rows), with the element
  // rotations of the last residual() call: the solver always assembles where it last evaluated.
  void assemble_system();

  TetMesh mesh_;
  Eigen::MatrixX3i boundary_;
  std::vector<char> on_boundary_;  // per node
  SolverOptions solver_;
  ParenchymaOptions parenchyma_;
  CapsuleOptions capsule_;
  CorotationalTetra tetra_;
  MembraneCST membrane_;               // all boundary triangles; capsule_active_ selects
  std::vector<int> capsule_active_;
  SparsePattern pattern_;
  std::vector<int> tet_map_, tri_map_, beam_map_;  // scatter maps: 144 per tetrahedron, 81 per triangle, 576 per beam
  std::vector<double> stiffness_, system_;
  int threads_ = 1;  // OpenMP threads for the element loops
  std::vector<Eigen::VectorXd> thread_forces_;            // per thread but the first
  std::vector<std::vector<double>> thread_stiffness_;
  // The stiffness K of the state a dynamic step starts from, for its Rayleigh damping b K v:
  // what the element products need (tetrahedron rotations, membrane frames, beam tangents and
  // their mappings), not the assembled matrix.
  struct DampingSnapshot {
    std::vector<Eigen::Matrix3d> tet_rotation;
    std::vector<Eigen::Matrix<double, 3, 2>> membrane_frame;
    std::vector<Matrix12d> beam_tangent;
    std::vector<Eigen::Matrix<double, 12, 24>> beam_mapping;
  } damping_;
  void snapshot_damping();
  // K v with the snapshot's stiffness (N per m/s of v).
  void damping_forces(const Eigen::VectorXd& v, Eigen::VectorXd& f);
  std::vector<int> fixed_entries_;      // off-diagonal values in fixed rows/columns
  std::vector<int> scene_fixed_nodes_;
  std::vector<char> fixed_by_scene_;  // per node
  std::vector<int> boundary_nodes_;
  struct Instrument {
    InstrumentOptions options;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();        // at the end of the step
    Eigen::Isometry3d pose_start = Eigen::Isometry3d::Identity();  // at its start
    bool closed = false;
    bool was_enabled = false;                  // at the last step
    std::vector<int> held;                     // grasper: held nodes
    std::vector<Eigen::Vector3d> held_local;   // and where, in the grasper's frame
    int suction_load = -1;                     // tube: its entry of pressures_
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
  std::vector<Instrument> instruments_;
  std::vector<Eigen::Isometry3d> stage_from_, stage_to_;
  Eigen::VectorXd x_stage_;  // positions at the start of the stage: slips are measured from them
  ContactOptions contact_;
  std::vector<Contact> contacts_, contacts_next_;
  Eigen::VectorXd contact_force_, contact_force_start_;  // per DOF (N), now and at the step's start
  std::vector<int> compliance_slot_;  // per node: its 3 columns in compliance_, or -1
  Eigen::MatrixXd compliance_;        // A^-1 columns of contact nodes, for factor compliance_factor_
  std::vector<int> compliance_nodes_; // nodes stored, by slot
  int compliance_factor_ = -1;
  long contact_solves_ = 0, compliance_columns_ = 0;
  Eigen::MatrixXd delassus_, rhs_columns_, new_columns_;
  Eigen::VectorXd contact_delta_, contact_lambda_;
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
  std::vector<char> fixed_dof_, fixed_next_;
  bool factor_valid_ = false;  // the factor preconditions the current constraint set and material
  CholmodSolver solver_cholmod_;

  Eigen::VectorXd X_, x_, v_, x_start_;
  Eigen::VectorXd v_previous_;  // velocity of the step before the last (the predictor's acceleration)
  bool rotations_continued_ = false;  // the last step predicted the rotations and was accepted
  Eigen::VectorXd mass_;  // lumped, per DOF (kg)
  std::vector<PressureLoad> pressures_;
  std::vector<NodalLoad> nodal_loads_;  // spread forces
  Eigen::Vector3d gravity_ = Eigen::Vector3d::Zero();  // m/s^2, acting on the lumped masses
  std::vector<Probe> probes_;
  std::vector<SurfaceTarget> surface_targets_;
  std::vector<EmbeddedPoint> vessel_nodes_;
  std::optional<CorotationalBeams> beams_;
  std::vector<int> beam_vessel_;
  std::vector<std::string> vessel_names_;
  // Tetrahedra that host vessel nodes: index per tetrahedron (-1: none), and per host its current
  // polar rotation and rotation derivative (3 x 12: d theta / d x) from the last force call.
  std::vector<int> host_index_;
  std::vector<int> hosts_;
  std::vector<Eigen::Matrix3d> host_rotation_;
  std::vector<Eigen::Matrix<double, 3, 12>> host_rotation_derivative_;
  std::vector<Eigen::Matrix3d> vessel_rotation_;  // per vessel node: its host's rotation
  Eigen::VectorXd vessel_positions_;
  double load_scale_ = 1.0;
  double state_energy_ = std::numeric_limits<double>::quiet_NaN();
  Eigen::VectorXd rotations_at_, internal_at_;  // the last internal_forces call: positions (whose rotations are current) and forces
  double tissue_energy_at_ = 0;  // and the strain energy of its tetrahedra and membranes (J)
  std::vector<double> thread_energy_;  // J, of (x_, v_) when known
  double time_ = 0.0;
  double force_floor_;   // residual (N) below which a state counts as converged: round-off, 1e-12 E L^2
  double length_scale_;  // bounding-box diagonal (m)
  Gmres gmres_;
  ConjugateGradient cg_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Upper> eigen_ldlt_;
  bool eigen_analyzed_ = false;
  Eigen::VectorXd jacobi_;  // inverse diagonal of system_ (CG strategy)

  // Work vectors kept between steps (no allocation per step).
  Eigen::VectorXd r_, r_try_, dx_, x_try_, f_tmp_, v_tmp_, f_ext_, energy_work_;
};

}  // namespace liver_sim
