#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <sstream>

#include "liver_sim/meshing/voxel_mask.h"
#include "point_text.h"

namespace liver_sim {
namespace {

// A ray along axis d meets a triangle at a depth, entering (+1: the triangle faces against the
// ray) or leaving (-1).
struct Crossing {
  double depth;
  int enter;
  bool operator<(const Crossing& o) const { return depth < o.depth; }
};

// Twice the signed area of (a, b, p) in the plane: which side of the edge a -> b the point lies.
double edge_function(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& p) {
  return (b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x());
}

// A point exactly on an edge counts for the triangle on one side only (the rasterisers' top-left
// rule, for counter-clockwise triangles): a ray through an edge or vertex the surface's
// triangles share crosses the surface once, not twice or never.
bool owns(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double e) {
  if (e != 0) return e > 0;
  const Eigen::Vector2d d = b - a;
  return d.y() < 0 || (d.y() == 0 && d.x() > 0);
}

}  // namespace

VoxelMask voxelize_surface(const SurfaceMesh& s, double voxel, int padding, const std::string& origin,
                           VoxelizeReport* report) {
  if (!(voxel > 0) || s.F.rows() == 0) throw MeshError(origin + ": nothing to voxelize");
  // Orientation: the sign that makes the enclosed volume positive (an inside-out file counts).
  double volume6 = 0;
  for (Eigen::Index t = 0; t < s.F.rows(); ++t)
    volume6 += s.V.row(s.F(t, 0)).dot(s.V.row(s.F(t, 1)).cross(s.V.row(s.F(t, 2))));
  const int outward = volume6 >= 0 ? 1 : -1;

  const Eigen::Vector3d lo = s.V.colwise().minCoeff().transpose(), hi = s.V.colwise().maxCoeff().transpose();
  VoxelMask m;
  const Eigen::Array3d cells = ((hi - lo) / voxel).array().ceil() + 1 + 2 * padding;
  if ((cells > 4096).any() || cells.prod() > double(1 << 28))
    throw MeshError(origin + ": a voxel of " + std::to_string(voxel) + " m is too fine for the surface's extent " + at(hi - lo));
  m.dims = cells.cast<int>();
  m.axes = voxel * Eigen::Matrix3d::Identity();
  // Centred on the surface's box: the grid's offset from the file's coordinates is arbitrary.
  m.origin = 0.5 * (lo + hi) - 0.5 * voxel * (cells - 1).matrix();
  const long n = static_cast<long>(cells.prod());
  std::vector<std::uint8_t> votes(n, 0);

  for (int d = 0; d < 3; ++d) {
    const int a = (d + 1) % 3, b = (d + 2) % 3;  // the plane of the columns
    const int na = m.dims[a], nb = m.dims[b], nd = m.dims[d];
    std::vector<std::vector<Crossing>> columns(static_cast<size_t>(na) * nb);
    for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
      std::array<Eigen::Vector3d, 3> p;
      for (int k = 0; k < 3; ++k) p[k] = (s.V.row(s.F(t, k)).transpose() - m.origin) / voxel;  // grid units
      const Eigen::Vector3d normal = (p[1] - p[0]).cross(p[2] - p[0]) * outward;
      if (normal[d] == 0) continue;  // parallel to the rays
      std::array<Eigen::Vector2d, 3> q;
      for (int k = 0; k < 3; ++k) q[k] = Eigen::Vector2d(p[k][a], p[k][b]);
      if (edge_function(q[0], q[1], q[2]) < 0) std::swap(q[1], q[2]), std::swap(p[1], p[2]);
      const double area = edge_function(q[0], q[1], q[2]);
      const int enter = normal[d] < 0 ? 1 : -1;
      const int ia0 = std::max(0, static_cast<int>(std::ceil(std::min({q[0].x(), q[1].x(), q[2].x()}))));
      const int ia1 = std::min(na - 1, static_cast<int>(std::floor(std::max({q[0].x(), q[1].x(), q[2].x()}))));
      const int ib0 = std::max(0, static_cast<int>(std::ceil(std::min({q[0].y(), q[1].y(), q[2].y()}))));
      const int ib1 = std::min(nb - 1, static_cast<int>(std::floor(std::max({q[0].y(), q[1].y(), q[2].y()}))));
      for (int ia = ia0; ia <= ia1; ++ia)
        for (int ib = ib0; ib <= ib1; ++ib) {
          const Eigen::Vector2d c(ia, ib);
          const double w0 = edge_function(q[1], q[2], c), w1 = edge_function(q[2], q[0], c),
                       w2 = edge_function(q[0], q[1], c);
          if (!owns(q[1], q[2], w0) || !owns(q[2], q[0], w1) || !owns(q[0], q[1], w2)) continue;
          const double depth = (w0 * p[0][d] + w1 * p[1][d] + w2 * p[2][d]) / area;
          columns[static_cast<size_t>(ia) + static_cast<size_t>(na) * ib].push_back({depth, enter});
        }
    }
    for (int ib = 0; ib < nb; ++ib)
      for (int ia = 0; ia < na; ++ia) {
        std::vector<Crossing>& c = columns[static_cast<size_t>(ia) + static_cast<size_t>(na) * ib];
        if (c.empty()) continue;
        std::sort(c.begin(), c.end());
        int winding = 0;
        size_t next = 0;
        for (int id = 0; id < nd; ++id) {
          while (next < c.size() && c[next].depth < id) winding += c[next++].enter;
          if (winding > 0) {
            Eigen::Vector3i g;
            g[d] = id, g[a] = ia, g[b] = ib;
            ++votes[m.index(g[0], g[1], g[2])];
          }
        }
      }
  }

  m.inside.assign(n, 0);
  VoxelizeReport r;
  Eigen::Vector3d disputed_sum = Eigen::Vector3d::Zero();
  for (int k = 0; k < m.dims[2]; ++k)
    for (int j = 0; j < m.dims[1]; ++j)
      for (int i = 0; i < m.dims[0]; ++i) {
        const std::uint8_t v = votes[m.index(i, j, k)];
        m.inside[m.index(i, j, k)] = v >= 2;
        r.inside_voxels += v >= 2;
        if (v == 1 || v == 2) {
          ++r.disputed_voxels;
          disputed_sum += m.centre(i, j, k);
        }
      }
  if (r.inside_voxels == 0) throw MeshError(origin + ": the surface encloses no voxel of " + std::to_string(voxel) + " m");
  if (r.disputed_voxels > r.inside_voxels / 10) {
    std::ostringstream msg;
    msg << origin << ": the surface does not bound a volume (open, or its triangles face both ways): rays in x, y "
        << "and z disagree on " << r.disputed_voxels << " voxels against " << r.inside_voxels
        << " inside, centred near " << at(disputed_sum / static_cast<double>(r.disputed_voxels));
    throw MeshError(msg.str());
  }
  if (report) *report = r;
  return m;
}

VoxelMask label_mask(const LabelImage& image, int label, int padding, const std::string& origin) {
  Eigen::Array3i lo = image.dims, hi = Eigen::Array3i::Constant(-1);
  const auto at_index = [&](int i, int j, int k) {
    return static_cast<size_t>(i) + static_cast<size_t>(image.dims[0]) * (j + static_cast<size_t>(image.dims[1]) * k);
  };
  std::map<int, long long> present;
  for (int k = 0; k < image.dims[2]; ++k)
    for (int j = 0; j < image.dims[1]; ++j)
      for (int i = 0; i < image.dims[0]; ++i) {
        const int v = image.labels[at_index(i, j, k)];
        if (present.size() < 64 || present.count(v)) ++present[v];
        if (v != label) continue;
        lo = lo.min(Eigen::Array3i(i, j, k));
        hi = hi.max(Eigen::Array3i(i, j, k));
      }
  if ((hi < 0).any()) {
    std::ostringstream msg;
    msg << origin << ": no voxel has the label " << label << "; labels present (voxels):";
    for (const auto& [value, count] : present) msg << " " << value << " (" << count << ")";
    throw MeshError(msg.str());
  }
  VoxelMask m;
  m.dims = hi - lo + 1 + 2 * padding;
  m.axes = image.axes;
  m.origin = image.origin + image.axes * (lo - padding).cast<double>().matrix();
  m.inside.assign(static_cast<size_t>(m.dims.cast<long>().prod()), 0);
  for (int k = lo[2]; k <= hi[2]; ++k)
    for (int j = lo[1]; j <= hi[1]; ++j)
      for (int i = lo[0]; i <= hi[0]; ++i)
        if (image.labels[at_index(i, j, k)] == label)
          m.inside[m.index(i - lo[0] + padding, j - lo[1] + padding, k - lo[2] + padding)] = 1;
  return m;
}

void keep_one_piece(VoxelMask& m, bool keep_largest, double speck, const std::string& origin, ComponentReport* report) {
  const long n = static_cast<long>(m.inside.size());
  const long sx = 1, sy = m.dims[0], sz = static_cast<long>(m.dims[0]) * m.dims[1];
  // Flood fill of voxels with value `value` from `seed`, labelling them `id`; returns the count.
  std::vector<int> piece(n, -1);
  std::vector<long> stack;
  auto fill = [&](long seed, std::uint8_t value, int id) {
    long long count = 0;
    stack.assign(1, seed);
    piece[seed] = id;
    while (!stack.empty()) {
      const long v = stack.back();
      stack.pop_back();
      ++count;
      const long i = v % sy, j = v % sz / sy, k = v / sz;
      const long next[6][2] = {{i > 0, v - sx}, {i + 1 < m.dims[0], v + sx}, {j > 0, v - sy},
                               {j + 1 < m.dims[1], v + sy}, {k > 0, v - sz}, {k + 1 < m.dims[2], v + sz}};
      for (const auto& [ok, u] : next)
        if (ok && piece[u] < 0 && m.inside[u] == value) {
          piece[u] = id;
          stack.push_back(u);
        }
    }
    return count;
  };
  std::vector<long long> size;
  std::vector<long> seed;
  for (long v = 0; v < n; ++v)
    if (m.inside[v] && piece[v] < 0) {
      seed.push_back(v);
      size.push_back(fill(v, 1, static_cast<int>(size.size())));
    }
  ComponentReport r;
  r.components = static_cast<int>(size.size());
  if (size.empty()) throw MeshError(origin + ": no voxel inside");
  const int largest = static_cast<int>(std::max_element(size.begin(), size.end()) - size.begin());
  std::ostringstream big;
  int big_pieces = 0;
  for (size_t p = 0; p < size.size(); ++p)
    if (static_cast<int>(p) != largest && size[p] >= speck * size[largest]) {
      if (big_pieces++ < 5) {
        const Eigen::Vector3d c = m.centre(seed[p] % sy, seed[p] % sz / sy, seed[p] / sz);
        big << ", " << size[p] * m.voxel_volume() << " m^3 at " << at(c);
      }
    }
  if (big_pieces > 0 && !keep_largest)
    throw MeshError(origin + ": " + std::to_string(big_pieces + 1) + " separate pieces; volumes " +
                    std::to_string(size[largest] * m.voxel_volume()) + " m^3 (the largest)" + big.str() +
                    "; keep only the largest with --largest-shell");
  for (long v = 0; v < n; ++v)
    if (m.inside[v] && piece[v] != largest) {
      m.inside[v] = 0;
      ++r.dropped_voxels;
    }
  // Cavities: outside voxels not connected to the grid's border (its first voxel is outside:
  // the grid is padded).
  std::fill(piece.begin(), piece.end(), -1);
  if (m.inside[0]) throw MeshError(origin + ": the volume touches the edge of the grid");
  fill(0, 0, 0);
  for (long v = 0; v < n; ++v)
    if (!m.inside[v] && piece[v] < 0) {
      m.inside[v] = 1;
      ++r.filled_voxels;
    }
  if (report) *report = r;
}

}  // namespace liver_sim
