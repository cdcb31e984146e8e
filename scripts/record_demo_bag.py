#!/usr/bin/python3
"""Records a scripted OR session into a bag, without a ROS master, for the node's default scene
(the liver phantom hanging under gravity): a probe approaches the anterior-superior surface of
the right lobe above the tumour, presses 5 mm into it, slides 10 mm and withdraws, while a
camera sees that surface as a noisy point cloud. Frames: everything in `liver` (the model
frame). SI units.

usage: scripts/record_demo_bag.py OUT.bag [--duration S]
play:  roslaunch liver_sim playback.launch bag:=$(pwd)/OUT.bag
"""
import argparse

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import PoseStamped
from sensor_msgs import point_cloud2
from std_msgs.msg import Header

RADIUS = 0.008    # m, probe tip radius (launch/liver_sim.launch's instrument_radius)
SURFACE_Z = 0.039  # m, height of the sagged surface under the probe (static equilibrium)
RIGHT_LOBE = ((0.030, 0.000, 0.000), (0.085, 0.075, 0.060))  # centre, semi-axes (m), as in make_phantom.py


def probe_position(t, duration):
    """Approach (0-20%), press (20-40%), slide (40-70%), withdraw (70-100%)."""
    s = t / duration
    x0, y0 = 0.050, -0.020
    above = SURFACE_Z + RADIUS + 0.004
    pressed = SURFACE_Z + RADIUS - 0.005
    if s < 0.2:
        return x0, y0, above
    if s < 0.4:
        return x0, y0, above + (pressed - above) * (s - 0.2) / 0.2
    if s < 0.7:
        return x0 + 0.010 * (s - 0.4) / 0.3, y0, pressed
    return x0 + 0.010, y0, pressed + (above - pressed) * (s - 0.7) / 0.3


def top_face_cloud(rng, n=40, noise=0.0005):
    """The upper surface of the right lobe as planned (rest shape), 1 mm grid, 0.5 mm noise."""
    (cx, cy, cz), (ax, ay, az) = RIGHT_LOBE
    xx, yy = np.meshgrid(np.linspace(0.0, 0.1, n), np.linspace(-0.05, 0.03, n))
    zz = cz + az * np.sqrt(np.clip(1 - ((xx - cx) / ax) ** 2 - ((yy - cy) / ay) ** 2, 0, None))
    pts = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    pts += rng.normal(0.0, noise, pts.shape)
    return pts.astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--duration", type=float, default=10.0, help="session length (s)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    start = rospy.Time.from_sec(1.0e9)
    with rosbag.Bag(args.out, "w") as bag:
        for k in range(int(args.duration * 30) + 1):  # poses at 30 Hz
            t = k / 30.0
            stamp = start + rospy.Duration.from_sec(t)
            msg = PoseStamped(header=Header(stamp=stamp, frame_id="liver"))
            msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = probe_position(t, args.duration)
            msg.pose.orientation.w = 1.0
            bag.write("/instrument_pose", msg, stamp)
            if k % 6 == 0:  # clouds at 5 Hz
                cloud = point_cloud2.create_cloud_xyz32(Header(stamp=stamp, frame_id="liver"), top_face_cloud(rng))
                bag.write("/points", cloud, stamp)
    print(f"wrote {args.out}: {args.duration:g} s, poses at 30 Hz, clouds at 5 Hz")


if __name__ == "__main__":
    main()
