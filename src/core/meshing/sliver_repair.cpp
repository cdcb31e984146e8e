#include "liver_sim/meshing/sliver_repair.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <map>
#include <set>

#include "liver_sim/geometry/closest_points.h"

namespace liver_sim {
namespace {

using Face = std::array<int, 3>;

Face sorted_face(int a, int b, int c) {
  Face f{a, b, c};
  std::sort(f.begin(), f.end());
  return f;
}

const int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};  // face k: opposite node k

// How many tetrahedra share each face: 1 on the boundary.
std::map<Face, int> face_counts(const TetMesh& m) {
  std::map<Face, int> count;
  for (int t = 0; t < m.T.rows(); ++t)
    for (const auto& f : kFaces) ++count[sorted_face(m.T(t, f[0]), m.T(t, f[1]), m.T(t, f[2]))];
  return count;
}

double tet_min_dihedral(const TetMesh& m, int t) {
  return min_dihedral_deg(m.V.row(m.T(t, 0)), m.V.row(m.T(t, 1)), m.V.row(m.T(t, 2)), m.V.row(m.T(t, 3)));
}

}  // namespace

double min_dihedral_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& d) {
  if (!((b - a).cross(c - a).dot(d - a) > 0)) return -1;
  const std::array<Eigen::Vector3d, 4> p{a, b, c, d};
  double smallest = 180;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      int k = 0;
      while (k == i || k == j) ++k;
      const int l = 6 - i - j - k;
      const Eigen::Vector3d e = p[j] - p[i];
      const Eigen::Vector3d n1 = e.cross(p[k] - p[i]), n2 = e.cross(p[l] - p[i]);
      const double cosine = n1.dot(n2) / (n1.norm() * n2.norm());
      smallest = std::min(smallest, std::acos(std::clamp(cosine, -1.0, 1.0)) * 180.0 / M_PI);
    }
  return smallest;
}

SliverRepairReport repair_slivers(TetMesh& m, double target, double max_boundary_move) {
  SliverRepairReport r;
  auto smallest = [&]() {
    double s = 180;
    for (int t = 0; t < m.T.rows(); ++t) s = std::min(s, tet_min_dihedral(m, t));
    return s;
  };
  r.before_deg = smallest();
  // The boundary as the mesher made it, per node its triangles: a boundary node may move along
  // it (its moves add up over visits and rounds) but not farther than max_boundary_move off it.
  // Unbounded (gmsh's own boundary), none of it is measured.
  const bool bounded = std::isfinite(max_boundary_move);
  std::vector<std::vector<Eigen::Matrix3d>> original_faces(m.V.rows());
  if (bounded)
    for (const auto& [f, n] : face_counts(m)) {
      if (n != 1) continue;
      Eigen::Matrix3d corners;
      for (int k = 0; k < 3; ++k) corners.col(k) = m.V.row(f[k]).transpose();
      for (const int v : f) original_faces[v].push_back(corners);
    }
  // How far point p lies from the original boundary's triangles at `nodes`.
  auto off_original = [&](const Eigen::Vector3d& p, std::initializer_list<int> nodes) {
    double d = std::numeric_limits<double>::infinity();
    for (const int node : nodes)
      for (const Eigen::Matrix3d& c : original_faces[node]) {
        const Eigen::Vector3d w = closest_on_triangle(p, c.col(0), c.col(1), c.col(2));
        d = std::min(d, (c * w - p).norm());
      }
    return d;
  };
  // Whether the triangle a peel lays bare stays within the bound of the original boundary around
  // the sliver's nodes (sampled on a grid of 4 x 4 sub-triangles): a later round's peel under an
  // earlier one adds up.
  auto peel_allowed = [&](int a, int b, int c, const Eigen::Vector4i& v) {
    if (!bounded) return true;
    const Eigen::Vector3d pa = m.V.row(a), pb = m.V.row(b), pc = m.V.row(c);
    for (int i = 0; i <= 4; ++i)
      for (int j = 0; i + j <= 4; ++j)
        if (off_original(pa + (pb - pa) * i / 4.0 + (pc - pa) * j / 4.0, {v[0], v[1], v[2], v[3]}) > max_boundary_move)
          return false;
    return true;
  };
  for (int round = 0; round < 8 && smallest() < target; ++round) {
    // The boundary: faces of one tetrahedron, their edges and nodes.
    std::map<Face, int> face_count = face_counts(m);
    std::set<std::pair<int, int>> boundary_edges;
    std::vector<char> on_boundary(m.V.rows(), 0);
    std::vector<int> uses(m.V.rows(), 0);
    for (const auto& [f, count] : face_count)
      if (count == 1)
        for (int k = 0; k < 3; ++k) {
          on_boundary[f[k]] = 1;
          boundary_edges.insert({std::min(f[k], f[(k + 1) % 3]), std::max(f[k], f[(k + 1) % 3])});
        }
    for (int t = 0; t < m.T.rows(); ++t)
      for (int k = 0; k < 4; ++k) ++uses[m.T(t, k)];

    // (1) Peel boundary slivers, one per neighbourhood per round.
    std::vector<char> touched(m.V.rows(), 0), keep(m.T.rows(), 1);
    for (int t = 0; t < m.T.rows(); ++t) {
      if (tet_min_dihedral(m, t) >= target) continue;
      const Eigen::Vector4i v = m.T.row(t);
      if (!on_boundary[v[0]] || !on_boundary[v[1]] || !on_boundary[v[2]] || !on_boundary[v[3]]) continue;
      if (touched[v[0]] || touched[v[1]] || touched[v[2]] || touched[v[3]]) continue;
      std::vector<int> outer;  // faces on the boundary (by their opposite node)
      for (int k = 0; k < 4; ++k)
        if (face_count[sorted_face(v[kFaces[k][0]], v[kFaces[k][1]], v[kFaces[k][2]])] == 1) outer.push_back(k);
      bool ok = false;
      if (outer.size() == 2) {
        // The two inner faces become boundary; they meet at the edge joining the outer faces'
        // opposite nodes, which must not be on the boundary already.
        const int c = v[outer[0]], d = v[outer[1]];
        int a = 0;
        while (a == outer[0] || a == outer[1]) ++a;
        const int b = 6 - outer[0] - outer[1] - a;
        // Both ways: the old ridge a-b lies as far from the new edge c-d as their segments are
        // apart, and the faces laid bare within the bound of the original boundary.
        const Eigen::Vector3d pa = m.V.row(v[a]), pb = m.V.row(v[b]), pc = m.V.row(c), pd = m.V.row(d);
        const Eigen::Vector2d st = closest_between_segments(pa, pb, pc, pd);
        ok = !boundary_edges.count({std::min(c, d), std::max(c, d)}) &&
             (pa + st[0] * (pb - pa) - pc - st[1] * (pd - pc)).norm() <= max_boundary_move &&
             peel_allowed(v[a], c, d, v) && peel_allowed(v[b], c, d, v);
      } else if (outer.size() == 3) {
        // A cap: its apex (the node opposite the inner face) must belong to no other tetrahedron.
        int inner = 0;
        while (std::count(outer.begin(), outer.end(), inner)) ++inner;
        // Both ways: the apex as far from the inner face as it lies, the inner face near the
        // original boundary.
        const Eigen::Vector3d apex = m.V.row(v[inner]), p0 = m.V.row(v[kFaces[inner][0]]),
                              p1 = m.V.row(v[kFaces[inner][1]]), p2 = m.V.row(v[kFaces[inner][2]]);
        const Eigen::Vector3d w = closest_on_triangle(apex, p0, p1, p2);
        ok = uses[v[inner]] == 1 && (w[0] * p0 + w[1] * p1 + w[2] * p2 - apex).norm() <= max_boundary_move &&
             peel_allowed(v[kFaces[inner][0]], v[kFaces[inner][1]], v[kFaces[inner][2]], v);
      }
      if (!ok) continue;
      keep[t] = 0;
      ++r.peeled;
      for (int k = 0; k < 4; ++k) touched[v[k]] = 1;
    }
    if (r.peeled > 0) {
      Eigen::MatrixX4i kept(std::count(keep.begin(), keep.end(), 1), 4);
      for (int t = 0, row = 0; t < m.T.rows(); ++t)
        if (keep[t]) kept.row(row++) = m.T.row(t);
      m.T = kept;
    }

    // (2) Move the nodes of the slivers left: interior nodes freely, boundary nodes in the plane
    // tangent to the boundary there (the surface keeps its shape to second order).
    Eigen::MatrixX3d normal = Eigen::MatrixX3d::Zero(m.V.rows(), 3);
    for (int t = 0; t < m.T.rows(); ++t)
      for (int k = 0; k < 4; ++k) {
        const int a = m.T(t, kFaces[k][0]), b = m.T(t, kFaces[k][1]), c = m.T(t, kFaces[k][2]);
        if (face_count[sorted_face(a, b, c)] != 1) continue;
        Eigen::RowVector3d n = (m.V.row(b) - m.V.row(a)).cross(m.V.row(c) - m.V.row(a));
        if (n.dot(m.V.row(m.T(t, k)) - m.V.row(a)) > 0) n = -n;  // away from the opposite node
        for (const int v : {a, b, c}) normal.row(v) += n.normalized();
      }
    std::vector<std::vector<int>> star(m.V.rows());
    for (int t = 0; t < m.T.rows(); ++t)
      for (int k = 0; k < 4; ++k) star[m.T(t, k)].push_back(t);
    auto star_quality = [&](int node) {
      double q = 180;
      for (const int t : star[node]) q = std::min(q, tet_min_dihedral(m, t));
      return q;
    };
    for (int t = 0; t < m.T.rows(); ++t) {
      if (tet_min_dihedral(m, t) >= target) continue;
      for (int k = 0; k < 4; ++k) {
        const int node = m.T(t, k);
        Eigen::Matrix3d directions = Eigen::Matrix3d::Identity();  // rows: the directions searched
        int searched = 3;
        if (on_boundary[node]) {
          const Eigen::Vector3d n = normal.row(node).normalized();
          const Eigen::Vector3d u = n.unitOrthogonal();
          directions.row(0) = u.transpose();
          directions.row(1) = n.cross(u).transpose();
          searched = 2;
        }
        double edge = 0;
        for (const int s : star[node])
          for (int j = 0; j < 4; ++j) edge = std::max(edge, (m.V.row(m.T(s, j)) - m.V.row(node)).norm());
        double best = star_quality(node), step = 0.1 * edge;
        const Eigen::RowVector3d start = m.V.row(node);
        for (int iteration = 0; iteration < 30 && step > 1e-4 * edge; ++iteration) {
          bool improved = false;
          for (int axis = 0; axis < searched && !improved; ++axis)
            for (const double sign : {1.0, -1.0}) {
              const Eigen::RowVector3d old = m.V.row(node);
              m.V.row(node) += sign * step * directions.row(axis);
              // Stays near where the mesher put it; on the boundary, within the move allowed.
              if ((m.V.row(node) - start).norm() > 0.25 * edge ||
                  (bounded && on_boundary[node] && off_original(m.V.row(node).transpose(), {node}) > max_boundary_move)) {
                m.V.row(node) = old;
                continue;
              }
              const double q = star_quality(node);
              if (q > best) {
                best = q;
                improved = true;
                break;
              }
              m.V.row(node) = old;
            }
          if (!improved) step *= 0.5;
        }
        r.moved_nodes += m.V.row(node) != start;
      }
    }
  }
  // Nodes of no tetrahedron (the apexes of peeled caps) drop out.
  std::vector<int> index(m.V.rows(), -1);
  int n = 0;
  for (int t = 0; t < m.T.rows(); ++t)
    for (int k = 0; k < 4; ++k)
      if (index[m.T(t, k)] < 0) index[m.T(t, k)] = n++;
  Eigen::MatrixX3d V(n, 3);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i)
    if (index[i] >= 0) V.row(index[i]) = m.V.row(i);
  for (int t = 0; t < m.T.rows(); ++t)
    for (int k = 0; k < 4; ++k) m.T(t, k) = index[m.T(t, k)];
  m.V = V;
  r.after_deg = smallest();
  return r;
}

}  // namespace liver_sim
