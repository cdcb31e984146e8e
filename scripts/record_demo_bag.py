#!/usr/bin/python3
"""Records a scripted OR session into a bag, without a ROS master, for the node's default scene
(the liver phantom hanging under gravity): a probe approaches the anterior-superior surface of
the right lobe above the tumour, presses 5 mm into it, slides 10 mm and withdraws, while a
camera sees the upper surface of the right lobe as a noisy point cloud, which the node
registers. The surface is the phantom's equilibrium under gravity (solved by the built
`simulate` tool); the probe hides a 2 cm disc of it from the camera. Frames: everything in
`liver` (the model frame). SI units.

usage: rosrun liver_sim record_demo_bag.py OUT.bag [--duration S]   (after scripts/run.sh built it)
play:  roslaunch liver_sim playback.launch bag:=$(pwd)/OUT.bag
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import PoseStamped
from sensor_msgs import point_cloud2
from std_msgs.msg import Header

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))  # package_paths, also through catkin's relay
from package_paths import package_file, tool  # noqa: E402
RADIUS = 0.0025   # m, probe tip radius (launch/liver_sim.launch's instrument_radius)
SURFACE_Z = 0.039  # m, height of the sagged surface under the probe (static equilibrium)


def probe_position(t, duration):
    """Approach (0-20%), press (20-40%), slide (40-70%), withdraw (70-100%)."""
    s = t / duration
    x0, y0 = -0.050, -0.020
    above = SURFACE_Z + RADIUS + 0.004
    pressed = SURFACE_Z + RADIUS - 0.005
    if s < 0.2:
        return x0, y0, above
    if s < 0.4:
        return x0, y0, above + (pressed - above) * (s - 0.2) / 0.2
    if s < 0.7:
        return x0 - 0.010 * (s - 0.4) / 0.3, y0, pressed
    return x0 - 0.010, y0, pressed + (above - pressed) * (s - 0.7) / 0.3


def sagged_top_surface(simulate):
    """Triangles (n, 3, 3) of the phantom's upper right-lobe surface at its equilibrium."""
    with tempfile.TemporaryDirectory() as tmp:
        vtu = os.path.join(tmp, "equilibrium.vtu")
        subprocess.run([simulate, "--scene", package_file("config", "scenes", "liver_phantom.yaml"),
                        "--vtu", vtu, "--quiet"],
                       check=True, stdout=subprocess.DEVNULL)
        text = open(vtu).read()
    arrays = re.findall(r"<DataArray[^>]*>\n(.*?)</DataArray>", text, re.S)
    displacement, points, cells = (np.array(a.split(), dtype=float) for a in arrays[:3])
    x = (points + displacement).reshape(-1, 3)
    tets = cells.astype(int).reshape(-1, 4)
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    _, index, count = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    boundary = x[faces[index[count == 1]]]
    n = np.cross(boundary[:, 1] - boundary[:, 0], boundary[:, 2] - boundary[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    c = boundary.mean(axis=1)
    # Outward normals (positively oriented tetrahedra) facing up, over the right lobe.
    keep = (n[:, 2] > 0.3) & (c[:, 0] < 0.0) & (c[:, 0] > -0.1) & (c[:, 1] > -0.05) & (c[:, 1] < 0.03)
    return boundary[keep]


def camera_cloud(triangles, rng, probe_xy, spacing=0.002, noise=0.0005):
    """Points 2 mm apart on the triangles, 0.5 mm noise, none within 2 cm of the probe's axis."""
    area = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    tri = np.repeat(np.arange(len(triangles)), rng.poisson(area / spacing**2))
    r1, r2 = np.sqrt(rng.random(len(tri))), rng.random(len(tri))
    t = triangles[tri]
    pts = (1 - r1)[:, None] * t[:, 0] + (r1 * (1 - r2))[:, None] * t[:, 1] + (r1 * r2)[:, None] * t[:, 2]
    pts = pts[np.linalg.norm(pts[:, :2] - probe_xy, axis=1) > 0.02]
    return (pts + rng.normal(0.0, noise, pts.shape)).astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--duration", type=float, default=10.0, help="session length (s)")
    ap.add_argument("--simulate", default=tool("simulate"), help="the simulate tool (default: the workspace's)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    surface = sagged_top_surface(args.simulate)
    start = rospy.Time.from_sec(1.0e9)
    with rosbag.Bag(args.out, "w") as bag:
        for k in range(int(args.duration * 30) + 1):  # poses at 30 Hz
            t = k / 30.0
            stamp = start + rospy.Duration.from_sec(t)
            msg = PoseStamped(header=Header(stamp=stamp, frame_id="liver"))
            msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = probe_position(t, args.duration)
            msg.pose.orientation.w = 1.0
            bag.write("/instruments/tool/pose", msg, stamp)
            if k % 6 == 0:  # clouds at 5 Hz
                probe_xy = np.array(probe_position(t, args.duration)[:2])
                cloud = point_cloud2.create_cloud_xyz32(Header(stamp=stamp, frame_id="liver"),
                                                        camera_cloud(surface, rng, probe_xy))
                bag.write("/points", cloud, stamp)
    print(f"wrote {args.out}: {args.duration:g} s, poses at 30 Hz, clouds at 5 Hz")


if __name__ == "__main__":
    main()
