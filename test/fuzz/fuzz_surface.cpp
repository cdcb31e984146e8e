// libFuzzer target: the surface readers (every format) must end in a surface or a MeshError, and
// the repair pass of a small surface read from the same bytes likewise.
#include <cstdint>
#include <string>

#include "liver_sim/io/surface_io.h"
#include "liver_sim/meshing/surface_repair.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  using liver_sim::SurfaceFormat;
  for (SurfaceFormat format : {SurfaceFormat::Stl, SurfaceFormat::Obj, SurfaceFormat::Ply, SurfaceFormat::Vtk}) {
    try {
      const liver_sim::SurfaceMesh s = liver_sim::read_surface(bytes, format, "fuzz");
      if (s.F.rows() > 5000) continue;  // the repair's cost grows with the surface, not its bugs
      liver_sim::SurfaceRepairOptions options;
      options.keep_largest_shell = size % 2 == 1;
      liver_sim::repair_surface(s, "fuzz", options);
    } catch (const liver_sim::MeshError&) {
    }
  }
  return 0;
}
