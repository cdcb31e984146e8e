#include "liver_sim/meshing/isosurface.h"

#include <vtkCellArray.h>
#include <vtkQuadricDecimation.h>
#include <vtkWindowedSincPolyDataFilter.h>
#include <vtkFloatArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkIdList.h>
#include <vtkImageData.h>
#include <vtkImageGaussianSmooth.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>

#include <Eigen/Geometry>
#include <cmath>

namespace liver_sim {

SurfaceMesh isosurface(const VoxelMask& mask, const IsosurfaceOptions& options, const std::string& origin) {
  if (!(options.smoothing > 0)) throw MeshError(origin + ": the smoothing must be > 0");
  // The field lives on the grid's indices (spacing 1); the blur's width per axis is the smoothing
  // over that axis' step, and the contour's points go through the grid's affine map at the end.
  auto image = vtkSmartPointer<vtkImageData>::New();
  image->SetDimensions(mask.dims[0], mask.dims[1], mask.dims[2]);
  auto values = vtkSmartPointer<vtkFloatArray>::New();
  values->SetNumberOfTuples(static_cast<vtkIdType>(mask.inside.size()));
  for (size_t v = 0; v < mask.inside.size(); ++v) values->SetValue(static_cast<vtkIdType>(v), mask.inside[v]);
  image->GetPointData()->SetScalars(values);

  auto blur = vtkSmartPointer<vtkImageGaussianSmooth>::New();
  blur->SetInputData(image);
  blur->SetDimensionality(3);
  blur->SetStandardDeviations(options.smoothing / mask.axes.col(0).norm(), options.smoothing / mask.axes.col(1).norm(),
                              options.smoothing / mask.axes.col(2).norm());
  blur->SetRadiusFactors(3, 3, 3);
  blur->SetNumberOfThreads(1);
  auto contour = vtkSmartPointer<vtkFlyingEdges3D>::New();
  contour->SetInputConnection(blur->GetOutputPort());
  contour->SetValue(0, 0.5);
  contour->ComputeNormalsOff();
  contour->ComputeGradientsOff();
  contour->ComputeScalarsOff();
  contour->Update();
  vtkSmartPointer<vtkPolyData> surface = contour->GetOutput();
  const vtkIdType contoured = surface->GetNumberOfPolys();
  if (contoured == 0) throw MeshError(origin + ": the smoothed volume has no surface (a piece thinner than the smoothing?)");
  // The contour of a blurred voxel volume still shows the voxels' facets (normals turning by
  // tens of degrees between neighbours, which gmsh would take for creases): a windowed-sinc
  // filter smooths them away without shrinking the volume.
  auto smooth = vtkSmartPointer<vtkWindowedSincPolyDataFilter>::New();
  smooth->SetInputData(surface);
  smooth->SetNumberOfIterations(20);
  smooth->SetPassBand(0.05);
  smooth->NormalizeCoordinatesOn();
  smooth->BoundarySmoothingOff();
  smooth->FeatureEdgeSmoothingOff();
  smooth->NonManifoldSmoothingOn();
  smooth->Update();
  surface = smooth->GetOutput();
  if (options.max_triangles > 0 && contoured > options.max_triangles) {
    // Quadric edge collapses keep the shape best for the triangles left; the volume is kept.
    auto decimate = vtkSmartPointer<vtkQuadricDecimation>::New();
    decimate->SetInputData(surface);
    decimate->SetTargetReduction(1.0 - static_cast<double>(options.max_triangles) / static_cast<double>(contoured));
    decimate->VolumePreservationOn();
    decimate->Update();
    surface = decimate->GetOutput();
  }

  SurfaceMesh s;
  const vtkIdType np = surface->GetNumberOfPoints();
  s.V.resize(np, 3);
  for (vtkIdType i = 0; i < np; ++i) {
    double p[3];
    surface->GetPoint(i, p);
    s.V.row(i) = (mask.origin + mask.axes * Eigen::Vector3d(p[0], p[1], p[2])).transpose();
  }
  s.F.resize(surface->GetNumberOfPolys(), 3);
  auto ids = vtkSmartPointer<vtkIdList>::New();
  vtkCellArray* polys = surface->GetPolys();
  polys->InitTraversal();
  Eigen::Index t = 0;
  while (polys->GetNextCell(ids))
    if (ids->GetNumberOfIds() == 3) {
      for (int k = 0; k < 3; ++k) s.F(t, k) = static_cast<int>(ids->GetId(k));
      ++t;
    }
  s.F.conservativeResize(t, 3);
  // Outward: the enclosed volume positive (the contour's own orientation, and the grid's
  // handedness, may turn it).
  double volume6 = 0;
  for (Eigen::Index f = 0; f < s.F.rows(); ++f)
    volume6 += s.V.row(s.F(f, 0)).dot(s.V.row(s.F(f, 1)).cross(s.V.row(s.F(f, 2))));
  if (volume6 < 0) s.F.col(1).swap(s.F.col(2));
  return s;
}

}  // namespace liver_sim
