#include "editable_surface.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace liver_sim {
namespace meshing_detail {

Eigen::Vector3d area_normal(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return (b - a).cross(c - a);
}

double min_angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const std::array<Eigen::Vector3d, 3> p{a, b, c};
  double smallest = M_PI;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d u = p[(k + 1) % 3] - p[k], v = p[(k + 2) % 3] - p[k];
    smallest = std::min(smallest, std::atan2(u.cross(v).norm(), u.dot(v)));
  }
  return smallest;
}

EditableSurface::EditableSurface(const SurfaceMesh& s) {
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
    p_.push_back(s.V.row(i).transpose());
    star_.emplace_back();
  }
  for (Eigen::Index t = 0; t < s.F.rows(); ++t) add_triangle({s.F(t, 0), s.F(t, 1), s.F(t, 2)});
}

SurfaceMesh EditableSurface::mesh(double* smallest_angle) const {
  std::vector<int> index(p_.size(), -1);
  int n = 0, m = 0;
  for (size_t t = 0; t < tri_.size(); ++t)
    if (alive_[t]) {
      ++m;
      for (const int v : tri_[t])
        if (index[v] < 0) index[v] = n++;
    }
  SurfaceMesh s;
  s.V.resize(n, 3);
  for (size_t v = 0; v < p_.size(); ++v)
    if (index[v] >= 0) s.V.row(index[v]) = p_[v].transpose();
  s.F.resize(m, 3);
  double smallest = M_PI;
  for (size_t t = 0, row = 0; t < tri_.size(); ++t)
    if (alive_[t]) {
      const Tri& f = tri_[t];
      s.F.row(row++) << index[f[0]], index[f[1]], index[f[2]];
      smallest = std::min(smallest, min_angle(p_[f[0]], p_[f[1]], p_[f[2]]));
    }
  if (smallest_angle) *smallest_angle = smallest;
  return s;
}

void EditableSurface::add_triangle(const Tri& f) {
  tri_.push_back(f);
  alive_.push_back(1);
  for (const int v : f) star_[v].push_back(static_cast<int>(tri_.size()) - 1);
}

void EditableSurface::drop(std::vector<int>& list, int value) { list.erase(std::find(list.begin(), list.end(), value)); }

int EditableSurface::across(int t, int a, int b) const {
  for (const int u : star_[a])
    if (u != t && corner(tri_[u], b) >= 0) return u;
  return -1;
}

int EditableSurface::opposite(int t, int a, int b) const {
  for (const int v : tri_[t])
    if (v != a && v != b) return v;
  return -1;
}

std::vector<int> EditableSurface::neighbours(int v) const {
  std::vector<int> n;
  for (const int t : star_[v])
    for (const int u : tri_[t])
      if (u != v && std::find(n.begin(), n.end(), u) == n.end()) n.push_back(u);
  return n;
}

bool EditableSurface::collapsible(int t, int u, int a, int b) const {
  const int c = opposite(t, a, b), d = opposite(u, a, b);
  if (star_[c].size() <= 3 || star_[d].size() <= 3) return false;
  const std::vector<int> na = neighbours(a), nb = neighbours(b);
  for (const int v : na)
    if (v != c && v != d && v != b && std::find(nb.begin(), nb.end(), v) != nb.end()) return false;
  return true;
}

void EditableSurface::merge(int t, int u, int a, int b) {
  const int c = opposite(t, a, b), d = opposite(u, a, b);
  alive_[t] = alive_[u] = 0;
  drop(star_[c], t), drop(star_[b], t), drop(star_[d], u), drop(star_[b], u);
  for (const int s : star_[a]) {
    if (s == t || s == u) continue;
    tri_[s][corner(tri_[s], a)] = b;
    star_[b].push_back(s);
  }
  star_[a].clear();
}

}  // namespace meshing_detail
}  // namespace liver_sim
