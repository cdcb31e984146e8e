#!/usr/bin/python3
"""Records a scripted OR session into a bag, without a ROS master, on the OR demo's liver (SOFA's
liver2 hanging from its ligaments under gravity, config/scenes/sofa_liver_or.yaml, as
launch/or_demo.launch and launch/playback.launch load it): a probe approaches the right lobe's
upper surface above the tumour (the scene's first probe), presses 5 mm into it, slides 10 mm
toward the lobe's lateral edge along the surface and withdraws, while a camera sees the upper
surface of the right lobe as a noisy point cloud, which the node registers. The surface is the
scene's equilibrium under gravity (solved by the built `simulate` tool); the probe hides a 2 cm
disc of it from the camera. Frames: everything in `liver` (the model frame). SI units.

usage: rosrun liver_sim record_demo_bag.py OUT.bag [--duration S] [--scene FILE]
play:  roslaunch liver_sim playback.launch bag:=$(pwd)/OUT.bag   (the same scene: add scene:=FILE
       when the bag was recorded on another one)
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
import yaml
from geometry_msgs.msg import PoseStamped
from sensor_msgs import point_cloud2
from std_msgs.msg import Header

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))  # package_paths, also through catkin's relay
from package_paths import package_file, tool  # noqa: E402
RADIUS = 0.0025  # m, probe tip radius (launch/liver_sim.launch's instrument_radius)
PRESS = 0.005    # m, below the surface
SLIDE = 0.010    # m, along -x (toward the right lobe's lateral edge)
ABOVE = 0.004    # m, the tip's gap to the surface before and after the press


def surface_height(triangles, xy):
    """Height of the highest triangle over the point xy (the surface a probe coming down meets)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2, d = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2], np.asarray(xy) - a[:, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
        v = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    inside = (u >= 0) & (v >= 0) & (u + v <= 1)
    if not inside.any():
        sys.exit(f"record_demo_bag: no surface over ({xy[0]:.3f}, {xy[1]:.3f}) m")
    return float(np.max((a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (c[:, 2] - a[:, 2]))[inside]))


def probe_position(t, duration, surface, start_xy):
    """The tip: approach (0-20%), press (20-40%), slide along the surface (40-70%), withdraw (70-100%)."""
    s = t / duration
    slid = min(max((s - 0.4) / 0.3, 0.0), 1.0)
    xy = np.asarray(start_xy) - np.array([SLIDE * slid, 0.0])
    top = surface_height(surface, xy) + RADIUS
    if s < 0.2:
        depth = -ABOVE
    elif s < 0.4:
        depth = -ABOVE + (PRESS + ABOVE) * (s - 0.2) / 0.2
    elif s < 0.7:
        depth = PRESS
    else:
        depth = PRESS - (PRESS + ABOVE) * (s - 0.7) / 0.3
    return xy[0], xy[1], top - depth


def equilibrium(simulate, scene):
    """The scene's surface triangles (n, 3, 3) at its equilibrium, outward, and its first probe (the tumour)."""
    with tempfile.TemporaryDirectory() as tmp:
        vtu = os.path.join(tmp, "equilibrium.vtu")
        subprocess.run([simulate, "--scene", scene, "--vtu", vtu, "--quiet"], check=True, stdout=subprocess.DEVNULL)
        text = open(vtu).read()
    arrays = re.findall(r"<DataArray[^>]*>\n(.*?)</DataArray>", text, re.S)
    displacement, points, cells = (np.array(a.split(), dtype=float) for a in arrays[:3])
    x = (points + displacement).reshape(-1, 3)
    tets = cells.astype(int).reshape(-1, 4)
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    _, index, count = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    return x[faces[index[count == 1]]]


def top_of_right_lobe(boundary):
    """The triangles of the right lobe's (-x, the patient's right) upper surface: outward normals
    (positively oriented tetrahedra) facing up."""
    n = np.cross(boundary[:, 1] - boundary[:, 0], boundary[:, 2] - boundary[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    keep = (n[:, 2] > 0.3) & (boundary.mean(axis=1)[:, 0] < 0.0)
    return boundary[keep]


def tumour_xy(scene):
    """The scene's first probe (the OR demo's scenes name the tumour's centre first), across (x, y)."""
    with open(scene) as f:
        probes = yaml.safe_load(f).get("probes") or []
    if not probes:
        sys.exit(f"record_demo_bag: {scene} has no probes (its first probe is where the probe presses)")
    return np.array(probes[0]["point"][:2], dtype=float)


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
    ap.add_argument("--scene", default=package_file("config", "scenes", "sofa_liver_or.yaml"),
                    help="scene file (default: the OR demo's, which playback.launch loads); its first probe is the tumour")
    ap.add_argument("--simulate", default=tool("simulate"), help="the simulate tool (default: the workspace's)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    boundary = equilibrium(args.simulate, args.scene)
    surface = top_of_right_lobe(boundary)
    start_xy = tumour_xy(args.scene)
    start = rospy.Time.from_sec(1.0e9)
    with rosbag.Bag(args.out, "w") as bag:
        for k in range(int(args.duration * 30) + 1):  # poses at 30 Hz
            t = k / 30.0
            stamp = start + rospy.Duration.from_sec(t)
            msg = PoseStamped(header=Header(stamp=stamp, frame_id="liver"))
            tip = probe_position(t, args.duration, boundary, start_xy)
            msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = tip
            msg.pose.orientation.w = 1.0
            bag.write("/instruments/tool/pose", msg, stamp)
            if k % 6 == 0:  # clouds at 5 Hz
                cloud = point_cloud2.create_cloud_xyz32(Header(stamp=stamp, frame_id="liver"),
                                                        camera_cloud(surface, rng, np.array(tip[:2])))
                bag.write("/points", cloud, stamp)
    print(f"wrote {args.out}: {args.duration:g} s, poses at 30 Hz, clouds at 5 Hz, on {args.scene}")


if __name__ == "__main__":
    main()
