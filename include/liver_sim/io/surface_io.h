// Closed triangle surfaces as segmentation tools write them (3D Slicer, ITK-SNAP, planning
// software): STL, OBJ, PLY and legacy VTK polydata readers and writers. The input of make_model
// (doc/patient_model.md); meshing/surface_repair.h checks and repairs them.
#pragma once

#include <string>

#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

enum class SurfaceFormat {
  Stl,  // ASCII or binary (told apart by the size the binary header announces), one vertex per
        // corner: nothing is shared until repair_surface merges duplicates
  Obj,  // Wavefront: v and f lines (v/vt/vn, negative indices), the rest ignored
  Ply,  // ASCII, binary little- or big-endian: element vertex (x, y, z), element face
        // (vertex_indices or vertex_index); other elements and properties skipped
  Vtk   // legacy VTK POLYDATA, ASCII or BINARY, file versions up to 5.1: POLYGONS and TRIANGLE_STRIPS
};

// By the extension, case-insensitive: .stl .obj .ply .vtk. Throws MeshError naming the file.
SurfaceFormat surface_format(const std::string& path);

// Reads a surface; polygons with more than 3 corners are split into a fan of triangles from
// their first corner. Every coordinate is multiplied by `scale`. Throws MeshError naming the file
// and the line or byte at fault: unknown format, truncated data, a count the file cannot hold
// (a binary STL whose triangle count disagrees with its size), an index out of range, a
// non-finite coordinate, no triangle at all.
SurfaceMesh read_surface(const std::string& path, double scale = 1.0);
// The same from the file's bytes; `origin` names the source in messages.
SurfaceMesh read_surface(const std::string& bytes, SurfaceFormat format, const std::string& origin,
                         double scale = 1.0);

// Writes by the extension of `path`. Binary: STL (float32), PLY (little-endian, float64) and VTK
// (big-endian as the format requires, float64); OBJ is always text. Text keeps every digit.
enum class SurfaceEncoding { Ascii, Binary };
void write_surface(const std::string& path, const SurfaceMesh& surface,
                   SurfaceEncoding encoding = SurfaceEncoding::Binary);

}  // namespace liver_sim
