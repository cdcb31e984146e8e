// Tetrahedral meshes: loading, generation, boundary extraction and quality checks.
// Positions are in metres once loaded (a loader's `scale` converts file units to metres).
#pragma once

#include <Eigen/Core>
#include <istream>
#include <stdexcept>
#include <string>
#include <vector>

namespace liver_sim {

// V: #V x 3 node positions (m). T: #T x 4 node indices of each tetrahedron (0-based),
// positively oriented: det[x1-x0, x2-x0, x3-x0] > 0.
struct TetMesh {
  Eigen::MatrixX3d V;
  Eigen::MatrixX4i T;
};

// Thrown by every loader and checker; what() names the file (and line when known) at fault.
class MeshError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Box [0,size] split into divisions(0) x divisions(1) x divisions(2) hexahedra, each cut into
// 5 tetrahedra with alternating orientation so that the mesh is conforming and mirror-symmetric
// about the mid-planes. Throws MeshError for non-positive size or divisions.
TetMesh make_box_mesh(const Eigen::Vector3d& size, const Eigen::Vector3i& divisions);

// Triangles that belong to exactly one tetrahedron, ordered so that the normal
// (x1-x0) x (x2-x0) points out of the volume. Requires positively oriented tetrahedra.
Eigen::MatrixX3i boundary_triangles(const Eigen::MatrixX4i& T);

// Signed volume of tetrahedron t (m^3), positive for the orientation above.
double signed_volume(const Eigen::MatrixX3d& V, const Eigen::MatrixX4i& T, int t);

struct MeshCheck {
  std::vector<int> inverted;    // signed volume < 0
  std::vector<int> degenerate;  // |volume| <= 1e-12 * (longest edge)^3, or repeated node
  bool ok() const { return inverted.empty() && degenerate.empty(); }
};
MeshCheck check_mesh(const TetMesh& mesh);

// Throws MeshError (prefix `what`) listing up to 10 offending element indices and the count
// when check_mesh(mesh) is not ok; also rejects out-of-range node indices and non-finite
// coordinates.
void validate_mesh(const TetMesh& mesh, const std::string& what);

}  // namespace liver_sim
