#include "liver_sim/meshing/surface_coarsen.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "editable_surface.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/surface_locator.h"

namespace liver_sim {
namespace {

using meshing_detail::area_normal;
using meshing_detail::min_angle;
using meshing_detail::Tri;

class Coarsener : public meshing_detail::EditableSurface {
 public:
  Coarsener(const SurfaceMesh& surface, const SurfaceMesh& reference, const CoarsenOptions& o)
      : EditableSurface(surface), tolerance_(o.tolerance), smallest_angle_(o.min_angle * M_PI / 180),
        // No edge past 12 tolerances either, so that the sampling is never sparser than the tolerance.
        longest_edge_(std::min(o.max_edge, 12 * o.tolerance)) {
    locator_.build(reference);
    start_quadrics();
  }

  // A pass collapses each vertex's edges at most once, so that the triangles grow evenly; passes
  // repeat until one removes under 1% of the triangles.
  void run() {
    std::vector<char> touched(p_.size());
    for (int pass = 0; pass < 30; ++pass) {
      // An edge, its merged vertex where the quadrics put it, and its order. Neither end of an
      // edge tried changes within the pass (a collapse touches its neighbourhood).
      struct Candidate {
        double key;
        int a, b;
        Eigen::Vector3d x;
      };
      std::vector<Candidate> candidates;
      int alive = 0;
      for (size_t t = 0; t < tri_.size(); ++t) {
        if (!alive_[t]) continue;
        ++alive;
        for (int k = 0; k < 3; ++k) {
          const int a = tri_[t][k], b = tri_[t][(k + 1) % 3];
          // On flat parts every collapse costs nothing: the shorter edges go first.
          if (a >= b) continue;
          const auto [x, error] = best_position(a, b);
          candidates.push_back({error + 1e-4 * (p_[a] - p_[b]).squaredNorm() * (p_[a] - p_[b]).squaredNorm(), a, b, x});
        }
      }
      std::sort(candidates.begin(), candidates.end(), [](const Candidate& x, const Candidate& y) { return x.key < y.key; });
      std::fill(touched.begin(), touched.end(), 0);
      int collapsed = 0;
      for (const Candidate& c : candidates) {
        if (touched[c.a] || touched[c.b] || star_[c.a].empty() || star_[c.b].empty()) continue;
        if (!try_collapse(c.a, c.b, c.x)) continue;
        ++collapsed;  // into c.b
        touched[c.b] = 1;
        for (const int v : neighbours(c.b)) touched[v] = 1;
      }
      if (collapsed < 0.005 * alive) break;
    }
  }

 private:
  // Each vertex's quadric: the squared distances to the planes of the triangles around it,
  // area-weighted.
  void start_quadrics() {
    quadric_.assign(p_.size(), Eigen::Matrix4d::Zero());
    for (size_t t = 0; t < tri_.size(); ++t) {
      if (!alive_[t]) continue;
      const Eigen::Vector3d n = area_normal(p_[tri_[t][0]], p_[tri_[t][1]], p_[tri_[t][2]]);
      const double area = 0.5 * n.norm();
      if (!(area > 0)) continue;
      const Eigen::Vector3d unit = n / n.norm();
      const double offset = -unit.dot(p_[tri_[t][0]]);
      Eigen::Matrix4d k;
      k.topLeftCorner<3, 3>() = unit * unit.transpose();
      k.topRightCorner<3, 1>() = offset * unit;
      k.bottomLeftCorner<1, 3>() = offset * unit.transpose();
      k(3, 3) = offset * offset;
      for (const int v : tri_[t]) quadric_[v] += area * k;
    }
  }

  // Where the merged vertex of edge a-b fits the two quadrics best, and that error: the
  // minimiser of the summed quadric from the edge's middle, along the directions the quadric
  // constrains (on a flat part only across it: the vertex stays on the plane).
  std::pair<Eigen::Vector3d, double> best_position(int a, int b) const {
    const Eigen::Matrix4d q = quadric_[a] + quadric_[b];
    const Eigen::Vector3d middle = 0.5 * (p_[a] + p_[b]);
    const Eigen::Matrix3d A = q.topLeftCorner<3, 3>();
    const Eigen::Vector3d linear = q.topRightCorner<3, 1>();
    const Eigen::Vector3d gradient = A * middle + linear;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(A);
    Eigen::Vector3d x = middle;
    const double largest = eigen.eigenvalues().maxCoeff();
    for (int i = 0; i < 3; ++i)
      if (eigen.eigenvalues()[i] > 1e-3 * largest)
        x -= eigen.eigenvectors().col(i) * (eigen.eigenvectors().col(i).dot(gradient) / eigen.eigenvalues()[i]);
    if ((x - middle).norm() > (p_[a] - p_[b]).norm()) x = middle;
    return {x, std::max(0.0, x.dot(A * x) + 2 * linear.dot(x) + q(3, 3))};
  }

  // Edge a-b collapsed into b at x (where its quadrics put it), moved to keep the volume, when
  // the checks pass.
  bool try_collapse(int a, int b, Eigen::Vector3d x) {
    int t = -1;
    for (const int s : star_[a])
      if (corner(tri_[s], b) >= 0) t = s;
    if (t < 0) return false;
    const int u = across(t, a, b);
    if (u < 0 || !collapsible(t, u, a, b)) return false;
    std::vector<int> around;  // the triangles the merged vertex will have
    for (const int v : {a, b})
      for (const int s : star_[v])
        if (s != t && s != u && std::find(around.begin(), around.end(), s) == around.end()) around.push_back(s);
    // The enclosed volume kept (Lindstrom & Turk 1998): the new triangles' share of it is linear
    // in the merged vertex, g . x; the quadrics' choice is moved along g onto that plane.
    double volume_before = 0;
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    for (const int s : star_[a]) volume_before += p_[tri_[s][0]].dot(p_[tri_[s][1]].cross(p_[tri_[s][2]])) / 6;
    for (const int s : star_[b])
      if (s != t && s != u) volume_before += p_[tri_[s][0]].dot(p_[tri_[s][1]].cross(p_[tri_[s][2]])) / 6;
    for (const int s : around) {
      const Tri& f = tri_[s];
      const int k = corner(f, a) >= 0 ? corner(f, a) : corner(f, b);
      g += p_[f[(k + 1) % 3]].cross(p_[f[(k + 2) % 3]]) / 6;
    }
    if (g.squaredNorm() > 0) x += (volume_before - g.dot(x)) / g.squaredNorm() * g;
    std::vector<std::array<Eigen::Vector3d, 3>> moved(around.size());
    for (size_t i = 0; i < around.size(); ++i) {
      const Tri& f = tri_[around[i]];
      for (int k = 0; k < 3; ++k) moved[i][k] = f[k] == a || f[k] == b ? x : p_[f[k]];
      for (int k = 0; k < 3; ++k)
        if ((moved[i][k] - moved[i][(k + 1) % 3]).norm() > longest_edge_) return false;
      const Eigen::Vector3d before = area_normal(p_[f[0]], p_[f[1]], p_[f[2]]);
      const Eigen::Vector3d after = area_normal(moved[i][0], moved[i][1], moved[i][2]);
      const double angle = min_angle(moved[i][0], moved[i][1], moved[i][2]);
      if (after.dot(before) < std::cos(30 * M_PI / 180) * after.norm() * before.norm() ||
          (angle < smallest_angle_ && angle < min_angle(p_[f[0]], p_[f[1]], p_[f[2]])))
        return false;
      if (!near_reference(moved[i], after.normalized())) return false;
    }
    p_[b] = x;
    quadric_[b] += quadric_[a];
    merge(t, u, a, b);
    return true;
  }

  // Whether triangle `q` lies within `tolerance` of the reference, facing the same way (a
  // triangle reaching across a thin part to the other sheet does not), sampled on a grid of
  // sub-triangles `tolerance` across (12 along an edge at most: coarsening makes none longer).
  bool near_reference(const std::array<Eigen::Vector3d, 3>& q, const Eigen::Vector3d& normal) const {
    const double longest = std::max({(q[1] - q[0]).norm(), (q[2] - q[1]).norm(), (q[0] - q[2]).norm()});
    const int k = std::clamp(static_cast<int>(std::ceil(longest / tolerance_)), 1, 12);
    for (int i = 0; i <= k; ++i)
      for (int j = 0; i + j <= k; ++j) {
        const Eigen::Vector3d point = q[0] + (q[1] - q[0]) * i / k + (q[2] - q[0]) * j / k;
        const SurfaceLocator::Hit hit = locator_.closest(point, tolerance_, -1);
        if (hit.triangle < 0 || hit.distance > tolerance_ || hit.normal.dot(normal) <= 0) return false;
      }
    const SurfaceLocator::Hit middle = locator_.closest((q[0] + q[1] + q[2]) / 3, tolerance_, -1);
    return middle.triangle >= 0 && middle.distance <= tolerance_ && middle.normal.dot(normal) > 0;
  }

  const double tolerance_, smallest_angle_, longest_edge_;
  SurfaceLocator locator_;  // of the reference
  std::vector<Eigen::Matrix4d> quadric_;
};

}  // namespace

SurfaceMesh coarsen_surface(const SurfaceMesh& surface, const SurfaceMesh& reference, const CoarsenOptions& options,
                            const std::string& origin, RemeshReport* report) {
  if (!(options.tolerance > 0) || !(options.max_edge > 0) || !(options.min_angle > 0 && options.min_angle < 60) ||
      !std::isfinite(options.tolerance) || !std::isfinite(options.max_edge))
    throw MeshError(origin + ": coarsening: the tolerance and the longest edge must be finite and > 0, the angle in (0, 60)");
  Coarsener c(surface, reference, options);
  c.run();
  double smallest = 0;
  SurfaceMesh s = c.mesh(&smallest);
  if (report) {
    report->triangles = static_cast<int>(s.F.rows());
    report->min_angle_deg = smallest * 180 / M_PI;
  }
  return s;
}

}  // namespace liver_sim
