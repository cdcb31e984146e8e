#include "cloud_bridge.h"

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl_conversions/pcl_conversions.h>

#include "msg_conversion.h"

namespace liver_sim {

std::string cloud_layout_error(const sensor_msgs::PointCloud2& c) {
  if (static_cast<uint64_t>(c.width) * c.height == 0) return "empty cloud";
  const std::string too_large = cloud_size_error(static_cast<uint64_t>(c.width) * c.height);
  if (!too_large.empty()) return too_large;
  if (static_cast<uint64_t>(c.point_step) * c.width > c.row_step ||
      static_cast<uint64_t>(c.row_step) * c.height > c.data.size())
    return "data shorter than width, height and steps say";
  unsigned axes = 0;  // a bit for each of x, y, z met
  for (const auto& f : c.fields) {
    const int axis = f.name == "x" ? 0 : f.name == "y" ? 1 : f.name == "z" ? 2 : -1;
    if (axis < 0) continue;
    if (axes & (1u << axis)) return "field " + f.name + " given twice";
    // 64 bits: an offset near 2^32 would wrap past the check and PCL would read outside the data.
    // A count of 0 is PCL's legacy spelling of 1.
    if (f.datatype != sensor_msgs::PointField::FLOAT32 || f.count > 1 || static_cast<uint64_t>(f.offset) + 4 > c.point_step)
      return "field " + f.name + " is not one float32 within point_step";
    axes |= 1u << axis;
  }
  return axes == 7 ? "" : "no float32 x, y, z fields";
}

CloudBridge::CloudBridge(ros::NodeHandle& nh, tf2_ros::Buffer& tf, TrackingSession& session, const std::string& frame_id,
                         const Eigen::AlignedBox3d& box)
    : nh_(nh),
      tf_(tf),
      session_(session),
      frame_id_(frame_id),
      box_(box),
      voxel_size_(session.registration().options().voxel_size),
      max_points_(session.registration().options().max_points),
      // Its callbacks go to the spinner's queue: a cloud's preparation never runs on tf's thread.
      filter_(tf, frame_id, 1, nh.getCallbackQueue()) {
  const std::string too_fine = voxel_grid_error(voxel_size_, box);
  if (!too_fine.empty()) throw std::invalid_argument("registration.voxel_size with ~cloud_margin: " + too_fine);
  filter_.registerCallback(&CloudBridge::on_transformable, this);
  filter_.registerFailureCallback(boost::bind(&CloudBridge::on_failure, this, boost::placeholders::_1, boost::placeholders::_2));
  sub_ = nh_.subscribe("points", 1, &CloudBridge::on_cloud, this);
}

CloudBridge::Counts CloudBridge::counts() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return counts_;
}

void CloudBridge::on_cloud(const sensor_msgs::PointCloud2::ConstPtr& msg) {
  const std::string layout = cloud_layout_error(*msg);
  if (!layout.empty()) return session_.refuse("points: " + layout);
  // A cloud in the model frame (or in none) needs no transform.
  if (msg->header.frame_id.empty() || msg->header.frame_id == frame_id_) return prepare(*msg, Eigen::Isometry3d::Identity(), false);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    waiting_ = msg;
  }
  filter_.add(msg);
  timeout_ = nh_.createSteadyTimer(
      ros::WallDuration(kTfTimeout), [this, msg](const ros::SteadyTimerEvent&) { on_timeout(msg); }, true);
}

void CloudBridge::on_transformable(const sensor_msgs::PointCloud2::ConstPtr& msg) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_ != msg) return;  // refused meanwhile: out of time
    waiting_.reset();
  }
  Eigen::Isometry3d to_model;
  try {
    to_model = to_isometry(tf_.lookupTransform(frame_id_, msg->header.frame_id, msg->header.stamp).transform);
  } catch (const tf2::TransformException& e) {
    return session_.refuse("points in frame '" + msg->header.frame_id + "': " + e.what());
  }
  if (!to_model.matrix().allFinite())
    return session_.refuse("points: non-finite transform from frame '" + msg->header.frame_id + "'");
  prepare(*msg, to_model, true);
}

void CloudBridge::on_failure(const sensor_msgs::PointCloud2::ConstPtr& msg,
                             tf2_ros::filter_failure_reasons::FilterFailureReason why) {
  // Unknown: a newer cloud took its place in the filter's queue of one.
  if (why == tf2_ros::filter_failure_reasons::Unknown) return;
  refuse_waiting(msg);
}

void CloudBridge::on_timeout(const sensor_msgs::PointCloud2::ConstPtr& msg) {
  if (refuse_waiting(msg)) filter_.clear();
}

bool CloudBridge::refuse_waiting(const sensor_msgs::PointCloud2::ConstPtr& msg) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_ != msg) return false;
    waiting_.reset();
  }
  std::string why = "no transform within " + std::to_string(kTfTimeout) + " s";
  try {
    tf_.lookupTransform(frame_id_, msg->header.frame_id, msg->header.stamp);
  } catch (const tf2::TransformException& e) {
    why = e.what();
  }
  session_.refuse("points in frame '" + msg->header.frame_id + "': " + why);
  return true;
}

void CloudBridge::prepare(const sensor_msgs::PointCloud2& msg, const Eigen::Isometry3d& to_model, bool from_sensor) {
  const ros::WallTime t0 = ros::WallTime::now();
  // Conversion and preparation behind one barrier: a malformed message, memory a huge cloud
  // does not find (the voxel grid fits the crop box: checked at start).
  pcl::PointCloud<pcl::PointXYZ> converted;
  Cloud cloud;
  int finite_points = 0;
  try {
    pcl::fromROSMsg(msg, converted);
    finite_points = prepare_cloud(converted, to_model, box_, voxel_size_, max_points_, cloud.points);
  } catch (const std::exception& e) {
    return session_.refuse(std::string("points: ") + e.what());
  }
  // A cloud in a sensor's frame is seen from that frame's origin; one already in the model
  // frame says nothing about where the sensor is.
  if (from_sensor) cloud.viewpoint = to_model.translation();
  cloud.stamp = to_stamp(msg.header.stamp);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    counts_.last_filter_s = (ros::WallTime::now() - t0).toSec();
    counts_.last_points = converted.size();
  }
  if (finite_points == 0) return session_.refuse("points: no finite point");
  if (cloud.points.empty()) return session_.refuse("points: no point near the model");
  session_.submit(std::move(cloud));
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_.received;
}

}  // namespace liver_sim
