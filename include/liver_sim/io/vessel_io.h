// Vessel tree files: centre-line graphs in legacy VTK polydata or YAML (formats in README.md,
// "Vessel trees"); every error names the file and the node or segment at fault.
#pragma once

#include <istream>
#include <string>

#include "liver_sim/geometry/vessel_tree.h"

namespace liver_sim {

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

// Writes the tree in the package's format (legacy VTK ASCII polydata, metres, every digit kept).
// Throws VesselError when the file cannot be written.
void write_vessel_vtk(const std::string& path, const VesselTree& tree, const std::string& title);

}  // namespace liver_sim
