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
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/cholmod_solver.h"
#include "liver_sim/corotational_beam.h"
#include "liver_sim/corotational_tetra.h"
#include "liver_sim/gmres.h"
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
  // backward-Euler time step of solver.dt. A diverging step restores the state before it.
  StepResult step();

  // Static load continuation: loads are multiplied by this factor (default 1).
  void set_load_scale(double s) { load_scale_ = s; }
  double load_scale() const { return load_scale_; }

  // Capsule on/off, E, h, nu, region: takes effect at the next step with no mesh reload and no
  // new symbolic analysis. Returns "" on success, else the validation message (nothing changed).
  std::string set_capsule(const CapsuleOptions& capsule);
  const CapsuleOptions& capsule() const { return capsule_; }

  // A rigid sphere probe (centre and radius in m) in sticking contact with the boundary: at each
  // step the boundary nodes inside it are moved onto its surface (along their inward normal) and
  // held there, and nodes the probe would have to pull are released (exact constraint forces,
  // no penalty; the frictional NLCP contact of the instruments replaces it). Throws
  // std::invalid_argument for a non-finite centre or a radius <= 0.
  void set_sphere_probe(const Eigen::Vector3d& centre, double radius);
  void remove_sphere_probe();
  struct ProbeReaction {
    Eigen::Vector3d force = Eigen::Vector3d::Zero();   // N, exerted by the tissue on the probe
    Eigen::Vector3d torque = Eigen::Vector3d::Zero();  // N m, about the sphere centre
    int contacts = 0;                                  // nodes held by the probe
  };
  const ProbeReaction& probe_reaction() const { return probe_reaction_; }

  // Back to the rest shape, zero velocity, time 0; parameters are kept (a probe stays set but
  // holds nothing until the next step).
  void reset();

  const TetMesh& mesh() const { return mesh_; }
  const Eigen::MatrixX3i& boundary() const { return boundary_; }
  const Eigen::VectorXd& positions() const { return x_; }  // 3 #V, node-major (m)
  Eigen::VectorXd displacement() const { return x_ - X_; }
  double max_displacement() const;  // largest node displacement from the rest shape (m)
  double time() const { return time_; }
  int capsule_triangles() const;  // membrane triangles in use (0 when disabled)
  const SolverOptions& solver_options() const { return solver_; }

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

  // Internal elastic forces (tetrahedra + active membranes + beams) at state x; updates rotations.
  void internal_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f);
  // Strain energy of tetrahedra, active membranes and beams at positions x (J); updates rotations.
  double elastic_energy(const Eigen::VectorXd& x);
  // External forces at positions x (follower pressure on the current triangles), unscaled.
  void external_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;

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
  // Line-search merit: the free residual norm and the gap to prescribed positions, in newtons.
  double merit(double residual_norm, const Eigen::VectorXd& x) const;
  // Newton iterations from the current state; adds to result (iterations, timings, status).
  void newton(StepResult& result);
  void update_contacts();
  bool release_tensile_contacts();  // true when a node was released
  void update_probe_reaction();
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
  std::vector<double> damping_stiffness_;  // K at the start of a dynamic step (Rayleigh b K)
  std::vector<int> fixed_entries_;      // off-diagonal values in fixed rows/columns
  std::vector<int> scene_fixed_nodes_;
  std::vector<char> fixed_by_scene_;  // per node
  std::vector<int> boundary_nodes_;
  struct SphereProbe {
    Eigen::Vector3d centre;
    double radius;
  };
  std::optional<SphereProbe> probe_;
  std::vector<int> contact_nodes_;
  std::vector<int> constrained_nodes_;  // work vector of update_contacts: scene-fixed + contacts
  Eigen::VectorXd node_normal_;  // work vector of update_contacts
  std::vector<char> released_;  // per node, within the current step
  ProbeReaction probe_reaction_;
  std::vector<char> fixed_dof_, fixed_next_;
  bool factor_valid_ = false;  // the factor preconditions the current constraint set and material
  CholmodSolver solver_cholmod_;

  Eigen::VectorXd X_, x_, v_, x_start_;
  Eigen::VectorXd target_;  // prescribed positions of fixed DOFs (rest, or on the probe)
  Eigen::VectorXd mass_;  // lumped, per DOF (kg)
  std::vector<PressureLoad> pressures_;
  std::vector<NodalLoad> nodal_loads_;  // spread forces
  Eigen::Vector3d gravity_ = Eigen::Vector3d::Zero();  // m/s^2, acting on the lumped masses
  std::vector<Probe> probes_;
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
  double state_energy_ = std::numeric_limits<double>::quiet_NaN();  // J, of (x_, v_) when known
  double time_ = 0.0;
  double force_floor_;   // residual (N) below which a state counts as converged: round-off, 1e-12 E L^2
  double length_scale_;  // bounding-box diagonal (m)
  Gmres gmres_;

  // Work vectors kept between steps (no allocation per step).
  Eigen::VectorXd r_, r_try_, dx_, x_try_, f_tmp_, v_tmp_, f_ext_, energy_work_;
};

}  // namespace liver_sim
