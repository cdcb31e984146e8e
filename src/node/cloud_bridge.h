// Point clouds into the session: each cloud's layout is checked, it waits in a
// tf2_ros::MessageFilter (never blocking a callback) until tf can move it into the model frame at
// its stamp, then it is converted, cropped to where the model can be and downsampled
// (prepare_cloud) on a callback thread, off the simulation thread (a 1M-point cloud becomes a
// few thousand points); the session registers the latest one. A cloud whose transform has not
// come within kTfTimeout is refused; one a newer cloud replaced while it waited is dropped, as
// the subscriber's queue of one drops it.
#pragma once

#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/message_filter.h>

#include <Eigen/Geometry>
#include <cstdint>
#include <mutex>
#include <string>

#include "liver_sim/session/tracking_session.h"

namespace liver_sim {

// Why a cloud cannot be converted, or "" (PCL's conversion indexes an empty cloud and trusts the
// layout fields, so they are checked first).
std::string cloud_layout_error(const sensor_msgs::PointCloud2& c);

class CloudBridge {
 public:
  static constexpr double kTfTimeout = 0.1;  // s
  // `box`: model frame, where cloud points can matter. Throws std::invalid_argument when the
  // registration's voxel grid is too fine for it.
  CloudBridge(ros::NodeHandle& nh, tf2_ros::Buffer& tf, TrackingSession& session, const std::string& frame_id,
              const Eigen::AlignedBox3d& box);

  struct Counts {
    uint64_t received = 0;    // clouds handed to the session
    size_t last_points = 0;   // of the last cloud converted
    double last_filter_s = 0; // its conversion and preparation (s)
  };
  Counts counts() const;

 private:
  using Filter = tf2_ros::MessageFilter<sensor_msgs::PointCloud2>;
  void on_cloud(const sensor_msgs::PointCloud2::ConstPtr& msg);
  void on_transformable(const sensor_msgs::PointCloud2::ConstPtr& msg);
  void on_failure(const sensor_msgs::PointCloud2::ConstPtr& msg, tf2_ros::filter_failure_reasons::FilterFailureReason why);
  void on_timeout(const sensor_msgs::PointCloud2::ConstPtr& msg);
  // Refuses a waiting cloud with tf's own reason; false when it no longer waits.
  bool refuse_waiting(const sensor_msgs::PointCloud2::ConstPtr& msg);
  void prepare(const sensor_msgs::PointCloud2& msg, const Eigen::Isometry3d& to_model, bool from_sensor);

  ros::NodeHandle nh_;
  tf2_ros::Buffer& tf_;
  TrackingSession& session_;
  std::string frame_id_;
  Eigen::AlignedBox3d box_;
  double voxel_size_;  // m: registration.voxel_size
  int max_points_;     // registration.max_points
  Filter filter_;
  ros::Subscriber sub_;
  ros::SteadyTimer timeout_;
  mutable std::mutex mutex_;  // guards waiting_ and counts_
  sensor_msgs::PointCloud2::ConstPtr waiting_;  // the cloud in the filter
  Counts counts_;
};

}  // namespace liver_sim
