#include "liver_sim/geometry/mesh_quality.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

namespace liver_sim {

TetQuality tet_quality(const TetMesh& mesh) {
  TetQuality q;
  q.min_dihedral_deg = q.min_radius_ratio = std::numeric_limits<double>::infinity();
  const double deg = 180.0 / M_PI;
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    Eigen::Vector3d x[4];
    for (int k = 0; k < 4; ++k) x[k] = mesh.V.row(mesh.T(t, k)).transpose();
    // Face k is opposite vertex k; its normal points away from that vertex (outward).
    Eigen::Vector3d n[4];
    double area_sum = 0;
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d& a = x[(k + 1) % 4];
      const Eigen::Vector3d& b = x[(k + 2) % 4];
      const Eigen::Vector3d& c = x[(k + 3) % 4];
      n[k] = (b - a).cross(c - a);
      if (n[k].dot(x[k] - a) > 0) n[k] = -n[k];
      area_sum += 0.5 * n[k].norm();
      n[k].normalize();
    }
    // The dihedral angle at the edge shared by faces k and l is pi minus the angle between their
    // outward normals.
    for (int k = 0; k < 4; ++k)
      for (int l = k + 1; l < 4; ++l) {
        const double angle = deg * (M_PI - std::acos(std::clamp(n[k].dot(n[l]), -1.0, 1.0)));
        if (angle < q.min_dihedral_deg) {
          q.min_dihedral_deg = angle;
          q.worst_dihedral = static_cast<int>(t);
        }
        q.max_dihedral_deg = std::max(q.max_dihedral_deg, angle);
      }
    const Eigen::Vector3d a = x[1] - x[0], b = x[2] - x[0], c = x[3] - x[0];
    const double six_volume = std::abs(a.dot(b.cross(c)));
    const double r_in = 0.5 * six_volume / area_sum;  // 3 V / (sum of face areas)
    // Circumcentre relative to x0: (|a|^2 b x c + |b|^2 c x a + |c|^2 a x b) / (2 a . (b x c)).
    const double r_circ =
        (a.squaredNorm() * b.cross(c) + b.squaredNorm() * c.cross(a) + c.squaredNorm() * a.cross(b)).norm() /
        (2.0 * six_volume);
    const double ratio = six_volume > 0 ? 3.0 * r_in / r_circ : 0.0;
    if (ratio < q.min_radius_ratio) {
      q.min_radius_ratio = ratio;
      q.worst_radius_ratio = static_cast<int>(t);
    }
    q.mean_radius_ratio += ratio / static_cast<double>(mesh.T.rows());
  }
  return q;
}

}  // namespace liver_sim
