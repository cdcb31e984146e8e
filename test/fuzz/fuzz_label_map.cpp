// libFuzzer target: the label-map readers (NIfTI-1, NRRD; raw, gzip, text) must end in an image
// or a MeshError, whatever the bytes.
#include <cstdint>
#include <string>

#include "liver_sim/io/label_map_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  for (const liver_sim::LabelMapFormat format : {liver_sim::LabelMapFormat::Nifti, liver_sim::LabelMapFormat::Nrrd}) {
    try {
      liver_sim::read_label_map(bytes, format, "fuzz");
    } catch (const liver_sim::MeshError&) {
    }
  }
  return 0;
}
