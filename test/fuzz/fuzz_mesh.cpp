// libFuzzer target: the mesh loaders must end in a mesh or a MeshError, nothing else.
#include <cstdint>
#include <sstream>
#include <string>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/io/mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const liver_sim::TetMesh m = liver_sim::read_mesh(in, "fuzz.msh");
    liver_sim::boundary_triangles(m.T);  // a loaded mesh must be usable
  } catch (const liver_sim::MeshError&) {
  }
  return 0;
}
