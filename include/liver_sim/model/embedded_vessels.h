// Vessels embedded in the parenchyma (SOFA's vocabulary: a beam force field behind a barycentric
// mapping), and the embedded points the model reports (probes, vessel nodes). Part of the
// mechanical model (mechanical_model.h); ROS-free.
//
// Vessels add no unknowns: a vessel node sits in a tetrahedron, its position is the barycentric
// interpolation of that tetrahedron's nodes and its rotation is the tetrahedron's rotation (polar
// decomposition of F), so the vessel is bonded to the tissue around it. Beam forces reach the
// tissue through J^T (J: the derivative of the beam-node positions and rotations with respect to
// the tetrahedron's nodes) and the beam stiffness as J^T K J.
//
// It reads the tetrahedra (their rotations and rest shapes) and nothing else of the model; it
// holds no solver state.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/model/corotational_beam.h"
#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

// A point that follows the tetrahedron containing it.
struct EmbeddedPoint {
  int tet = -1;
  Eigen::Vector4d barycentric = Eigen::Vector4d::Zero();
};

// The tetrahedron of T that contains p best (largest smallest barycentric weight), by the rest
// shape of `tetra`.
EmbeddedPoint locate(const CorotationalTetra& tetra, const Eigen::MatrixX3d& X, const Eigen::Vector3d& p);
// The point's position for node positions x (3 #V, node-major).
Eigen::Vector3d interpolate(const Eigen::MatrixX4i& T, const Eigen::VectorXd& x, const EmbeddedPoint& q);

class EmbeddedVessels {
 public:
  // Loads and embeds the enabled trees in the tetrahedra of `tetra` (rest positions X). Throws
  // std::invalid_argument naming the vessel: invalid options, a file that does not load, a node
  // farther outside the mesh than its snap tolerance.
  // `trees`: the centre lines of `vessels`, one per entry in order (a disabled vessel's is not
  // read). Throws std::invalid_argument when their counts differ.
  EmbeddedVessels(const CorotationalTetra& tetra, const Eigen::MatrixX3d& X, const std::vector<VesselOptions>& vessels,
                  const std::vector<VesselTree>& trees, RotationMethod rotation);

  // Per beam, the 8 tissue nodes it couples (the 4 of each end's tetrahedron): the pattern's groups.
  const std::vector<std::vector<int>>& coupled_nodes() const { return coupled_; }

  // Host rotations and their derivatives, beam-node positions and frames at x, then the beam
  // forces added to f. The tetrahedra's rotations must be those of x (polar parenchyma reuses them).
  void add_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f);
  // Strain energy of beam e at the last add_forces (J).
  double beam_energy(int e) const { return beams_->element_energy(e); }
  // Adds each beam's J^T K J, from the last add_forces, into `values` through the scatter maps
  // (576 per beam).
  void add_tangent(const std::vector<int>& scatter_map, std::vector<double>& values) const;
  // The beams' stiffness at the last add_forces, kept for the damping products.
  void snapshot_damping();
  // Adds K v with the snapshot's stiffness to f.
  void add_damping_forces(const Eigen::VectorXd& v, Eigen::VectorXd& f) const;

  bool empty() const { return !beams_; }
  int num_nodes() const { return static_cast<int>(nodes_.size()); }
  int num_beams() const { return beams_ ? beams_->size() : 0; }
  const Eigen::MatrixX2i& segments() const { return beams_->segments(); }  // only when num_beams() > 0
  int beam_vessel(int e) const { return beam_vessel_[e]; }
  const std::string& vessel_name(int v) const { return names_[v]; }
  Eigen::Vector3d node_position(const Eigen::VectorXd& x, int k) const { return interpolate(T_, x, nodes_[k]); }

 private:
  // J of beam e: its [p_a theta_a p_b theta_b] with respect to its 8 tissue nodes.
  Eigen::Matrix<double, 12, 24> mapping(int e) const;

  const CorotationalTetra& tetra_;
  const Eigen::MatrixX4i& T_;
  RotationMethod rotation_;
  std::vector<EmbeddedPoint> nodes_;
  std::optional<CorotationalBeams> beams_;
  std::vector<int> beam_vessel_;
  std::vector<std::string> names_;
  std::vector<std::vector<int>> coupled_;
  // Tetrahedra that host vessel nodes: index per tetrahedron (-1: none), and per host its current
  // polar rotation and rotation derivative (3 x 12: d theta / d x) from the last force call.
  std::vector<int> host_index_;
  std::vector<int> hosts_;
  std::vector<Eigen::Matrix3d> host_rotation_;
  std::vector<Eigen::Matrix<double, 3, 12>> host_rotation_derivative_;
  std::vector<Eigen::Matrix3d> node_rotation_;  // per vessel node: its host's rotation
  Eigen::VectorXd node_positions_;
  struct DampingSnapshot {
    std::vector<Matrix12d> tangent;
    std::vector<Eigen::Matrix<double, 12, 24>> mapping;
  } damping_;
};

}  // namespace liver_sim
