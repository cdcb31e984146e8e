#include "liver_sim/geometry/mesh.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <unordered_map>

namespace liver_sim {
namespace {

// Outward faces of a positively oriented tetrahedron (v0, v1, v2, v3).
constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

std::string index_list(const std::vector<int>& idx) {
  std::ostringstream s;
  for (size_t i = 0; i < idx.size() && i < 10; ++i) s << (i ? ", " : "") << idx[i];
  if (idx.size() > 10) s << ", ...";
  return s.str();
}

}  // namespace

double signed_volume(const Eigen::MatrixX3d& V, const Eigen::MatrixX4i& T, int t) {
  Eigen::Matrix3d D;
  for (int k = 0; k < 3; ++k) D.col(k) = (V.row(T(t, k + 1)) - V.row(T(t, 0))).transpose();
  return D.determinant() / 6.0;
}

TetMesh make_box_mesh(const Eigen::Vector3d& size, const Eigen::Vector3i& divisions) {
  if (!size.allFinite() || (size.array() <= 0).any())
    throw MeshError("box: size must be three positive lengths");
  if ((divisions.array() < 1).any()) throw MeshError("box: divisions must be at least 1");
  const int nx = divisions[0], ny = divisions[1], nz = divisions[2];
  auto id = [&](int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); };
  TetMesh m;
  m.V.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        m.V.row(id(i, j, k)) << size[0] * i / nx, size[1] * j / ny, size[2] * k / nz;
  // Corners numbered by bits (x, y, z). Even cells cut off corners 0, 3, 5, 6 around the
  // tetrahedron (1, 2, 4, 7); odd cells the mirror image, so that the diagonals of shared faces
  // match and the mesh is symmetric about the mid-planes.
  static constexpr int kEven[5][4] = {{0, 1, 2, 4}, {3, 2, 1, 7}, {5, 1, 4, 7}, {6, 4, 2, 7}, {1, 2, 4, 7}};
  static constexpr int kOdd[5][4] = {{1, 0, 5, 3}, {2, 0, 3, 6}, {4, 0, 6, 5}, {7, 3, 5, 6}, {0, 3, 6, 5}};
  m.T.resize(5 * nx * ny * nz, 4);
  int e = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        int c[8];
        for (int b = 0; b < 8; ++b) c[b] = id(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
        const auto& split = ((i + j + k) % 2 == 0) ? kEven : kOdd;
        for (const auto& t : split) {
          m.T.row(e) << c[t[0]], c[t[1]], c[t[2]], c[t[3]];
          if (signed_volume(m.V, m.T, e) < 0) std::swap(m.T(e, 2), m.T(e, 3));
          ++e;
        }
      }
  return m;
}

Eigen::MatrixX3i boundary_triangles(const Eigen::MatrixX4i& T) {
  // Count each face by its sorted node triple; boundary faces are seen once.
  struct Hash {
    size_t operator()(const std::array<int, 3>& k) const {
      return std::hash<long long>()((static_cast<long long>(k[0]) * 73856093) ^
                                    (static_cast<long long>(k[1]) * 19349663) ^
                                    (static_cast<long long>(k[2]) * 83492791));
    }
  };
  std::unordered_map<std::array<int, 3>, int, Hash> count;
  count.reserve(4 * T.rows());
  auto key = [&](int t, int f) {
    std::array<int, 3> k = {T(t, kFaces[f][0]), T(t, kFaces[f][1]), T(t, kFaces[f][2])};
    std::sort(k.begin(), k.end());
    return k;
  };
  for (int t = 0; t < T.rows(); ++t)
    for (int f = 0; f < 4; ++f) ++count[key(t, f)];
  std::vector<Eigen::Vector3i> faces;
  for (int t = 0; t < T.rows(); ++t)
    for (int f = 0; f < 4; ++f)
      if (count[key(t, f)] == 1) faces.emplace_back(T(t, kFaces[f][0]), T(t, kFaces[f][1]), T(t, kFaces[f][2]));
  Eigen::MatrixX3i B(faces.size(), 3);
  for (size_t i = 0; i < faces.size(); ++i) B.row(i) = faces[i].transpose();
  return B;
}

MeshCheck check_mesh(const TetMesh& mesh) {
  MeshCheck c;
  for (int t = 0; t < mesh.T.rows(); ++t) {
    double longest = 0;
    bool repeated = false;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        repeated |= mesh.T(t, a) == mesh.T(t, b);
        longest = std::max(longest, (mesh.V.row(mesh.T(t, a)) - mesh.V.row(mesh.T(t, b))).norm());
      }
    const double v = signed_volume(mesh.V, mesh.T, t);
    if (repeated || std::abs(v) <= 1e-12 * longest * longest * longest)
      c.degenerate.push_back(t);
    else if (v < 0)
      c.inverted.push_back(t);
  }
  return c;
}

void validate_mesh(const TetMesh& mesh, const std::string& what) {
  if (mesh.T.rows() == 0) throw MeshError(what + ": no tetrahedra");
  if (!mesh.V.allFinite()) throw MeshError(what + ": non-finite node coordinates");
  if (mesh.T.minCoeff() < 0 || mesh.T.maxCoeff() >= mesh.V.rows())
    throw MeshError(what + ": node index out of range");
  const MeshCheck c = check_mesh(mesh);
  const std::string of = " (of " + std::to_string(mesh.T.rows()) + "): ";
  if (!c.degenerate.empty())
    throw MeshError(what + ": " + std::to_string(c.degenerate.size()) + " degenerate tetrahedra" + of +
                    index_list(c.degenerate));
  if (!c.inverted.empty())
    throw MeshError(what + ": " + std::to_string(c.inverted.size()) + " inverted tetrahedra" + of +
                    index_list(c.inverted));
}

}  // namespace liver_sim
