// Label maps as segmentation tools write them (3D Slicer, ITK-SNAP, deep-learning pipelines):
// NIfTI-1 (.nii, .nii.gz) and NRRD (.nrrd, .seg.nrrd; raw, gzip or text). The voxels' positions
// come from the file's spacing, origin and direction, converted to the patient's LPS frame in
// metres (NIfTI's qform and sform are RAS: x and y negated). The input of make_model's
// --label-map (doc/patient_model.md); meshing/voxel_mask.h takes one label out.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

enum class LabelMapFormat {
  Nifti,  // NIfTI-1 single file (magic n+1), either byte order, gzip-compressed or not
  Nrrd    // NRRD with its data attached (no detached .nhdr), encoding raw, gzip or text
};

struct LabelImage {
  Eigen::Array3i dims = Eigen::Array3i::Zero();        // voxels along i, j, k (i fastest)
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();  // columns: one step of i, j, k (m, LPS)
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();    // centre of voxel (0, 0, 0) (m, LPS)
  std::vector<std::int32_t> labels;                    // one per voxel
  // 3D Slicer's segment names with their label values (.seg.nrrd: SegmentN_Name and
  // SegmentN_LabelValue); empty for other files.
  std::vector<std::pair<std::string, int>> segments;
  std::string orientation_source;  // how the positions were found, e.g. "sform", "qform", "space directions"
};

// By the extension, case-insensitive: .nii, .nii.gz, .nrrd (.seg.nrrd too). Throws MeshError.
LabelMapFormat label_map_format(const std::string& path);
bool is_label_map(const std::string& path);

// Reads a label map. Voxel values must be whole numbers (any integer or floating type, after
// NIfTI's scl_slope and scl_inter); lengths are taken in the file's unit (NIfTI xyzt_units,
// NRRD space units; millimetres when the file does not say). Throws MeshError naming the file
// and the defect: truncated or corrupt data, a header whose sizes the data cannot hold, more than
// 2^28 voxels, a dimension other than 3 (NIfTI allows trailing sizes of 1), a singular or
// non-finite direction, an unsupported type, encoding or detached data, a fractional or
// non-finite voxel value.
LabelImage read_label_map(const std::string& path);
// The same from the file's bytes; `origin` names the source in messages.
LabelImage read_label_map(const std::string& bytes, LabelMapFormat format, const std::string& origin);

}  // namespace liver_sim
