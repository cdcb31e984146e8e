// libFuzzer target: both vessel-tree readers must end in a validated tree or a VesselError.
#include <cstdint>
#include <sstream>
#include <string>

#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/io/vessel_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    std::istringstream in(text);
    liver_sim::read_vessel_vtk(in, "fuzz.vtk");
  } catch (const liver_sim::VesselError&) {
  }
  try {
    liver_sim::read_vessel_yaml(text, "fuzz.yaml");
  } catch (const liver_sim::VesselError&) {
  }
  return 0;
}
