// Vascular trees as centre-line graphs: node positions, outer radius and wall thickness per
// node, segments between nodes. Loaded from legacy VTK polydata or YAML (formats in README.md,
// "Vessel trees"); every error names the file and the node or segment at fault.
#pragma once

#include <Eigen/Core>
#include <istream>
#include <stdexcept>
#include <string>

namespace liver_sim {

struct VesselTree {
  Eigen::MatrixX3d points;         // centre-line nodes (m)
  Eigen::VectorXd radius;          // outer radius per node (m)
  Eigen::VectorXd wall_thickness;  // wall thickness per node (m), 0 < t <= radius
  Eigen::MatrixX2i segments;       // node index pairs (0-based)
};

class VesselError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// By extension: .vtk (legacy ASCII POLYDATA: POINTS, LINES, POINT_DATA scalars `radius` and
// `wall_thickness`) or .yaml/.yml (`nodes: [[x, y, z, radius, wall], ...]`, `segments: [[i, j],
// ...]`). Lengths are multiplied by `scale` (file unit -> m). The tree is validated.
VesselTree read_vessel_tree(const std::string& path, double scale = 1.0);
// The same readers on text; `origin` names the source in messages.
VesselTree read_vessel_vtk(std::istream& in, const std::string& origin, double scale = 1.0);
VesselTree read_vessel_yaml(const std::string& text, const std::string& origin, double scale = 1.0);

// Throws VesselError for: non-finite coordinates, radius <= 0, wall <= 0 or thicker than the
// radius, a segment with an out-of-range or repeated node or zero length, a segment closing a
// cycle, a node in no segment, an empty tree.
void validate_vessel_tree(const VesselTree& tree, const std::string& origin);

}  // namespace liver_sim
