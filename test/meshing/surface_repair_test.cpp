// Segmented surfaces checked before meshing: each repair and each refusal, named and located.
// Each test names the deliberate mutation of the code it guards that it was seen to fail on.
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

// ---- repairs

// STL's per-corner vertices become one vertex per position. Kills: skipping the merge (tried: the
// surface is then refused as open, no edge being shared).
TEST(SurfaceRepair, MergesDuplicateVertices) {
  const SurfaceMesh box = box_surface();
  SurfaceMesh soup;
  soup.V.resize(3 * box.F.rows(), 3);
  soup.F.resize(box.F.rows(), 3);
  for (Eigen::Index t = 0; t < box.F.rows(); ++t)
    for (int k = 0; k < 3; ++k) {
      soup.V.row(3 * t + k) = box.V.row(box.F(t, k));
      soup.F(t, k) = static_cast<int>(3 * t + k);
    }
  SurfaceRepairs r;
  const SurfaceMesh merged = repair_surface(soup, "soup.stl", {}, &r);
  EXPECT_EQ(merged.V.rows(), box.V.rows());
  EXPECT_EQ(r.merged_vertices, 3 * box.F.rows() - box.V.rows());
  EXPECT_EQ(oriented_triangles(merged), oriented_triangles(box));
  // Vertices 1e-3 apart are one vertex only when the merge distance says so.
  soup.V(0, 0) += 1e-3;
  EXPECT_NE(repair_error(soup).find("open boundary"), std::string::npos);
  SurfaceRepairOptions wide;
  wide.merge_distance = 2e-3;
  EXPECT_EQ(repair_surface(soup, "soup.stl", wide).V.rows(), box.V.rows());
}

// One triangle turned the wrong way is turned back, the others stay. Kills: dropping the
// propagation of orientation to neighbours (tried: the triangle stays inward).
TEST(SurfaceRepair, TurnsAFlippedTriangleBack) {
  const SurfaceMesh box = box_surface();
  for (int flipped : {0, 17}) {  // also the first triangle, where the walk over the shell starts
    SurfaceMesh s = box;
    std::swap(s.F(flipped, 1), s.F(flipped, 2));
    SurfaceRepairs r;
    const SurfaceMesh fixed = repair_surface(s, "liver.stl", {}, &r);
    EXPECT_EQ(r.reoriented_triangles, 1);
    EXPECT_FALSE(r.inside_out);
    EXPECT_EQ(oriented_triangles(fixed), oriented_triangles(box)) << "flipped " << flipped;
  }
}

// A surface whose every normal points inward is turned whole. Kills: dropping the volume sign
// test (tried: the inward surface passes as it is).
TEST(SurfaceRepair, TurnsAnInsideOutSurface) {
  const SurfaceMesh box = box_surface();
  SurfaceMesh s = box;
  s.F.col(1).swap(s.F.col(2));
  SurfaceRepairs r;
  const SurfaceMesh fixed = repair_surface(s, "liver.stl", {}, &r);
  EXPECT_TRUE(r.inside_out);
  EXPECT_EQ(oriented_triangles(fixed), oriented_triangles(box));
  EXPECT_NEAR(enclosed_volume(fixed), 100.3 * 80.7 * 60.1, 1e-6 * 100.3 * 80.7 * 60.1);
}

// Collapsed and repeated triangles are dropped. Kills: keeping duplicates (tried: their edges
// have three triangles, refused as non-manifold).
TEST(SurfaceRepair, DropsCollapsedAndDuplicateTriangles) {
  const SurfaceMesh box = box_surface();
  SurfaceMesh s = box;
  s.F.conservativeResize(s.F.rows() + 2, 3);
  s.F.row(s.F.rows() - 2) = box.F.row(3);
  s.F.row(s.F.rows() - 1) << 4, 4, 7;
  SurfaceRepairs r;
  const SurfaceMesh fixed = repair_surface(s, "liver.stl", {}, &r);
  EXPECT_EQ(r.duplicate_triangles, 1);
  EXPECT_EQ(r.collapsed_triangles, 1);
  EXPECT_EQ(oriented_triangles(fixed), oriented_triangles(box));
}

SurfaceMesh join(const SurfaceMesh& a, const SurfaceMesh& b) {
  SurfaceMesh s;
  s.V.resize(a.V.rows() + b.V.rows(), 3);
  s.V << a.V, b.V;
  s.F.resize(a.F.rows() + b.F.rows(), 3);
  s.F << a.F, (b.F.array() + static_cast<int>(a.V.rows())).matrix();
  return s;
}

// Two disjoint shells: refused, or the larger kept when asked. Kills: keeping the first shell
// instead of the largest (tried; the small box comes first here).
TEST(SurfaceRepair, SeveralShellsRefusedOrLargestKept) {
  const SurfaceMesh small = box_surface({10, 10, 10}, {500, 0, 0}), large = box_surface();
  const SurfaceMesh both = join(small, large);
  const std::string e = repair_error(both);
  EXPECT_NE(e.find("2 disconnected shells"), std::string::npos) << e;
  EXPECT_NE(e.find("--largest-shell"), std::string::npos) << e;
  SurfaceRepairOptions keep;
  keep.keep_largest_shell = true;
  SurfaceRepairs r;
  const SurfaceMesh kept = repair_surface(both, "liver.stl", keep, &r);
  EXPECT_EQ(r.dropped_shells, 1);
  EXPECT_NEAR(enclosed_volume(kept), 100.3 * 80.7 * 60.1, 1e-6 * 100.3 * 80.7 * 60.1);
}

// ---- refusals

// A triangle removed: the hole is named with its edge. Kills: dropping the open-edge check (tried:
// the orientation walk then reads past the missing neighbour).
TEST(SurfaceRefusals, OpenBoundaryNamesTheEdge) {
  SurfaceMesh s = box_surface();
  s.F.row(5) = s.F.row(s.F.rows() - 1);
  s.F.conservativeResize(s.F.rows() - 1, 3);
  const std::string e = repair_error(s);
  EXPECT_NE(e.find("open boundary"), std::string::npos) << e;
  EXPECT_NE(e.find("3 edges belong to one triangle only"), std::string::npos) << e;
  EXPECT_NE(e.find("the edge vertex"), std::string::npos) << e;  // with indices and coordinates
  EXPECT_NE(e.find("liver.stl"), std::string::npos) << e;
}

// A fin: a third triangle on an edge of the closed box, named as the non-manifold edge rather than
// as the hole its free edges also make. Kills: dropping the non-manifold check (tried).
TEST(SurfaceRefusals, NonManifoldEdge) {
  SurfaceMesh s = box_surface();
  const int a = s.F(0, 0), b = s.F(0, 1);
  s.V.conservativeResize(s.V.rows() + 1, 3);
  s.V.row(s.V.rows() - 1) = s.V.row(a) + Eigen::RowVector3d(0, 0, 500);
  s.F.conservativeResize(s.F.rows() + 1, 3);
  s.F.row(s.F.rows() - 1) << a, b, static_cast<int>(s.V.rows() - 1);
  const std::string e = repair_error(s);
  EXPECT_NE(e.find("non-manifold edge"), std::string::npos) << e;
  EXPECT_NE(e.find("shared by 3 triangles"), std::string::npos) << e;
}

// Two boxes touching at one corner share a vertex and no edge. Kills: skipping the fan check
// (tried).
TEST(SurfaceRefusals, NonManifoldVertex) {
  const SurfaceMesh a = box_surface({10, 10, 10}, {0, 0, 0}), b = box_surface({10, 10, 10}, {10, 10, 10});
  const std::string e = repair_error(join(a, b));
  EXPECT_NE(e.find("non-manifold vertex"), std::string::npos) << e;
  EXPECT_NE(e.find("(10, 10, 10)"), std::string::npos) << e;
}

// A top-face vertex pushed down through the bottom face. Kills: dropping the triangle-triangle
// test (tried), or counting only crossings strictly inside a triangle (it was: on this regular
// grid the fold meets the bottom's edges exactly).
TEST(SurfaceRefusals, SelfIntersection) {
  SurfaceMesh s = box_surface();
  // The top-face vertex nearest the face's centre: an interior vertex of that face.
  const double top_z = s.V.col(2).maxCoeff();
  Eigen::Index top = -1;
  for (Eigen::Index i = 0; i < s.V.rows(); ++i)
    if (s.V(i, 2) == top_z && (top < 0 || std::hypot(s.V(i, 0) - 37.8, s.V(i, 1) - 43.6) <
                                              std::hypot(s.V(top, 0) - 37.8, s.V(top, 1) - 43.6)))
      top = i;
  s.V(top, 2) -= 200;
  const std::string e = repair_error(s);
  EXPECT_NE(e.find("self-intersection"), std::string::npos) << e;
  EXPECT_NE(e.find("triangle"), std::string::npos) << e;
}

// A surface built in memory (no reader to check it): no triangles, a NaN, 1e300.
TEST(SurfaceRefusals, EmptyNonFiniteAndGiganticCoordinates) {
  EXPECT_NE(repair_error(SurfaceMesh()).find("no triangles"), std::string::npos);
  SurfaceMesh s = box_surface();
  s.V(3, 1) = std::nan("");
  EXPECT_NE(repair_error(s).find("vertex 3 has a non-finite coordinate"), std::string::npos);
  s = box_surface();
  s.V(3, 1) = 1e300;
  EXPECT_NE(repair_error(s).find("coordinates too large"), std::string::npos);
}

}  // namespace
}  // namespace liver_sim
