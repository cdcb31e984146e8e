// Tetrahedral meshing of a closed surface with gmsh's library (libgmsh): the surface is
// re-meshed at the target size (gmsh classifies it into patches that it can parametrise, then
// meshes them: a 500k-triangle segmentation becomes a few thousand boundary triangles on the same
// shape), then the volume is filled (Delaunay, optimised). Deterministic: one thread, fixed
// options and random seed, so the same surface gives the same mesh bit for bit on one machine.
// Each gmsh session runs in a child process (runtime/child_process.h) with a time budget of 30 s
// plus 1 ms per tetrahedron expected, at most 300 s: gmsh can loop without end on rare surfaces,
// and which ones depends on the heap's state (the environment). A session past its budget, or
// crashed, has failed.
// Built into liver_sim_mesher, not the core: the node and the simulator do not link gmsh.
#pragma once

#include <functional>
#include <string>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/surface_mesh.h"

namespace liver_sim {

struct VolumeMeshOptions {
  double element_size = 0;      // m, target edge length, > 0; <= 0: chosen for target_elements
  int target_elements = 10000;  // tetrahedra wanted when element_size <= 0 (about: within 15% when reached)
  double feature_angle = 40;    // degrees: surface creases sharper than this stay edges of the mesh
  double max_deviation = 0.5e-3;  // m, > 0: edges on curved parts shortened (down to a quarter of the
                                  // size) so that they bulge at most this far from the surface
  // > 0: a surface gmsh splits into more patches than this at the feature angle is taken for
  // stair-steps or noise, refused with RoughSurfaceError before any meshing (re-surface it)
  int max_patches = 0;
  // The surface is smooth and has no crease (a re-surfaced segmentation, a level set): it is
  // remeshed here at the curvature sizes (surface_remesh.h) and filled as it is, without gmsh's
  // patches, whose parametrisation of such surfaces fails or cuts thin rims.
  bool remesh_boundary = false;
  double gradation = 0.3;  // remesh_boundary: sizes grow at most this much per length along the surface
  // remesh_boundary, m, >= 0: the remeshed boundary then coarsened while it stays within this of
  // the surface (surface_coarsen.h; its edges up to 4/3 of the largest size); 0: not coarsened
  double coarsen_within = 0;
  std::function<void(const std::string&)> progress;  // one line per stage, e.g. "meshing volume"
};

class RoughSurfaceError : public MeshError {
 public:
  using MeshError::MeshError;
};

struct VolumeMeshReport {
  double element_size = 0;  // m, the size the final pass used
  int passes = 0;           // volume meshings (more when one missed the count or failed; a
                            // session stopped or crashed counts as one)
  bool curvature_sizing = true;  // false: gmsh failed with it and the mesh has a uniform size
};

// `surface`: closed, manifold, outward-oriented, in metres (repair_surface's output). Returns
// positively oriented tetrahedra (checked). Throws MeshError naming `origin` with gmsh's message when gmsh
// fails, RoughSurfaceError (see max_patches).
TetMesh mesh_volume(const SurfaceMesh& surface, const std::string& origin, const VolumeMeshOptions& options,
                    VolumeMeshReport* report = nullptr);

// The volume inside `boundary` filled with tetrahedra (gmsh's Delaunay and optimiser) whose
// boundary triangles are `boundary`'s own: no patches, no parametrisation, so the shape is the
// one given (surface_remesh.h makes such a boundary). Inside, sizes grow from the boundary's
// edges up to `max_size` (m). Throws MeshError naming `origin` with gmsh's message.
TetMesh fill_volume(const SurfaceMesh& boundary, double max_size, const std::string& origin);

}  // namespace liver_sim
