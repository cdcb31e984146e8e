// Tetrahedral mesh files: Gmsh and legacy VTK readers and writers.
#pragma once

#include <istream>
#include <string>

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

// Reads a tetrahedral mesh. Formats, chosen by content: Gmsh legacy 1.0 ($NOD/$ELM), Gmsh 2.2
// ASCII and Gmsh 4.1 ASCII ($MeshFormat), legacy VTK ASCII UNSTRUCTURED_GRID (.vtk).
// Non-tetrahedral elements are ignored; nodes used by no tetrahedron are dropped.
// Every coordinate is multiplied by `scale` (file unit -> m).
// A mesh whose tetrahedra are all negatively oriented is reoriented (a file convention); a mesh
// with a mix of orientations, degenerate tetrahedra, or no tetrahedra throws MeshError naming
// the offending element indices.
TetMesh read_mesh(const std::string& path, double scale = 1.0);
// Same, from a stream; `path` names the source in messages.
TetMesh read_mesh(std::istream& stream, const std::string& path, double scale = 1.0);

void write_gmsh22(const std::string& path, const TetMesh& mesh);
void write_gmsh41(const std::string& path, const TetMesh& mesh);
void write_vtk(const std::string& path, const TetMesh& mesh);

}  // namespace liver_sim
