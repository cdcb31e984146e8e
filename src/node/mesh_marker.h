// Conversion of the model's deformed surface, vessels and targets into rviz markers.
#pragma once

#include <std_msgs/ColorRGBA.h>
#include <std_msgs/Header.h>
#include <visualization_msgs/Marker.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>
#include <string>
#include <utility>
#include <vector>

#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/registration.h"

namespace liver_sim {

// Colour of a displacement magnitude u (m): a ramp from a pale tissue tone (0) through yellow,
// orange and red to dark red (scale_max, m); larger values stay dark red.
std_msgs::ColorRGBA displacement_colour(double u, double scale_max);

// Unit outward normals at the nodes of the boundary triangles F at positions x (3 #V, m): the
// area-weighted mean of the adjacent triangles' normals; zero rows for interior nodes.
Eigen::MatrixX3d vertex_normals(const Eigen::MatrixX3i& F, const Eigen::VectorXd& x);

// The unit vector toward the viewer of the package's rviz config, in the model frame
// (config/liver_sim.rviz's orbit view: in front, -y, and above, +z). The surface's light comes
// from it (rviz lights no surface with per-vertex colours, so the markers carry their shading)
// and the target labels are laid out in its view.
extern const Eigen::Vector3d kViewerDirection;

// TRIANGLE_LIST of the boundary triangles at the current positions (m). Each vertex is coloured
// by its displacement from `reference` (3 #V, m: the pre-operative equilibrium, or the rest shape)
// on the displacement_colour ramp, darkened by a diffuse light from kViewerDirection so that the
// shape shows. `alpha` in [0, 1]: 1 draws an opaque surface; below 1 the vessels show through,
// and the triangles are ordered back to front as seen from kViewerDirection, because rviz blends
// a translucent marker's triangles in their order without sorting them.
void fill_mesh_marker(const LiverModel& model, const Eigen::VectorXd& reference, double scale_max, double alpha,
                      visualization_msgs::Marker& marker);

// LINE_LIST of the vessel beams at their current positions (m), one colour per vessel tree.
void fill_vessel_marker(const LiverModel& model, visualization_msgs::Marker& marker);

// A target's label: a probe's name; a bifurcation's vessel initial and number ("portal
// bifurcation 3": "P3"), short enough to stay apart from its neighbours.
std::string target_label(const TrackedTarget& target);

// The targets that carry a label, with their texts: every target, except that a probe named
// "<stem>_centre" speaks for the probes named "<stem>_*" (a tumour's centre and the points on its
// margin): one label "<stem>" for the group, on the centre.
std::vector<std::pair<size_t, std::string>> labelled_targets(const std::vector<TrackedTarget>& targets);

// Text of TEXT_VIEW_FACING markers `height` (m) high: half the width of a label of `text`, about
// 0.6 of the height per character, with a tenth of the height free on each side.
double label_half_width(const std::string& text, double height);

// Labels laid out off the organ in the view from kViewerDirection: `at`, their centres (m);
// `inner`, the end of each label that faces the organ, where a leader line from its anchor ends.
struct LabelLayout {
  std::vector<Eigen::Vector3d> at, inner;
};

// Where labels of `height` (m) go: in a column left of the organ's silhouette (`organ`: its node
// positions, 3 #V, m) for the anchors left of its middle, in one right of it for the others, a
// height's gap from it; in a column, in the order of their anchors' heights in the view, a line
// apart or more, each as near its anchor's height as that allows. All lie in the
// plane facing the viewer through the organ's point nearest to it: in front of the organ, and
// scaled alike by the view's perspective, so that apart in this plane is apart on the screen.
LabelLayout label_positions(const std::vector<Eigen::Vector3d>& anchors, const std::vector<std::string>& texts,
                            double height, const Eigen::VectorXd& organ);

// The labelled targets' labels (labelled_targets) as TEXT_VIEW_FACING markers 6 mm high placed by
// label_positions around the organ at `organ` (namespace "target_names", id = the target's
// index, as the target spheres, so that the spheres stay plain), and a LINE_LIST of leader lines
// from each target to its label (namespace "target_leaders").
void append_target_names(const std::vector<TrackedTarget>& targets, const Eigen::VectorXd& organ,
                                        const std_msgs::Header& header, visualization_msgs::MarkerArray& markers);

// The patient's axes in front of and below `box` (the model's rest bounding box, m), left of the
// colour legend (append_colour_legend): arrows along +x, +y, +z labelled L, P, S (the model frame is LPS: the patient's left, posterior,
// superior); namespace "orientation".
void append_orientation_axes(const Eigen::AlignedBox3d& box, const std_msgs::Header& header,
                             visualization_msgs::MarkerArray& markers);

// The colour scale's legend under `box` (the model's rest bounding box, m): a horizontal bar of
// cubes 8 cm long from 0 (left, -x) to scale_max (right, m) in front of and below the box, under
// its middle (where the package's view has room: the labels take its sides), labelled in mm
// below, and a title at its right end; namespace "legend".
void append_colour_legend(const Eigen::AlignedBox3d& box, double scale_max, const std_msgs::Header& header,
                          visualization_msgs::MarkerArray& markers);

// What ~targets shows besides the target spheres: the targets' labels (append_target_names) around
// the organ at `organ` (3 #V, m), the patient's axes and the colour legend by `rest` (the model's
// rest bounding box, m).
void append_annotations(const std::vector<TrackedTarget>& targets, const Eigen::VectorXd& organ,
                        const Eigen::AlignedBox3d& rest, double scale_max, const std_msgs::Header& header,
                        visualization_msgs::MarkerArray& markers);

}  // namespace liver_sim
