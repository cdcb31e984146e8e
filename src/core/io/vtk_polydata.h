// Legacy VTK POLYDATA files (ASCII or BINARY, file versions up to 5.1), shared by the surface
// reader (polygons) and the vessel-tree reader (polylines and their point arrays).
// Internal to the core library.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "byte_cursor.h"

namespace liver_sim {

// Cells of one kind as offsets into a connectivity list: cell c has the points
// connectivity[offsets[c]] .. connectivity[offsets[c + 1] - 1], every index < the point count.
struct VtkCells {
  std::vector<long long> offsets{0};
  std::vector<long long> connectivity;
  long long size() const { return static_cast<long long>(offsets.size()) - 1; }
};

struct VtkPolyData {
  Eigen::MatrixX3d points;  // file units
  bool has_points = false;
  VtkCells vertices, lines, polygons, strips;
  // Point data by array name (SCALARS, VECTORS, NORMALS, TEXTURE_COORDINATES, TENSORS and FIELD
  // arrays): #points x components. Cell data and dataset field data are read and dropped.
  std::map<std::string, Eigen::MatrixXd> point_arrays;
};

// Throws FormatError naming `origin` and the line or byte at fault. Every count is checked
// against the data left before anything is allocated.
VtkPolyData read_vtk_polydata(const std::string& data, const std::string& origin);

}  // namespace liver_sim
