// Patient frames and anatomical landmarks of the liver.
//
// The model frame (`liver`, the node's ~frame_id) is the patient's LPS frame, as DICOM defines it:
// +x toward the patient's left, +y posterior, +z superior (head), in metres; right-handed, so
// REP 103 and tf hold. Segmentations come in LPS (DICOM, ITK, ITK-SNAP; 3D Slicer writes models in
// LPS since 4.11) or in RAS (older 3D Slicer files, FreeSurfer); RAS to LPS is a half turn about z.
#pragma once

#include <Eigen/Core>
#include <string>

#include "liver_sim/geometry/region.h"
#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

enum class PatientFrame {
  LPS,  // +x left, +y posterior, +z superior: the model frame
  RAS   // +x right, +y anterior, +z superior
};

// Rows of V (points in `frame`) in LPS. RAS -> LPS negates x and y: a rotation, so triangles keep
// their orientation.
Eigen::MatrixX3d to_lps(const Eigen::MatrixX3d& V, PatientFrame frame);

// The bare area, where the liver is attached to the diaphragm around the vena cava and not
// covered by peritoneum: a sphere of radius 0.25 times the liver's largest extent centred on the
// surface's most posterior-superior point (largest y + z in LPS). A default to check against the
// images: the segmentation does not show the diaphragm. Its size: large enough that a 2 L liver
// hangs from it under gravity in `simulate` without swinging about it (doc/patient_model.md).
Region bare_area(const SurfaceMesh& surface_lps);

}  // namespace liver_sim
