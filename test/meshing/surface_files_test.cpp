// Surface files (doc/patient_model.md): every format written and read back, files as other tools
// write them, malformed files refused with the defect named. Each test names the deliberate
// mutation of the code it guards that it was seen to fail on.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "liver_sim/geometry/mesh_quality.h"
#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/io/mesh_io.h"
#include "liver_sim/io/surface_io.h"
#include "liver_sim/io/vessel_io.h"
#include "liver_sim/meshing/anatomy.h"
#include "liver_sim/meshing/surface_deviation.h"
#include "liver_sim/meshing/surface_repair.h"
#include "liver_sim/meshing/volume_mesher.h"
#include "liver_sim/simulation/liver_model.h"
#include "surface_fixtures.h"

namespace liver_sim {
namespace {

using namespace meshing_test;

// ---- readers and writers

// Every format and encoding written then read gives the same triangles (STL: after the merge of
// its per-corner vertices, binary in float32). Kills: the VTK binary reader in little-endian
// order (tried).
TEST(SurfaceFiles, EveryFormatRoundTrips) {
  const SurfaceMesh box = box_surface();
  for (const char* name : {"a.stl", "a.obj", "a.ply", "a.vtk"})
    for (SurfaceEncoding encoding : {SurfaceEncoding::Ascii, SurfaceEncoding::Binary}) {
      const std::string path = (temp_dir() / name).string();
      write_surface(path, box, encoding);
      const SurfaceMesh back = read_surface(path);
      const bool stl = surface_format(path) == SurfaceFormat::Stl;
      SCOPED_TRACE(std::string(name) + (encoding == SurfaceEncoding::Binary ? " binary" : " ascii"));
      if (!stl) {
        EXPECT_EQ(back.V, box.V);
        EXPECT_EQ(back.F, box.F);
        continue;
      }
      ASSERT_EQ(back.V.rows(), 3 * box.F.rows());  // STL: one vertex per corner
      const SurfaceMesh merged = repair_surface(back, path);
      EXPECT_EQ(merged.V.rows(), box.V.rows());
      SurfaceMesh expected = box;  // what a binary STL stores: float32 coordinates
      if (encoding == SurfaceEncoding::Binary) expected.V = box.V.cast<float>().cast<double>();
      EXPECT_EQ(oriented_triangles(merged), oriented_triangles(expected));
    }
}

// Files as other tools write them, each against values written by hand. Kills: the PLY binary
// reader ignoring its byte order, an STL starting with "solid" taken as ASCII without looking at
// its bytes (both tried).
TEST(SurfaceFiles, ReadsWhatOtherToolsWrite) {
  // OBJ: quads split into two triangles, v/vt/vn references, negative (relative) indices.
  const SurfaceMesh obj = read_surface(
      "# exported\no liver\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
      "f 1/1/1 2/1/1 3/1/1 4/1/1\nf -4//1 -2//1 -1//1\n",
      SurfaceFormat::Obj, "a.obj", 10.0);
  ASSERT_EQ(obj.F.rows(), 3);
  EXPECT_EQ(obj.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(obj.F.row(2), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(obj.V(2, 1), 10.0);  // the scale applies

  // ASCII PLY with colours, a vertex_index list and an element the reader does not use.
  const SurfaceMesh ply = read_surface(
      "ply\nformat ascii 1.0\ncomment x\nelement vertex 3\nproperty float y\nproperty float x\nproperty uchar red\n"
      "property float z\nelement face 1\nproperty list uchar uint vertex_index\nelement edge 1\n"
      "property int vertex1\nproperty int vertex2\nend_header\n1 2 255 3\n4 5 0 6\n7 8 0 9\n3 2 1 0\n0 1\n",
      SurfaceFormat::Ply, "a.ply");
  EXPECT_EQ(ply.V.row(0), Eigen::RowVector3d(2, 1, 3));  // x, y, z by name, not by position
  EXPECT_EQ(ply.F.row(0), Eigen::RowVector3i(2, 1, 0));

  // Big-endian binary PLY (the writer writes little-endian).
  std::string be = "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
                   "property double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  auto put_be = [&](const void* p, size_t n) {
    for (size_t i = 0; i < n; ++i) be += static_cast<const char*>(p)[n - 1 - i];
  };
  for (double v : {0.5, 0.0, 0.0, 0.0, 0.25, 0.0, 0.0, 0.0, 0.125}) put_be(&v, 8);
  be += '\3';
  for (int32_t i : {0, 1, 2}) put_be(&i, 4);
  const SurfaceMesh ply_be = read_surface(be, SurfaceFormat::Ply, "be.ply");
  // A binary STL whose header starts with "solid", as several CAD exporters write it.
  const std::string stl_path = (temp_dir() / "solid_header.stl").string();
  write_surface(stl_path, box_surface());
  std::fstream stl(stl_path, std::ios::in | std::ios::out | std::ios::binary);
  stl.write("solid liver", 11);
  stl.close();
  EXPECT_EQ(read_surface(stl_path).F.rows(), box_surface().F.rows());
  EXPECT_EQ(ply_be.V(1, 1), 0.25);
  EXPECT_EQ(ply_be.F.row(0), Eigen::RowVector3i(0, 1, 2));

  // Legacy VTK 5.1 (VTK 9): OFFSETS and CONNECTIVITY, a triangle strip, METADATA and a FIELD.
  const SurfaceMesh vtk = read_surface(
      "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET POLYDATA\nPOINTS 5 float\n0 0 0 1 0 0 0 1 0 1 1 0 1 2 0\n"
      "METADATA\nINFORMATION 0\n\nTRIANGLE_STRIPS 2 5\nOFFSETS vtktypeint64\n0 5\nCONNECTIVITY vtktypeint64\n0 1 2 3 4\n"
      "POINT_DATA 5\nFIELD FieldData 1\nNormals 3 5 float\n0 0 1 0 0 1 0 0 1 0 0 1 0 0 1\n",
      SurfaceFormat::Vtk, "a.vtk");
  ASSERT_EQ(vtk.F.rows(), 3);
  // A strip keeps one orientation: (0 1 2), (2 1 3), (2 3 4) all face +z.
  for (int t = 0; t < 3; ++t) {
    const Eigen::Vector3d a = vtk.V.row(vtk.F(t, 0)), b = vtk.V.row(vtk.F(t, 1)), c = vtk.V.row(vtk.F(t, 2));
    EXPECT_GT((b - a).cross(c - a).z(), 0) << "triangle " << t;
  }
}

// Each malformed file is refused with the defect named. Kills: dropping the binary STL size
// check (the reader then stops at the end of the data with another message; tried).
TEST(SurfaceFiles, MalformedFilesNameTheDefect) {
  EXPECT_NE(read_error("", SurfaceFormat::Stl).find("empty file"), std::string::npos);
  EXPECT_NE(read_error("solid liver\nendsolid liver\n", SurfaceFormat::Stl).find("no triangles"), std::string::npos);
  EXPECT_NE(read_error("solid x\nfacet normal 0 0 1\nouter loop\nvertex nan 0 0\n", SurfaceFormat::Stl).find("not finite"),
            std::string::npos);
  const std::string nan_obj = read_error("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", SurfaceFormat::Obj);
  EXPECT_NE(nan_obj.find("vertex 0 has a non-finite coordinate"), std::string::npos) << nan_obj;
  // A binary STL whose header announces more triangles than the file holds.
  std::string stl(80, 'x');
  const uint32_t lie = 1000;
  stl.append(reinterpret_cast<const char*>(&lie), 4);
  stl.append(2 * 50, '\0');
  const std::string lying = read_error(stl, SurfaceFormat::Stl);
  EXPECT_NE(lying.find("announces 1000 triangles"), std::string::npos) << lying;
  EXPECT_NE(lying.find("has 184 bytes"), std::string::npos) << lying;
  EXPECT_NE(read_error("v 0 0 0\nf 1 2 3\n", SurfaceFormat::Obj).find("out of range"), std::string::npos);
  EXPECT_NE(read_error("ply\nformat ascii 1.0\nelement vertex 99999999\nproperty float x\nend_header\n1\n", SurfaceFormat::Ply)
                .find("cannot fit"),
            std::string::npos);
  EXPECT_NE(read_error("# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\n", SurfaceFormat::Vtk)
                .find("expected DATASET POLYDATA"),
            std::string::npos);
  EXPECT_THROW(surface_format("liver.stp"), MeshError);
}

}  // namespace
}  // namespace liver_sim
