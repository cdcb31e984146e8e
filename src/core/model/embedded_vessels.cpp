#include "liver_sim/model/embedded_vessels.h"

#include <limits>
#include <sstream>
#include <stdexcept>

#include "liver_sim/linalg/sparse_pattern.h"

namespace liver_sim {

EmbeddedPoint locate(const CorotationalTetra& tetra, const Eigen::MatrixX3d& X, const Eigen::Vector3d& p) {
  const Eigen::MatrixX4i& T = tetra.elements();
  EmbeddedPoint best;
  double best_min = -std::numeric_limits<double>::infinity();
  for (int e = 0; e < T.rows(); ++e) {
    const Eigen::Vector3d w = tetra.rest_edge_inverse(e) * (p - X.row(T(e, 0)).transpose());
    const Eigen::Vector4d b(1 - w.sum(), w[0], w[1], w[2]);
    if (b.minCoeff() > best_min) {
      best_min = b.minCoeff();
      best = {e, b};
    }
  }
  return best;
}

Eigen::Vector3d interpolate(const Eigen::MatrixX4i& T, const Eigen::VectorXd& x, const EmbeddedPoint& q) {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) p += q.barycentric[k] * x.segment<3>(3 * T(q.tet, k));
  return p;
}

EmbeddedVessels::EmbeddedVessels(const CorotationalTetra& tetra, const Eigen::MatrixX3d& X,
                                 const std::vector<VesselOptions>& vessels, const std::vector<VesselTree>& trees,
                                 RotationMethod rotation)
    : tetra_(tetra), T_(tetra.elements()), rotation_(rotation) {
  if (trees.size() != vessels.size()) throw std::invalid_argument("one vessel tree per vessel is needed");
  Eigen::VectorXd rest_x(3 * X.rows());
  for (int i = 0; i < X.rows(); ++i) rest_x.segment<3>(3 * i) = X.row(i).transpose();
  std::vector<Eigen::Vector3d> rest;
  std::vector<Eigen::Vector2i> segments;
  std::vector<BeamSection> sections;
  for (size_t k = 0; k < vessels.size(); ++k) {
    const VesselOptions& v = vessels[k];
    const std::string error = validate(v);
    if (!error.empty()) throw std::invalid_argument(error);
    if (!v.enabled) continue;
    const std::string what = "vessels." + v.name;
    const VesselTree& tree = trees[k];
    const int base = num_nodes();
    for (int i = 0; i < tree.points.rows(); ++i) {
      const Eigen::Vector3d p = tree.points.row(i).transpose();
      EmbeddedPoint at = locate(tetra, X, p);
      if (at.barycentric.minCoeff() < 0) {
        // Outside the faceted surface: onto the nearest point of the best tetrahedron's span
        // (clamped weights), if that is within the tolerance.
        at.barycentric = at.barycentric.cwiseMax(0.0);
        at.barycentric /= at.barycentric.sum();
        const double gap = (interpolate(T_, rest_x, at) - p).norm();
        if (gap > v.snap_tolerance) {
          std::ostringstream m;
          m << what << ": node " << i << " at (" << p.transpose() << ") m lies " << gap * 1e3
            << " mm outside the mesh (snap_tolerance " << v.snap_tolerance * 1e3 << " mm)";
          throw std::invalid_argument(m.str());
        }
      }
      nodes_.push_back(at);
      rest.push_back(interpolate(T_, rest_x, at));
    }
    for (int s = 0; s < tree.segments.rows(); ++s) {
      const int a = tree.segments(s, 0), b = tree.segments(s, 1);
      segments.emplace_back(base + a, base + b);
      BeamSection section;
      section.outer_radius = 0.5 * (tree.radius[a] + tree.radius[b]);
      section.wall_thickness = 0.5 * (tree.wall_thickness[a] + tree.wall_thickness[b]);
      section.young_modulus = v.young_modulus;
      section.poisson_ratio = v.poisson_ratio;
      sections.push_back(section);
      beam_vessel_.push_back(static_cast<int>(names_.size()));
    }
    names_.push_back(v.name);
  }
  if (segments.empty()) return;
  const int m = num_nodes();
  Eigen::MatrixX3d P(m, 3);
  for (int k = 0; k < m; ++k) P.row(k) = rest[k].transpose();
  Eigen::MatrixX2i S(static_cast<int>(segments.size()), 2);
  for (size_t s = 0; s < segments.size(); ++s) S.row(s) = segments[s].transpose();
  beams_.emplace(P, S, sections);
  host_index_.assign(T_.rows(), -1);
  for (const EmbeddedPoint& p : nodes_) {
    if (host_index_[p.tet] >= 0) continue;
    host_index_[p.tet] = static_cast<int>(hosts_.size());
    hosts_.push_back(p.tet);
  }
  host_rotation_.assign(hosts_.size(), Eigen::Matrix3d::Identity());
  host_rotation_derivative_.assign(hosts_.size(), Eigen::Matrix<double, 3, 12>::Zero());
  node_rotation_.assign(m, Eigen::Matrix3d::Identity());
  node_positions_.setZero(3 * m);
  for (int e = 0; e < beams_->size(); ++e) {
    std::vector<int> g;
    for (int end = 0; end < 2; ++end)
      for (int k = 0; k < 4; ++k) g.push_back(T_(nodes_[S(e, end)].tet, k));
    coupled_.push_back(std::move(g));
  }
}

void EmbeddedVessels::add_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) {
  for (size_t h = 0; h < hosts_.size(); ++h) {
    const Eigen::Matrix3d F = tetra_.deformation_gradient(hosts_[h], x);
    // The vessel follows the polar rotation of its host; with polar parenchyma that is the
    // rotation the tetrahedron's force has just computed at x.
    host_rotation_[h] = rotation_ == RotationMethod::Polar ? tetra_.rotation(hosts_[h]) : polar_rotation(F);
    host_rotation_derivative_[h] = polar_rotation_derivative(host_rotation_[h], F, tetra_.rest_edge_inverse(hosts_[h]));
  }
  for (int k = 0; k < num_nodes(); ++k) {
    node_positions_.segment<3>(3 * k) = interpolate(T_, x, nodes_[k]);
    node_rotation_[k] = host_rotation_[host_index_[nodes_[k].tet]];
  }
  beams_->update_frames(node_positions_, node_rotation_);
  Vector12d fe;
  for (int e = 0; e < beams_->size(); ++e) {
    beams_->element_force(e, fe);
    for (int end = 0; end < 2; ++end) {
      const EmbeddedPoint& at = nodes_[beams_->segments()(e, end)];
      // Force through the barycentric weights, moment through d theta / d x of the host.
      const Eigen::Matrix<double, 3, 12>& G = host_rotation_derivative_[host_index_[at.tet]];
      const Eigen::Matrix<double, 12, 1> fm = G.transpose() * fe.segment<3>(6 * end + 3);
      for (int k = 0; k < 4; ++k)
        f.segment<3>(3 * T_(at.tet, k)) += at.barycentric[k] * fe.segment<3>(6 * end) + fm.segment<3>(3 * k);
    }
  }
}

Eigen::Matrix<double, 12, 24> EmbeddedVessels::mapping(int e) const {
  Eigen::Matrix<double, 12, 24> J = Eigen::Matrix<double, 12, 24>::Zero();
  for (int end = 0; end < 2; ++end) {
    const EmbeddedPoint& at = nodes_[beams_->segments()(e, end)];
    for (int k = 0; k < 4; ++k) J.block<3, 3>(6 * end, 3 * (4 * end + k)).diagonal().setConstant(at.barycentric[k]);
    J.block<3, 12>(6 * end + 3, 12 * end) = host_rotation_derivative_[host_index_[at.tet]];
  }
  return J;
}

void EmbeddedVessels::add_tangent(const std::vector<int>& scatter_map, std::vector<double>& values) const {
  Matrix12d Ke;
  for (int e = 0; e < num_beams(); ++e) {
    beams_->element_tangent(e, Ke);
    const Eigen::Matrix<double, 12, 24> J = mapping(e);
    const Eigen::Matrix<double, 24, 24> Kb = J.transpose() * Ke * J;
    scatter_add(Kb, &scatter_map[576 * e], values);
  }
}

void EmbeddedVessels::snapshot_damping() {
  damping_.tangent.resize(num_beams());
  damping_.mapping.resize(num_beams());
  for (int e = 0; e < num_beams(); ++e) {
    beams_->element_tangent(e, damping_.tangent[e]);
    damping_.mapping[e] = mapping(e);
  }
}

void EmbeddedVessels::add_damping_forces(const Eigen::VectorXd& v, Eigen::VectorXd& f) const {
  for (int e = 0; e < num_beams(); ++e) {
    Eigen::Matrix<double, 24, 1> ve;
    for (int end = 0; end < 2; ++end) {
      const int tet = nodes_[beams_->segments()(e, end)].tet;
      for (int k = 0; k < 4; ++k) ve.segment<3>(12 * end + 3 * k) = v.segment<3>(3 * T_(tet, k));
    }
    const Eigen::Matrix<double, 12, 24>& J = damping_.mapping[e];
    const Eigen::Matrix<double, 24, 1> fe = J.transpose() * (damping_.tangent[e] * (J * ve));
    for (int end = 0; end < 2; ++end) {
      const int tet = nodes_[beams_->segments()(e, end)].tet;
      for (int k = 0; k < 4; ++k) f.segment<3>(3 * T_(tet, k)) += fe.segment<3>(12 * end + 3 * k);
    }
  }
}

}  // namespace liver_sim
