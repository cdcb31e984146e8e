#include "liver_sim/meshing/surface_repair.h"
#include "point_text.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <sstream>
#include <unordered_map>

namespace liver_sim {
namespace {

std::string number(double x) {
  std::ostringstream s;
  s.precision(6);
  s << x;
  return s.str();
}

int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

// Sign of det[b-a, c-a, d-a] (which side of the plane abc the point d lies on): 0 when its
// magnitude is within rounding of the products that form it, so that touching, coplanar and
// nearly degenerate configurations never count as crossings.
int orientation(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const Eigen::Vector3d u = b - a, v = c - a, w = d - a;
  const double det = u.cross(v).dot(w);
  const double bound = 1e-12 * u.norm() * v.norm() * w.norm();
  return det > bound ? 1 : det < -bound ? -1 : 0;
}

// Segment pq, with its ends strictly on both sides of the plane of triangle abc, passes through
// the triangle (its edges and corners included: on a regular grid a fold meets them exactly).
bool segment_crosses_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const int sp = orientation(a, b, c, p), sq = orientation(a, b, c, q);
  if (sp == 0 || sq == 0 || sp == sq) return false;
  const int s1 = orientation(p, q, a, b), s2 = orientation(p, q, b, c), s3 = orientation(p, q, c, a);
  return (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0);
}

class SurfaceChecker {
 public:
  SurfaceChecker(const SurfaceMesh& in, const std::string& origin, const SurfaceRepairOptions& options,
                 SurfaceRepairs& repairs)
      : in_(in), origin_(origin), options_(options), repairs_(repairs) {}

  SurfaceMesh run() {
    check_input();
    checked_input_ = true;
    merge_vertices();
    collect_triangles();
    build_edges();
    orient_shells();
    check_vertex_fans();
    keep_shells();
    check_self_intersections();
    return compact();
  }

 private:
  [[noreturn]] void refuse(const std::string& message) const {
    if (checked_input_) throw SurfaceDefectError(origin_ + ": " + message);
    throw MeshError(origin_ + ": " + message);
  }
  Eigen::Vector3d point(int v) const { return in_.V.row(v).transpose(); }
  std::string vertex(int v) const { return "vertex " + std::to_string(v) + " at " + at(point(v)); }
  std::string triangle(int t) const { return "triangle " + std::to_string(source_[t]); }

  void check_input() {
    if (in_.F.rows() == 0 || in_.V.rows() == 0) refuse("no triangles");
    for (Eigen::Index i = 0; i < in_.V.rows(); ++i)
      if (!in_.V.row(i).allFinite()) refuse("vertex " + std::to_string(i) + " has a non-finite coordinate");
    for (Eigen::Index t = 0; t < in_.F.rows(); ++t)
      for (int k = 0; k < 3; ++k)
        if (in_.F(t, k) < 0 || in_.F(t, k) >= in_.V.rows())
          refuse("triangle " + std::to_string(t) + " refers to vertex " + std::to_string(in_.F(t, k)) + " out of range");
    lo_ = in_.V.colwise().minCoeff().transpose();
    const Eigen::Vector3d hi = in_.V.colwise().maxCoeff().transpose();
    diagonal_ = (hi - lo_).norm();
    // Coordinates whose differences overflow, or so large that double precision cannot resolve
    // a millionth of the extent, are no surface of an organ in any unit.
    if (!std::isfinite(diagonal_) || lo_.cwiseAbs().maxCoeff() > 1e12 || hi.cwiseAbs().maxCoeff() > 1e12)
      refuse("coordinates too large (beyond 1e12 in the file's unit, from " + at(lo_) + " to " + at(hi) + ")");
    if (!(diagonal_ > 0)) refuse("every vertex is at one point " + at(lo_));
  }

  // Each vertex joins the first earlier representative within the merge distance (a grid of
  // that cell size finds it among the 27 cells around); representatives are farther apart.
  void merge_vertices() {
    const double tol = options_.merge_distance > 0 ? options_.merge_distance : 1e-6 * diagonal_;
    // Cell indices up to 2e6 per axis: three of them, offset by one, fit 21 bits each.
    if (diagonal_ / tol > 2e6)
      refuse("merge distance " + number(tol) + " too small for the extent " + number(diagonal_));
    std::unordered_map<long long, std::vector<int>> cells;
    auto key = [](long long x, long long y, long long z) { return ((x + 1) << 42) | ((y + 1) << 21) | (z + 1); };
    const int n = static_cast<int>(in_.V.rows());
    rep_.resize(n);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d p = point(i);
      const Eigen::Vector3d c = ((p - lo_) / tol).array().floor();
      int best = i;
      for (long long dx = -1; dx <= 1; ++dx)
        for (long long dy = -1; dy <= 1; ++dy)
          for (long long dz = -1; dz <= 1; ++dz) {
            const auto it = cells.find(key(static_cast<long long>(c[0]) + dx, static_cast<long long>(c[1]) + dy,
                                           static_cast<long long>(c[2]) + dz));
            if (it == cells.end()) continue;
            for (const int r : it->second)
              if (r < best && (point(r) - p).norm() <= tol) best = r;
          }
      rep_[i] = best;
      if (best == i) {
        cells[key(static_cast<long long>(c[0]), static_cast<long long>(c[1]), static_cast<long long>(c[2]))].push_back(i);
      } else {
        ++repairs_.merged_vertices;
      }
    }
    if (repairs_.merged_vertices > 0)
      repairs_.notes.push_back("merged " + std::to_string(repairs_.merged_vertices) + " duplicate vertices (within " +
                               number(tol) + ")");
  }

  void collect_triangles() {
    std::unordered_map<long long, std::vector<int>> by_lowest;  // lowest vertex -> triangles kept
    int first_collapsed = -1;
    for (Eigen::Index t = 0; t < in_.F.rows(); ++t) {
      std::array<int, 3> f{rep_[in_.F(t, 0)], rep_[in_.F(t, 1)], rep_[in_.F(t, 2)]};
      if (f[0] == f[1] || f[1] == f[2] || f[2] == f[0]) {
        if (first_collapsed < 0) first_collapsed = static_cast<int>(t);
        ++repairs_.collapsed_triangles;
        continue;
      }
      std::array<int, 3> sorted = f;
      std::sort(sorted.begin(), sorted.end());
      bool duplicate = false;
      for (const int u : by_lowest[sorted[0]]) {
        std::array<int, 3> g = faces_[u];
        std::sort(g.begin(), g.end());
        duplicate = duplicate || g == sorted;
      }
      if (duplicate) {
        ++repairs_.duplicate_triangles;
        continue;
      }
      by_lowest[sorted[0]].push_back(static_cast<int>(faces_.size()));
      faces_.push_back(f);
      source_.push_back(static_cast<int>(t));
    }
    if (faces_.empty()) refuse("no triangles with three distinct vertices");
    if (repairs_.collapsed_triangles > 0)
      repairs_.notes.push_back("dropped " + std::to_string(repairs_.collapsed_triangles) +
                               " collapsed triangles (two corners on one vertex, e.g. triangle " +
                               std::to_string(first_collapsed) + ")");
    if (repairs_.duplicate_triangles > 0)
      repairs_.notes.push_back("dropped " + std::to_string(repairs_.duplicate_triangles) + " duplicate triangles");
  }

  // Every edge must have exactly two triangles; edge_twin_[3 t + k] is the triangle across edge
  // k (corners k, k+1) of triangle t.
  void build_edges() {
    struct Side {
      int a, b, t, k;
    };
    std::vector<Side> sides;
    sides.reserve(3 * faces_.size());
    for (size_t t = 0; t < faces_.size(); ++t)
      for (int k = 0; k < 3; ++k) {
        const int a = faces_[t][k], b = faces_[t][(k + 1) % 3];
        sides.push_back({std::min(a, b), std::max(a, b), static_cast<int>(t), k});
      }
    std::sort(sides.begin(), sides.end(), [](const Side& x, const Side& y) {
      return std::tie(x.a, x.b, x.t) < std::tie(y.a, y.b, y.t);
    });
    twin_.assign(3 * faces_.size(), -1);
    long long open = 0, non_manifold = 0;
    std::string first_open, first_non_manifold;
    for (size_t i = 0; i < sides.size();) {
      size_t j = i;
      while (j < sides.size() && sides[j].a == sides[i].a && sides[j].b == sides[i].b) ++j;
      const std::string edge = "the edge " + vertex(sides[i].a) + " - " + vertex(sides[i].b);
      if (j - i == 1) {
        if (open++ == 0) first_open = edge + ", side of " + triangle(sides[i].t);
      } else if (j - i > 2) {
        if (non_manifold++ == 0)
          first_non_manifold = edge + ", shared by " + std::to_string(j - i) + " triangles (" + triangle(sides[i].t) +
                               ", " + triangle(sides[i + 1].t) + ", " + triangle(sides[i + 2].t) + ")";
      } else {
        twin_[3 * sides[i].t + sides[i].k] = sides[i + 1].t;
        twin_[3 * sides[i + 1].t + sides[i + 1].k] = sides[i].t;
      }
      i = j;
    }
    if (non_manifold > 0)
      refuse("non-manifold edge: " + std::to_string(non_manifold) + " edges have more than two triangles, e.g. " +
             first_non_manifold);
    if (open > 0)
      refuse("open boundary (a hole): " + std::to_string(open) + " edges belong to one triangle only, e.g. " +
             first_open + "; close it in the segmentation tool (fill holes)");
  }

  // Breadth-first over each shell, turning triangles to agree with the first one; then the
  // shell is turned whole if its volume is negative (its normals pointed inward).
  void orient_shells() {
    const int n = static_cast<int>(faces_.size());
    shell_.assign(n, -1);
    std::vector<char> flip(n, 0);
    for (int seed = 0; seed < n; ++seed) {
      if (shell_[seed] >= 0) continue;
      const int s = static_cast<int>(shell_volume_.size());
      std::vector<int> members{seed};
      shell_[seed] = s;
      for (size_t q = 0; q < members.size(); ++q) {
        const int t = members[q];
        for (int k = 0; k < 3; ++k) {
          const int u = twin_[3 * t + k];
          // Consistent neighbours run along their shared edge in opposite directions.
          const int a = faces_[t][k], b = faces_[t][(k + 1) % 3];
          bool same_direction = false;
          for (int m = 0; m < 3; ++m) same_direction = same_direction || (faces_[u][m] == a && faces_[u][(m + 1) % 3] == b);
          const char want = static_cast<char>(flip[t] ^ static_cast<char>(same_direction));
          if (shell_[u] < 0) {
            shell_[u] = s;
            flip[u] = want;
            members.push_back(u);
          } else if (flip[u] != want) {
            refuse("non-orientable surface (like a Moebius strip): " + triangle(t) + " and " + triangle(u) +
                   " cannot face the same side, at " + at(point(a)));
          }
        }
      }
      double volume = 0;
      for (const int t : members) volume += (flip[t] ? -1.0 : 1.0) * signed_volume6(t);
      volume /= 6.0;
      if (volume < 0)
        for (const int t : members) flip[t] ^= 1;
      shell_volume_.push_back(std::abs(volume));
      shell_seed_.push_back(seed);
      shell_size_.push_back(static_cast<int>(members.size()));
    }
    for (int t = 0; t < n; ++t)
      if (flip[t]) std::swap(faces_[t][1], faces_[t][2]);
    // A turned triangle's sides are numbered anew: find the twins again.
    flipped_ = flip;
    rebuild_twins();
  }

  double signed_volume6(int t) const {
    return point(faces_[t][0]).dot(point(faces_[t][1]).cross(point(faces_[t][2])));
  }

  void rebuild_twins() {
    std::unordered_map<long long, int> directed;  // (a, b) of each oriented edge -> triangle
    directed.reserve(3 * faces_.size());
    const long long n = in_.V.rows();
    for (size_t t = 0; t < faces_.size(); ++t)
      for (int k = 0; k < 3; ++k) directed[faces_[t][k] * n + faces_[t][(k + 1) % 3]] = static_cast<int>(t);
    for (size_t t = 0; t < faces_.size(); ++t)
      for (int k = 0; k < 3; ++k) twin_[3 * t + k] = directed.at(faces_[t][(k + 1) % 3] * n + faces_[t][k]);
  }

  // Around each vertex the triangles must form one fan: two cones touching at their tips
  // share a vertex but no edge there.
  void check_vertex_fans() {
    const int n = static_cast<int>(faces_.size());
    std::vector<int> parent(3 * n);
    std::iota(parent.begin(), parent.end(), 0);
    for (int t = 0; t < n; ++t)
      for (int k = 0; k < 3; ++k) {
        const int u = twin_[3 * t + k];
        for (int m = 0; m < 3; ++m)
          for (const int c : {k, (k + 1) % 3})
            if (faces_[u][m] == faces_[t][c]) parent[find_root(parent, 3 * t + c)] = find_root(parent, 3 * u + m);
      }
    std::unordered_map<int, int> fan_of_vertex;
    for (int t = 0; t < n; ++t)
      for (int k = 0; k < 3; ++k) {
        const int v = faces_[t][k], r = find_root(parent, 3 * t + k);
        const auto [it, inserted] = fan_of_vertex.emplace(v, r);
        if (!inserted && it->second != r)
          refuse("non-manifold vertex: two sheets of the surface touch only at " + vertex(v) + " (" + triangle(t) +
                 " and " + triangle(it->second / 3) + ")");
      }
  }

  void keep_shells() {
    const int shells = static_cast<int>(shell_volume_.size());
    const int largest =
        static_cast<int>(std::max_element(shell_volume_.begin(), shell_volume_.end()) - shell_volume_.begin());
    if (shells > 1 && !options_.keep_largest_shell) {
      std::ostringstream m;
      m << shells << " disconnected shells; enclosed volumes";
      for (int s = 0; s < shells && s < 5; ++s)
        m << (s ? ", " : " ") << shell_volume_[s] << " (" << shell_size_[s] << " triangles from "
          << triangle(shell_seed_[s]) << " at " << at(point(faces_[shell_seed_[s]][0])) << ")";
      m << (shells > 5 ? ", ..." : "") << "; keep only the largest with --largest-shell";
      refuse(m.str());
    }
    if (shells > 1) {
      repairs_.dropped_shells = shells - 1;
      std::ostringstream m;
      m << "kept the largest of " << shells << " shells (volume " << shell_volume_[largest] << ", "
        << shell_size_[largest] << " triangles); dropped " << shells - 1 << " with "
        << faces_.size() - shell_size_[largest] << " triangles";
      repairs_.notes.push_back(m.str());
    }
    std::vector<std::array<int, 3>> faces;
    std::vector<int> source;
    int turned = 0;
    for (size_t t = 0; t < faces_.size(); ++t) {
      if (shell_[t] != largest && shells > 1) continue;
      faces.push_back(faces_[t]);
      source.push_back(source_[t]);
      turned += flipped_[t];
    }
    faces_.swap(faces);
    source_.swap(source);
    repairs_.reoriented_triangles = turned;
    repairs_.inside_out = turned == static_cast<int>(faces_.size());
    if (repairs_.inside_out) {
      repairs_.notes.push_back("the surface was inside out (every normal pointed inward): turned");
    } else if (turned > 0) {
      repairs_.notes.push_back("turned " + std::to_string(turned) +
                               " triangles to agree with their neighbours and face outward");
    }
  }

  // Pairs of triangles whose boxes overlap, found by sorting (grid cell, triangle) entries; each
  // pair is tested once, in the first cell both cover.
  void check_self_intersections() {
    const int n = static_cast<int>(faces_.size());
    std::vector<Eigen::AlignedBox3d> box(n);
    double mean_extent = 0;
    for (int t = 0; t < n; ++t) {
      for (int k = 0; k < 3; ++k) box[t].extend(point(faces_[t][k]));
      mean_extent += box[t].sizes().maxCoeff() / n;
    }
    double cell = std::max(mean_extent, 1e-3 * diagonal_);
    std::vector<std::pair<long long, int>> entries;
    for (;;) {
      entries.clear();
      const double limit = 8.0 * n + 1e6;
      bool fits = true;
      for (int t = 0; t < n && fits; ++t) {
        const Eigen::Array3d a = ((box[t].min() - lo_) / cell).array().floor(),
                             b = ((box[t].max() - lo_) / cell).array().floor();
        for (double x = a[0]; x <= b[0]; ++x)
          for (double y = a[1]; y <= b[1]; ++y)
            for (double z = a[2]; z <= b[2]; ++z)
              entries.emplace_back((static_cast<long long>(x) * 2000003LL + static_cast<long long>(y)) * 2000003LL +
                                       static_cast<long long>(z),
                                   t);
        fits = static_cast<double>(entries.size()) < limit;
      }
      if (fits) break;
      cell *= 2;
    }
    std::sort(entries.begin(), entries.end());
    for (size_t i = 0; i < entries.size();) {
      size_t j = i;
      while (j < entries.size() && entries[j].first == entries[i].first) ++j;
      for (size_t p = i; p < j; ++p)
        for (size_t q = p + 1; q < j; ++q) {
          const int s = entries[p].second, t = entries[q].second;
          if (!box[s].intersects(box[t])) continue;
          // Test the pair only in the cell of the lower corner of their boxes' overlap.
          const Eigen::Vector3d corner = box[s].intersection(box[t]).min();
          const Eigen::Array3d c = ((corner - lo_) / cell).array().floor();
          const long long home =
              (static_cast<long long>(c[0]) * 2000003LL + static_cast<long long>(c[1])) * 2000003LL + static_cast<long long>(c[2]);
          if (home != entries[i].first) continue;
          check_pair(s, t);
        }
      i = j;
    }
  }

  void check_pair(int s, int t) const {
    const std::array<int, 3>&A = faces_[s], &B = faces_[t];
    int shared = 0;
    for (const int a : A) shared += std::count(B.begin(), B.end(), a);
    auto P = [&](int v) { return point(v); };
    auto cross_report = [&](const Eigen::Vector3d& where) {
      refuse("self-intersection: " + triangle(s) + " and " + triangle(t) + " cross each other near " + at(where));
    };
    if (shared == 0) {
      for (int k = 0; k < 3; ++k) {
        if (segment_crosses_triangle(P(A[k]), P(A[(k + 1) % 3]), P(B[0]), P(B[1]), P(B[2])))
          cross_report(0.5 * (P(A[k]) + P(A[(k + 1) % 3])));
        if (segment_crosses_triangle(P(B[k]), P(B[(k + 1) % 3]), P(A[0]), P(A[1]), P(A[2])))
          cross_report(0.5 * (P(B[k]) + P(B[(k + 1) % 3])));
      }
    } else if (shared == 1) {
      // Apart from the shared vertex the two can only meet where the edge opposite it in one
      // crosses the other.
      auto opposite = [](const std::array<int, 3>& F, const std::array<int, 3>& G) {
        for (int k = 0; k < 3; ++k)
          if (std::count(G.begin(), G.end(), F[k])) return std::make_pair(F[(k + 1) % 3], F[(k + 2) % 3]);
        return std::make_pair(F[0], F[1]);
      };
      const auto [a1, a2] = opposite(A, B);
      const auto [b1, b2] = opposite(B, A);
      if (segment_crosses_triangle(P(a1), P(a2), P(B[0]), P(B[1]), P(B[2]))) cross_report(0.5 * (P(a1) + P(a2)));
      if (segment_crosses_triangle(P(b1), P(b2), P(A[0]), P(A[1]), P(A[2]))) cross_report(0.5 * (P(b1) + P(b2)));
    } else if (shared == 2) {
      // Neighbours across an edge overlap only when folded flat onto each other: coplanar with
      // their third vertices on the same side of the edge.
      int u = -1, w = -1, a = -1, b = -1;  // shared edge u-w, third vertices a (of A) and b (of B)
      for (const int v : A) {
        if (!std::count(B.begin(), B.end(), v)) a = v;
        else if (u < 0) u = v;
        else w = v;
      }
      for (const int v : B)
        if (!std::count(A.begin(), A.end(), v)) b = v;
      if (orientation(P(u), P(w), P(a), P(b)) == 0) {
        const Eigen::Vector3d e = P(w) - P(u);
        if (e.cross(P(a) - P(u)).dot(e.cross(P(b) - P(u))) > 0)
          refuse("self-intersection: " + triangle(s) + " and " + triangle(t) + " are folded onto each other across " +
                 "the edge " + vertex(u) + " - " + vertex(w));
      }
    }
  }

  SurfaceMesh compact() {
    std::vector<int> index(in_.V.rows(), -1);
    SurfaceMesh out;
    int n = 0;
    for (const auto& f : faces_)
      for (const int v : f)
        if (index[v] < 0) index[v] = n++;
    int used_representatives = 0;
    for (Eigen::Index i = 0; i < in_.V.rows(); ++i) used_representatives += rep_[i] == i;
    repairs_.unused_vertices = used_representatives - n;
    out.V.resize(n, 3);
    for (Eigen::Index i = 0; i < in_.V.rows(); ++i)
      if (index[i] >= 0) out.V.row(index[i]) = in_.V.row(i);
    out.F.resize(static_cast<Eigen::Index>(faces_.size()), 3);
    for (size_t t = 0; t < faces_.size(); ++t)
      for (int k = 0; k < 3; ++k) out.F(t, k) = index[faces_[t][k]];
    return out;
  }

  const SurfaceMesh& in_;
  const std::string& origin_;
  const SurfaceRepairOptions& options_;
  SurfaceRepairs& repairs_;
  Eigen::Vector3d lo_;
  double diagonal_ = 0;
  bool checked_input_ = false;  // past the input's own checks: what is refused now is a defect
  std::vector<int> rep_;                  // per input vertex: the vertex it merged into
  std::vector<std::array<int, 3>> faces_;  // kept triangles (input vertex indices)
  std::vector<int> source_;               // per kept triangle: its index in the input
  std::vector<int> twin_;                 // per triangle side: the triangle across it
  std::vector<int> shell_;                // per triangle: its shell
  std::vector<char> flipped_;             // per triangle: turned relative to the input
  std::vector<double> shell_volume_;
  std::vector<int> shell_seed_, shell_size_;
};

}  // namespace

SurfaceMesh repair_surface(const SurfaceMesh& surface, const std::string& origin, const SurfaceRepairOptions& options,
                           SurfaceRepairs* repairs) {
  SurfaceRepairs local;
  SurfaceRepairs& r = repairs ? *repairs : local;
  r = SurfaceRepairs();
  return SurfaceChecker(surface, origin, options, r).run();
}

double enclosed_volume(const SurfaceMesh& s) {
  double v = 0;
  for (Eigen::Index t = 0; t < s.F.rows(); ++t)
    v += s.V.row(s.F(t, 0)).dot(s.V.row(s.F(t, 1)).cross(s.V.row(s.F(t, 2))));
  return v / 6.0;
}

}  // namespace liver_sim
