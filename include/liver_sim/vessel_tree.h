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

// By extension: .vtk (legacy POLYDATA, ASCII or BINARY: POINTS, LINES, point arrays `radius`
// and `wall_thickness` as SCALARS or FIELD arrays) or .yaml/.yml (`nodes: [[x, y, z, radius,
// wall], ...]`, `segments: [[i, j], ...]`). Lengths are multiplied by `scale` (file unit -> m).
// The tree is validated.
// VMTK's centrelines are read too: without `radius`, the radius is VMTK's
// `MaximumInscribedSphereRadius`; without `wall_thickness`, the wall is `wall_ratio` times the
// radius when wall_ratio > 0 (else the file is refused: the format has no wall).
VesselTree read_vessel_tree(const std::string& path, double scale = 1.0, double wall_ratio = 0.0);
// The same readers on text; `origin` names the source in messages.
VesselTree read_vessel_vtk(std::istream& in, const std::string& origin, double scale = 1.0, double wall_ratio = 0.0);
VesselTree read_vessel_yaml(const std::string& text, const std::string& origin, double scale = 1.0);

// Throws VesselError for: non-finite coordinates, radius <= 0, wall <= 0 or thicker than the
// radius, a segment with an out-of-range or repeated node or zero length, a segment closing a
// cycle, a node in no segment, an empty tree.
void validate_vessel_tree(const VesselTree& tree, const std::string& origin);

// Writes the tree in the package's format (legacy VTK ASCII polydata, metres, every digit kept).
// Throws VesselError when the file cannot be written.
void write_vessel_vtk(const std::string& path, const VesselTree& tree, const std::string& title);

}  // namespace liver_sim
