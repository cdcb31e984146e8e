#include "liver_sim/meshing/surface_remesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <queue>
#include <string>

#include "editable_surface.h"
#include "liver_sim/geometry/surface_locator.h"

namespace liver_sim {
namespace {

using meshing_detail::area_normal;
using meshing_detail::min_angle;
using meshing_detail::Tri;

// Triangles thinner than this (radians, about 6 degrees) are not made by a collapse or a move.
constexpr double kThin = 0.1;

// Whether triangle (a, b, c) may replace one with area normal `before` and smallest angle
// `angle_before`: it does not turn over (normals within 60 degrees), and it is not thinner than
// kThin unless the one it replaces was.
bool acceptable(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                const Eigen::Vector3d& before, double angle_before) {
  const Eigen::Vector3d n = area_normal(a, b, c);
  const double angle = min_angle(a, b, c);
  return n.dot(before) > 0.5 * n.norm() * before.norm() && (angle >= kThin || angle >= angle_before);
}

// The surface being remeshed, starting from the reference itself. Every vertex lies on the
// reference; `size` is the target there.
class Remesher : public meshing_detail::EditableSurface {
 public:
  Remesher(const SurfaceMesh& reference, const std::vector<double>& size, double deviation, double min_length,
           size_t max_vertices, const std::string& origin)
      : EditableSurface(reference), ref_(reference), ref_size_(size), deviation_(deviation), min_length_(min_length),
        max_vertices_(max_vertices), origin_(origin), size_(size.begin(), size.end()), hint_(reference.V.rows(), -1) {
    locator_.build(reference);
    for (Eigen::Index t = 0; t < reference.F.rows(); ++t)
      for (int k = 0; k < 3; ++k) hint_[reference.F(t, k)] = static_cast<int>(t);
  }

  void run(int iterations) {
    for (int i = 0; i < iterations; ++i) {
      split_long_edges();
      collapse_short_edges();
      flip_toward_valence_six();
      for (int s = 0; s < 2; ++s) smooth_tangentially();
    }
    flip_toward_valence_six();
  }

  SurfaceMesh result(RemeshReport* report) const {
    double smallest = 0;
    SurfaceMesh s = mesh(&smallest);
    if (report) {
      report->triangles = static_cast<int>(s.F.rows());
      report->min_angle_deg = smallest * 180 / M_PI;
    }
    return s;
  }

 private:
  double target(int a, int b) const { return 0.5 * (size_[a] + size_[b]); }
  // How far the middle of segment a-b lies from the reference (the chord's bulge).
  double bulge(const Eigen::Vector3d& a, const Eigen::Vector3d& b, int hint) const {
    return locator_.closest(0.5 * (a + b), std::numeric_limits<double>::infinity(), hint).distance;
  }
  bool too_long(int a, int b) const {
    const double length = (p_[a] - p_[b]).norm();
    return length > 4.0 / 3.0 * target(a, b) || (length > min_length_ && bulge(p_[a], p_[b], hint_[a]) > deviation_);
  }

  // Onto the closest point of the reference, with the size interpolated there.
  void project(int v) {
    const SurfaceLocator::Hit hit = locator_.closest(p_[v], std::numeric_limits<double>::infinity(), hint_[v]);
    p_[v] = hit.point;
    hint_[v] = hit.triangle;
    size_[v] = 0;
    for (int k = 0; k < 3; ++k) size_[v] += hit.weights[k] * ref_size_[ref_.F(hit.triangle, k)];
  }

  void split_long_edges() {
    for (int sweep = 0; sweep < 20; ++sweep) {
      bool any = false;
      const size_t n = tri_.size();  // the triangles a split makes wait for the next sweep
      for (size_t t = 0; t < n; ++t)
        if (alive_[t] && split_triangle(static_cast<int>(t))) any = true;
      if (!any) return;
    }
  }

  // Splits an edge of t that is too long or, when none is, its longest edge if the triangle's
  // middle bulges from the reference (a saddle, a rim along it). One split per call: t changes.
  bool split_triangle(int t) {
    int longest = 0;
    auto length = [&](int k) { return (p_[tri_[t][k]] - p_[tri_[t][(k + 1) % 3]]).norm(); };
    for (int k = 0; k < 3; ++k) {
      const int a = tri_[t][k], b = tri_[t][(k + 1) % 3];
      if (too_long(a, b) && split_edge(t, a, b)) return true;
      if (length(k) > length(longest)) longest = k;
    }
    const int a = tri_[t][longest], b = tri_[t][(longest + 1) % 3], c = tri_[t][(longest + 2) % 3];
    return length(longest) > min_length_ &&
           locator_.closest((p_[a] + p_[b] + p_[c]) / 3, std::numeric_limits<double>::infinity(), hint_[a]).distance >
               deviation_ &&
           split_edge(t, a, b);
  }

  // t = (a, b, c) and u = (b, a, d) become (a, m, c), (m, b, c), (b, m, d), (m, a, d), m the
  // middle of a-b projected onto the reference. Not done when m lands near a or b (across a
  // thin part the projection may jump: the split would not shorten the edge) or a new triangle
  // would turn over.
  bool split_edge(int t, int a, int b) {
    if (p_.size() >= max_vertices_)
      throw MeshError(origin_ + ": remeshing stopped at " + std::to_string(p_.size()) +
                      " vertices, more than the sizes asked for can need on this surface's area (runaway splitting)");
    const int u = across(t, a, b);
    const int c = opposite(t, a, b), d = opposite(u, a, b);
    const int m = static_cast<int>(p_.size());
    p_.push_back(0.5 * (p_[a] + p_[b]));
    size_.push_back(0);
    hint_.push_back(hint_[a]);
    project(m);
    const double length = (p_[a] - p_[b]).norm();
    const Eigen::Vector3d nt = area_normal(p_[a], p_[b], p_[c]), nu = area_normal(p_[b], p_[a], p_[d]);
    const double at = min_angle(p_[a], p_[b], p_[c]), au = min_angle(p_[b], p_[a], p_[d]);
    if (std::min((p_[m] - p_[a]).norm(), (p_[m] - p_[b]).norm()) < 0.25 * length ||
        !acceptable(p_[a], p_[m], p_[c], nt, at) || !acceptable(p_[m], p_[b], p_[c], nt, at) ||
        !acceptable(p_[b], p_[m], p_[d], nu, au) || !acceptable(p_[m], p_[a], p_[d], nu, au)) {
      p_.pop_back(), size_.pop_back(), hint_.pop_back();
      return false;
    }
    star_.emplace_back();
    Tri t_new = tri_[t], u_new = tri_[u];
    tri_[t][corner(tri_[t], b)] = m;
    t_new[corner(t_new, a)] = m;
    tri_[u][corner(tri_[u], a)] = m;
    u_new[corner(u_new, b)] = m;
    drop(star_[b], t);
    drop(star_[a], u);
    star_[m] = {t, u};
    add_triangle(t_new);  // (m, b, c): into the stars of m, b, c
    add_triangle(u_new);  // (m, a, d)
    return true;
  }

  void collapse_short_edges() {
    for (size_t t = 0; t < tri_.size(); ++t)
      for (int k = 0; alive_[t] && k < 3; ++k) {
        const int a = tri_[t][k], b = tri_[t][(k + 1) % 3];
        if ((p_[a] - p_[b]).norm() < 0.8 * target(a, b)) collapse_edge(static_cast<int>(t), a, b);
      }
  }

  // Removes a, b moves to the edge's midpoint (projected), when the surface stays manifold, no
  // triangle turns over and no edge becomes too long. Returns whether it did.
  bool collapse_edge(int t, int a, int b) {
    const int u = across(t, a, b);
    if (!collapsible(t, u, a, b)) return false;
    // b at the new position, undone when a check fails.
    const Eigen::Vector3d old_a = p_[a], old_b = p_[b];
    const double old_size_b = size_[b];
    const int old_hint_b = hint_[b];
    p_[b] = 0.5 * (old_a + old_b);
    project(b);
    bool ok = true;
    for (const int v : {a, b}) {
      for (const int s : star_[v]) {
        if (s == t || s == u) continue;
        const Tri& f = tri_[s];
        Eigen::Vector3d q[3];
        for (int k = 0; k < 3; ++k) q[k] = f[k] == a ? p_[b] : p_[f[k]];
        Eigen::Vector3d old_q[3];
        for (int k = 0; k < 3; ++k) old_q[k] = f[k] == a ? old_a : f[k] == b ? old_b : p_[f[k]];
        if (!acceptable(q[0], q[1], q[2], area_normal(old_q[0], old_q[1], old_q[2]),
                        min_angle(old_q[0], old_q[1], old_q[2]))) {
          ok = false;
          break;
        }
        for (int k = 0; k < 3; ++k) {
          const int w = f[k] == a ? b : f[k];
          if (w != b && too_long(w, b)) ok = false;
        }
      }
      if (!ok) break;
    }
    if (!ok) {
      p_[b] = old_b, size_[b] = old_size_b, hint_[b] = old_hint_b;
      return false;
    }
    merge(t, u, a, b);
    return true;
  }

  void flip_toward_valence_six() {
    for (size_t t = 0; t < tri_.size(); ++t)
      for (int k = 0; alive_[t] && k < 3; ++k) {
        const int a = tri_[t][k], b = tri_[t][(k + 1) % 3];
        if (a < b && flip_edge(static_cast<int>(t), a, b)) break;
      }
  }

  // t = (a, b, c), u = (b, a, d) become (c, a, d), (d, b, c) when that brings the four vertices
  // closer to six triangles each, the two are nearly flat and neither new one turns over.
  bool flip_edge(int t, int a, int b) {
    const int u = across(t, a, b);
    const int c = opposite(t, a, b), d = opposite(u, a, b);
    if (c == d || star_[a].size() <= 3 || star_[b].size() <= 3) return false;
    const std::vector<int> nc = neighbours(c);
    if (std::find(nc.begin(), nc.end(), d) != nc.end()) return false;  // c-d is an edge already
    auto deviation = [&](int va, int vb, int vc, int vd) {
      return (va - 6) * (va - 6) + (vb - 6) * (vb - 6) + (vc - 6) * (vc - 6) + (vd - 6) * (vd - 6);
    };
    const int sa = static_cast<int>(star_[a].size()), sb = static_cast<int>(star_[b].size()),
              sc = static_cast<int>(star_[c].size()), sd = static_cast<int>(star_[d].size());
    if (deviation(sa - 1, sb - 1, sc + 1, sd + 1) >= deviation(sa, sb, sc, sd)) return false;
    const Eigen::Vector3d nt = area_normal(p_[a], p_[b], p_[c]).normalized(),
                          nu = area_normal(p_[b], p_[a], p_[d]).normalized();
    if (nt.dot(nu) < std::cos(20 * M_PI / 180)) return false;  // the edge is a fold: keep its shape
    const double angle = std::min(min_angle(p_[a], p_[b], p_[c]), min_angle(p_[b], p_[a], p_[d]));
    if (!acceptable(p_[c], p_[a], p_[d], nt + nu, angle) || !acceptable(p_[d], p_[b], p_[c], nt + nu, angle) ||
        std::min(min_angle(p_[c], p_[a], p_[d]), min_angle(p_[d], p_[b], p_[c])) < 0.5 * angle)
      return false;
    tri_[t] = {c, a, d};
    tri_[u] = {d, b, c};
    drop(star_[a], u), drop(star_[b], t);
    star_[c].push_back(u), star_[d].push_back(t);
    return true;
  }

  // Each vertex toward the area-weighted centre of its triangles, in its tangent plane, then back
  // onto the reference; undone where a triangle would turn over.
  void smooth_tangentially() {
    for (size_t v = 0; v < p_.size(); ++v) {
      if (star_[v].empty()) continue;
      Eigen::Vector3d centre = Eigen::Vector3d::Zero(), normal = Eigen::Vector3d::Zero();
      double area = 0;
      for (const int t : star_[v]) {
        const Tri& f = tri_[t];
        const Eigen::Vector3d n = area_normal(p_[f[0]], p_[f[1]], p_[f[2]]);
        centre += n.norm() * (p_[f[0]] + p_[f[1]] + p_[f[2]]) / 3;
        area += n.norm();
        normal += n;
      }
      if (!(area > 0)) continue;
      centre /= area;
      normal.normalize();
      const Eigen::Vector3d old = p_[v];
      const double old_size = size_[v];
      const int old_hint = hint_[v];
      std::vector<Eigen::Vector3d> before;
      std::vector<double> angle_before;
      for (const int t : star_[v]) {
        const Tri& f = tri_[t];
        before.push_back(area_normal(p_[f[0]], p_[f[1]], p_[f[2]]));
        angle_before.push_back(min_angle(p_[f[0]], p_[f[1]], p_[f[2]]));
      }
      p_[v] = centre + normal * normal.dot(old - centre);
      project(static_cast<int>(v));
      for (size_t i = 0; i < star_[v].size(); ++i) {
        const Tri& f = tri_[star_[v][i]];
        // Near a sharp tip the projection can pull vertices together: undone.
        if (!acceptable(p_[f[0]], p_[f[1]], p_[f[2]], before[i], angle_before[i])) {
          p_[v] = old, size_[v] = old_size, hint_[v] = old_hint;
          break;
        }
      }
    }
  }

  const SurfaceMesh& ref_;
  const std::vector<double>& ref_size_;
  const double deviation_, min_length_;
  const size_t max_vertices_;
  const std::string origin_;
  SurfaceLocator locator_;
  std::vector<double> size_;
  std::vector<int> hint_;  // the reference triangle the vertex was last projected onto
};

}  // namespace

SurfaceMesh remesh_surface(const SurfaceMesh& reference, const std::vector<double>& size, const RemeshOptions& options,
                           const std::string& origin, RemeshReport* report) {
  if (static_cast<Eigen::Index>(size.size()) != reference.V.rows() || reference.F.rows() < 4)
    throw MeshError(origin + ": remeshing needs a closed surface and a size at each vertex");
  for (const double s : size)
    if (!(s > 0) || !std::isfinite(s)) throw MeshError(origin + ": remeshing: sizes must be finite and > 0");
  // Edges of length L tile an area A with about 1.2 A / L^2 vertices (equilateral triangles);
  // collapsed below 0.8 L and split anew, a pass may hold about four times that. Past 16 A / L^2
  // summed over the reference's triangles (L the size there, or min_size where that is shorter:
  // bulging edges are split down to it), and the reference's own vertices, the splitting has run
  // away.
  size_t cap = options.max_vertices;
  if (cap == 0) {
    double need = static_cast<double>(reference.V.rows());
    for (Eigen::Index t = 0; t < reference.F.rows(); ++t) {
      const Eigen::RowVector3d a = reference.V.row(reference.F(t, 0)), b = reference.V.row(reference.F(t, 1)),
                               c = reference.V.row(reference.F(t, 2));
      const double here = (size[reference.F(t, 0)] + size[reference.F(t, 1)] + size[reference.F(t, 2)]) / 3;
      const double L = std::min(options.min_size, here);
      need += 16 * 0.5 * (b - a).cross(c - a).norm() / (L * L);
    }
    cap = static_cast<size_t>(std::min(need, 1e9));
  }
  Remesher r(reference, size, options.deviation, options.min_size, cap, origin);
  r.run(options.iterations);
  return r.result(report);
}

std::vector<double> curvature_sizes(const SurfaceMesh& s, double deviation, double min_size, double max_size,
                                    double gradation) {
  const Eigen::Index n = s.V.rows();
  Eigen::MatrixX3d normal = Eigen::MatrixX3d::Zero(n, 3);
  std::vector<std::vector<int>> ring(n);
  for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
    const Eigen::RowVector3d a = s.V.row(s.F(t, 0)), b = s.V.row(s.F(t, 1)), c = s.V.row(s.F(t, 2));
    const Eigen::RowVector3d an = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) {
      normal.row(s.F(t, k)) += an;
      const int v = s.F(t, k), w = s.F(t, (k + 1) % 3);
      ring[v].push_back(w);
      ring[w].push_back(v);
    }
  }
  normal.rowwise().normalize();
  std::vector<double> size(n, max_size);
  for (Eigen::Index i = 0; i < n; ++i) {
    double curvature = 0;
    for (const int j : ring[i]) {
      // The circle through j touching the surface at i: its curvature 2 (n_i . (p_j - p_i)) / |p_j - p_i|^2.
      const Eigen::RowVector3d e = s.V.row(j) - s.V.row(i);
      if (e.squaredNorm() > 0) curvature = std::max(curvature, 2 * std::abs(normal.row(i).dot(e)) / e.squaredNorm());
    }
    if (curvature > 0) size[i] = std::clamp(std::sqrt(8 * deviation / curvature), min_size, max_size);
  }
  // Where the surface comes close to itself (a thin rim, two lobes facing each other) edges
  // longer than the gap let the remeshed sheets cross: no edge longer than the radius of the
  // largest ball touching the surface at the vertex from inside or outside (shrinking balls,
  // Ma et al. 2012), however flat the surface is there.
  SurfaceLocator locator;
  locator.build(s);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d p = s.V.row(i).transpose();
    for (const double side : {-1.0, 1.0}) {
      const Eigen::Vector3d direction = side * normal.row(i).transpose();
      double radius = max_size;
      for (int step = 0; step < 30; ++step) {
        const Eigen::Vector3d centre = p + radius * direction;
        const Eigen::Vector3d q = locator.closest(centre).point;
        const double through = direction.dot(q - p);  // the ball through p and q tangent at p
        if ((centre - q).norm() >= (1 - 1e-3) * radius || through <= 0) break;
        const double smaller = (q - p).squaredNorm() / (2 * through);
        // A q seen from the new ball's centre within 60 degrees of p lies on p's own sheet: the
        // surface's curvature or noise, which the curvature sizes see to (Ma et al.'s denoising).
        const Eigen::Vector3d c = p + smaller * direction;
        if ((p - c).dot(q - c) > 0.5 * smaller * smaller) break;
        radius = smaller;
      }
      size[i] = std::min(size[i], std::max(radius, 0.1 * min_size));
    }
  }
  // Grading: size[v] = min over u of size[u] + gradation * path(u, v), smallest first.
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (Eigen::Index i = 0; i < n; ++i) queue.push({size[i], static_cast<int>(i)});
  while (!queue.empty()) {
    const auto [value, i] = queue.top();
    queue.pop();
    if (value > size[i]) continue;
    for (const int j : ring[i]) {
      const double through = value + gradation * (s.V.row(j) - s.V.row(i)).norm();
      if (through < size[j]) {
        size[j] = through;
        queue.push({through, j});
      }
    }
  }
  return size;
}

}  // namespace liver_sim
