// libFuzzer target: the scene parser must end in a Scene or a SceneError, nothing else.
#include <cstdint>
#include <string>

#include "liver_sim/scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    liver_sim::parse_scene(std::string(reinterpret_cast<const char*>(data), size), "/fuzz", "fuzz.yaml");
  } catch (const liver_sim::SceneError&) {
  }
  return 0;
}
