// A closed triangle surface edited in place by the remeshing and the coarsening: positions,
// triangles (dead ones flagged rather than erased, so indices stay valid) and, per vertex, the
// live triangles around it; the topology both need (the triangle across an edge, the link
// condition, an edge collapse).
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {
namespace meshing_detail {

using Tri = std::array<int, 3>;

// Twice the triangle's area, along its outward normal.
Eigen::Vector3d area_normal(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);
// The triangle's smallest angle, rad.
double min_angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);

class EditableSurface {
 public:
  explicit EditableSurface(const SurfaceMesh& s);
  // The live triangles and the vertices they use, renumbered; their smallest angle (rad).
  SurfaceMesh mesh(double* smallest_angle = nullptr) const;

 protected:
  void add_triangle(const Tri& f);
  static void drop(std::vector<int>& list, int value);
  static int corner(const Tri& f, int v) { return f[0] == v ? 0 : f[1] == v ? 1 : f[2] == v ? 2 : -1; }
  // The other triangle across edge (a, b) of triangle t, and its vertex opposite the edge.
  int across(int t, int a, int b) const;
  int opposite(int t, int a, int b) const;
  std::vector<int> neighbours(int v) const;
  // Whether edge a-b of triangles t and u may be collapsed: neither opposite vertex is left with
  // two triangles, and a and b share exactly those two neighbours (the link condition: the
  // surface stays manifold).
  bool collapsible(int t, int u, int a, int b) const;
  // Edge a-b collapsed into b (wherever b now lies): t and u die, a's other triangles pass to b.
  void merge(int t, int u, int a, int b);

  std::vector<Eigen::Vector3d> p_;
  std::vector<Tri> tri_;
  std::vector<char> alive_;
  std::vector<std::vector<int>> star_;  // live triangles around each vertex
};

}  // namespace meshing_detail
}  // namespace liver_sim
