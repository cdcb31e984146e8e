// Vascular trees as centre-line graphs: node positions, outer radius and wall thickness per
// node, segments between nodes, and their validation. Read and written by io/vessel_io.h.
#pragma once

#include <Eigen/Core>
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

// Throws VesselError for: non-finite coordinates, radius <= 0, wall <= 0 or thicker than the
// radius, a segment with an out-of-range or repeated node or zero length, a segment closing a
// cycle, a node in no segment, an empty tree.
void validate_vessel_tree(const VesselTree& tree, const std::string& origin);

}  // namespace liver_sim
