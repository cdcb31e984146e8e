// The mechanical model of the composite liver: the force fields (corotational tetrahedra for the
// parenchyma, corotational CST membranes on the boundary for Glisson's capsule, beams for the
// vessels through their embedding), the loads (follower pressure, gravity, spread forces), the
// surface springs of the registration, the supports and the lumped mass. It gives the forces,
// the tangent, the strain energy and the damping products of a state x; ROS-free.
//
// It holds no solver state: no positions or velocities of its own, no time, no factor. What it
// caches (the element rotations of the last evaluation, which warm-start the next polar
// iterations, and that evaluation's forces) changes no result beyond round-off. It may not
// touch the stepper (newton_stepper.h), the contact (instrument_contact.h) or a linear solver.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/model/embedded_vessels.h"
#include "liver_sim/model/membrane_cst.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/scene/scene.h"
#include "liver_sim/linalg/sparse_pattern.h"
#include "liver_sim/runtime/worker_pool.h"

namespace liver_sim {

// A soft surface constraint (registration to a point cloud, registration.h): a zero-length
// spring of stiffness k (N/m) between a point fixed in space and a point on a boundary triangle,
// given by barycentric weights (the triangle's nodes carry the force in those proportions).
// Potential 1/2 k |P (sum_j w_j x_j - p)|^2 with P = n n^T for a unit normal n (point-to-plane:
// the surface may slide along the plane) or P = I for n = 0 (point-to-point).
struct SurfaceTarget {
  int triangle = -1;                                   // row of boundary()
  Eigen::Vector3d weights = Eigen::Vector3d::Zero();   // barycentric, on the triangle's nodes
  Eigen::Vector3d point = Eigen::Vector3d::Zero();     // m
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();    // unit (point-to-plane) or zero (point-to-point)
  double stiffness = 0;                                // N/m, >= 0
  // The directions the spring pulls along: n n^T (point-to-plane) or the identity.
  Eigen::Matrix3d projector() const {
    return normal.isZero(0.0) ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(normal * normal.transpose());
  }
  // P (sum_j w_j x_j - p) at positions x (m): the stretch the spring resists; its force on the
  // surface point is -stiffness times it, its energy 1/2 stiffness |stretch|^2.
  Eigen::Vector3d stretch(const Eigen::VectorXd& x, const Eigen::MatrixX3i& boundary) const {
    Eigen::Vector3d gap = -point;
    for (int j = 0; j < 3; ++j) gap += weights[j] * x.segment<3>(3 * boundary(triangle, j));
    return normal.isZero(0.0) ? gap : Eigen::Vector3d(normal * normal.dot(gap));
  }
};

// Follower pressure on boundary triangles (Pa, > 0 pushes inward).
struct PressureLoad {
  double pressure = 0;
  std::vector<int> triangles;  // rows of boundary()
};

class MechanicalModel {
 public:
  // Precomputes element matrices, the matrix pattern and its scatter maps. Throws
  // std::invalid_argument naming the problem (invalid option, region selecting nothing, probe
  // outside the mesh, a static scene with nothing fixed, a vessel that does not embed).
  // `vessel_trees`: the centre lines of scene.vessels, one per entry (io/scene_files.h reads them).
  MechanicalModel(TetMesh mesh, const Scene& scene, const std::vector<VesselTree>& vessel_trees);
  MechanicalModel(const MechanicalModel&) = delete;
  MechanicalModel& operator=(const MechanicalModel&) = delete;

  const TetMesh& mesh() const { return mesh_; }
  const Eigen::MatrixX3i& boundary() const { return boundary_; }
  const std::vector<int>& boundary_nodes() const { return boundary_nodes_; }
  const Eigen::VectorXd& rest_positions() const { return X_; }  // 3 #V, node-major (m)
  const Eigen::VectorXd& mass() const { return mass_; }          // lumped, per DOF (kg)
  const std::vector<char>& fixed_dofs() const { return fixed_dof_; }
  bool fixed_by_scene(int node) const { return fixed_by_scene_[node]; }
  const ParenchymaOptions& parenchyma() const { return parenchyma_; }
  const SparsePattern& pattern() const { return pattern_; }
  // The threads of the element loops (solver.threads): forces, damping products, membrane frames.
  WorkerPool& workers() { return workers_; }
  double length_scale() const { return length_scale_; }  // bounding-box diagonal (m)
  // Residual (N) below which a state counts as converged: round-off, 1e-12 E L^2.
  double force_floor() const { return force_floor_; }

  // Internal elastic forces (tetrahedra + active membranes + beams) at state x; updates the
  // rotations. The last evaluation is kept: the same x again costs a copy.
  void internal_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f);
  // Strain energy of tetrahedra, active membranes and beams at positions x (J).
  double elastic_energy(const Eigen::VectorXd& x);
  // External forces at positions x (follower pressure on the current triangles), unscaled.
  void external_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;
  // Adds the registration's forces to f: the surface springs' at positions x and the surface
  // loads.
  void add_target_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;
  // The values (in pattern()) of k K + m M + the springs' stiffness, K the tangent at the last
  // internal_forces call and M the lumped mass, with identity rows and columns at the supports.
  void assemble(double k, double m, std::vector<double>& values);

  // Rayleigh damping b K v with the stiffness of one state: snapshot_damping(x) keeps what the
  // element products need (tetrahedron rotations, membrane frames, beam tangents and mappings)
  // at x; damping_forces(v) gives K v with it (N per m/s), without an assembled matrix.
  void snapshot_damping(const Eigen::VectorXd& x);
  void damping_forces(const Eigen::VectorXd& v, Eigen::VectorXd& f);

  // True when the element rotations are those of x (the last evaluation was at x).
  bool evaluated_at(const Eigen::VectorXd& x) const { return rotations_at_.size() == x.size() && rotations_at_ == x; }
  // The tetrahedra's next polar iterations start from their rotations continued at constant
  // angular velocity (CorotationalTetra::predict_rotations).
  void predict_rotations(bool continued) { tetra_.predict_rotations(continued); }

  // Capsule on/off, E, h, nu, region, with no mesh reload and no new pattern. Returns "" on
  // success, else the validation message (nothing changed).
  std::string set_capsule(const CapsuleOptions& capsule);
  const CapsuleOptions& capsule() const { return capsule_; }
  int capsule_triangles() const;  // membrane triangles in use (0 when disabled)

  // A factor on the whole tissue's stiffness (parenchyma, capsule, vessels: forces, tangent,
  // energy, damping), as if every Young's modulus were multiplied by it: the registration's
  // estimate of a patient stiffer or softer than the scene (registration.h). Default 1; must be
  // finite and > 0 (std::invalid_argument).
  void set_stiffness_scale(double s);
  double stiffness_scale() const { return stiffness_scale_; }

  // A pressure load for a part that sets it step by step (an aspiration tube's suction); its
  // index for pressure_load().
  int add_pressure_load();
  PressureLoad& pressure_load(int i) { return pressures_[i]; }
  const PressureLoad& pressure_load(int i) const { return pressures_[i]; }
  int num_pressure_loads() const { return static_cast<int>(pressures_.size()); }

  // Replaces the surface springs; throws std::invalid_argument for a triangle out of range or
  // non-finite values.
  void set_surface_targets(std::vector<SurfaceTarget> targets);
  const std::vector<SurfaceTarget>& surface_targets() const { return surface_targets_; }
  double spring_stiffness() const;  // sum over the springs (N/m)
  // Replaces the surface loads: dead nodal forces (N, 3 #V, or empty: none) the registration
  // found on the surface the camera does not see. Throws std::invalid_argument for a wrong size
  // or a non-finite value.
  void set_surface_loads(Eigen::VectorXd loads);
  const Eigen::VectorXd& surface_loads() const { return surface_loads_; }

  // Back to the rest rotations (identity guesses), no springs and no surface loads.
  void reset();

  // What a step leaves behind here: the element rotations with the polar iterations' warm
  // starts, the membranes' frames, the last evaluation (its point, forces, energy) and the
  // damping snapshot. The stepper saves it before a step and restores it when the step is rolled
  // back; the vessels' beams are then evaluated again at the restored point with the restored
  // rotations (the same bits: they keep no iteration state), their damping snapshot is the
  // step's start's.
  struct EvaluationState {
    CorotationalTetra::RotationState tetra;
    std::vector<Eigen::Matrix<double, 3, 2>> membrane_frames;
    Eigen::VectorXd rotations_at, internal_at;
    double tissue_energy_at = 0;
    std::vector<Eigen::Matrix3d> damping_rotations;
    std::vector<Eigen::Matrix<double, 3, 2>> damping_frames;
  };
  void save(EvaluationState& s) const;
  void restore(const EvaluationState& s);
  const CorotationalTetra& tetrahedra() const { return tetra_; }  // rotations and warm starts, for tests

  // Tracked points of the scene (probes), vessels.
  int num_probes() const { return static_cast<int>(probes_.size()); }
  const std::string& probe_name(int i) const { return probes_[i].name; }
  Eigen::Vector3d probe_position(const Eigen::VectorXd& x, int i) const { return interpolate(mesh_.T, x, probes_[i].at); }
  const EmbeddedVessels& vessels() const { return vessels_; }

 private:
  struct Probe {
    std::string name;
    EmbeddedPoint at;
  };
  struct NodalLoad {
    Eigen::Vector3d force;  // per node (N)
    std::vector<int> nodes;
  };
  std::vector<int> select_nodes(const Region& r, const std::string& what) const;
  std::vector<int> select_triangles(const Region& r, const std::string& what) const;
  void set_fixed(const std::vector<int>& nodes);
  // f (of `size`) = the sum over the tetrahedra, four at a time, and the active membranes of the
  // element vectors tet_block(first, count, fe) and triangle(t, fm) write; returns the sum of
  // what they return (an energy). The same bits for any thread count (see element_vectors_).
  template <typename TetBlock, typename Triangle>
  double element_pass(Eigen::Index size, Eigen::VectorXd& f, const TetBlock& tet_block, const Triangle& triangle);
  // For each node, where its 3-blocks lie in the element vectors (offsets in doubles), in
  // element order.
  struct NodeGather {
    std::vector<int> start;  // per node, into slot; one past the last node at the end
    std::vector<int> slot;
  };
  TetMesh mesh_;
  Eigen::MatrixX3i boundary_;
  std::vector<char> on_boundary_;  // per node
  ParenchymaOptions parenchyma_;
  CapsuleOptions capsule_;
  CorotationalTetra tetra_;
  MembraneCST membrane_;  // all boundary triangles; capsule_active_ selects
  std::vector<int> capsule_active_;
  EmbeddedVessels vessels_;
  SparsePattern pattern_;
  std::vector<int> tet_map_, tri_map_, beam_map_;  // scatter maps: 144 per tetrahedron, 81 per triangle, 576 per beam
  std::vector<double> stiffness_;
  WorkerPool workers_;
  // With more than one thread, element_pass writes every element's vector and every tetrahedron
  // block's energy here, then adds them per node (and the energies) in the order in which one
  // thread adds as it goes: the result is that of one thread, to the last bit.
  struct ElementVectors {
    std::vector<Vector12d> tet;
    std::vector<Vector9d> membrane;  // per capsule_active_ entry
    std::vector<double> block_energy, membrane_energy;
    NodeGather tet_gather, membrane_gather;
  } element_vectors_;
  struct DampingSnapshot {
    std::vector<Eigen::Matrix3d> tet_rotation;
    std::vector<Eigen::Matrix<double, 3, 2>> membrane_frame;
  } damping_;
  std::vector<char> fixed_dof_;      // per DOF
  std::vector<int> fixed_entries_;   // off-diagonal values in fixed rows/columns
  std::vector<char> fixed_by_scene_;  // per node
  std::vector<int> boundary_nodes_;
  Eigen::VectorXd X_;
  Eigen::VectorXd mass_;
  std::vector<PressureLoad> pressures_;
  std::vector<NodalLoad> nodal_loads_;  // spread forces
  Eigen::Vector3d gravity_ = Eigen::Vector3d::Zero();  // m/s^2, acting on the lumped masses
  std::vector<Probe> probes_;
  std::vector<SurfaceTarget> surface_targets_;
  Eigen::VectorXd surface_loads_;
  // The last internal_forces call: positions (whose rotations are current) and forces, and the
  // strain energy of its tetrahedra and membranes (J).
  Eigen::VectorXd rotations_at_, internal_at_;
  double tissue_energy_at_ = 0;
  Eigen::VectorXd energy_work_;
  double force_floor_ = 0;
  double length_scale_ = 0;
  double stiffness_scale_ = 1;
};

}  // namespace liver_sim
