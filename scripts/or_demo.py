#!/usr/bin/python3
"""A headless demo of an OR session against a running liver_sim node (launch/or_demo.launch, or
scripts/run.sh, which starts both; their scene is SOFA's liver2, config/scenes/sofa_liver_or.yaml;
any scene whose first probe is the tumour will do):

  0 s   a depth camera in front of and above the liver sends clouds at 5 Hz until the end: the
        liver in the abdomen lies up to 3 mm higher over the tumour's lobe than the pre-operative
        model (a smooth lift), and the node registers the clouds;
  6 s   a grasper closes on the right lobe's lateral edge and lifts it 15 mm (a retraction);
  13 s  a probe presses 5 mm into the right lobe above the tumour, slides 10 mm, withdraws;
  22 s  the grasper lowers the edge, opens and withdraws.

One status line per second (simulation frames per second, the latency from an input's stamp, a
pose's or a cloud's, to the first mesh marker that shows it, contacts per instrument,
registration RMS, the tumour's displacement from the pre-operative equilibrium) and a summary at
the end, with where the probe pressed: it exits 1 unless the pressing probe's tip was within 5 mm
across from the tumour and above it. Instrument poses are the tips in the model frame (`liver`), +z back along
the instrument; the camera sees the surface of the intra-operative liver except within 25 mm of
an instrument's tip (the instruments hide it and deform it in ways the camera's truth does not
model). SI units; lengths printed in mm.

usage: scripts/or_demo.py [--speed F]   (with ROS_MASTER_URI of the node's master)
"""
import argparse
import math
import sys
import threading
import time

import numpy as np
import rosgraph
import rospy
import yaml
from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from liver_sim.msg import InstrumentCommand, SimulationStatus

NODE = "/liver_sim"
FRAME = "liver"
CLOUD_PERIOD = 0.2     # s
POSE_PERIOD = 1 / 30.  # s
LIFT = 0.015           # m, grasper lift
PRESS = 0.005          # m, probe press below the surface
SLIDE = 0.010          # m, probe slide along +x
PROBE_RADIUS = 0.0025  # m
PRESS_ACROSS_MAX = 0.005  # m: the pressing probe's tip at most this far across from the tumour
JAW_RADIUS = 0.003     # m
OCCLUDED = 0.025       # m, no cloud points this near an instrument's tip


def quaternion_z_to(d):
    """Unit quaternion (x, y, z, w) that turns +z onto the unit vector d."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return (0.0, 0.0, 0.0, 1.0) if d[2] > 0 else (1.0, 0.0, 0.0, 0.0)
    angle = math.atan2(s, float(z @ d))
    axis = axis / s * math.sin(angle / 2)
    return (axis[0], axis[1], axis[2], math.cos(angle / 2))


def lerp(a, b, s):
    s = min(max(s, 0.0), 1.0)
    return a + (b - a) * (0.5 - 0.5 * math.cos(math.pi * s))  # smooth start and stop


class Camera:
    """A depth camera 25 cm in front of and above the liver's centre, 160 x 120 pixels, 60 deg:
    one point per pixel on the nearest surface (a z-buffer of dense surface samples), depth
    noise 1 mm at 25 cm growing with the square of the depth."""

    def __init__(self, triangles, rng, width=160, height=120, fov=1.05):
        centre = triangles.reshape(-1, 3).mean(axis=0)
        self.eye = centre + 0.25 * np.array([0.0, -1.0, 0.6]) / np.linalg.norm([0.0, -1.0, 0.6])
        axis = (centre - self.eye) / np.linalg.norm(centre - self.eye)
        right = np.cross(axis, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, axis)
        n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        area = 0.5 * np.linalg.norm(n, axis=1)
        front = np.einsum("ij,ij->i", n, self.eye - triangles.mean(axis=1)) > 0
        tri = np.repeat(np.nonzero(front)[0], rng.poisson(area[front] / 0.7e-3**2))
        r1, r2 = np.sqrt(rng.random(len(tri))), rng.random(len(tri))
        t = triangles[tri]
        p = (1 - r1)[:, None] * t[:, 0] + (r1 * (1 - r2))[:, None] * t[:, 1] + (r1 * r2)[:, None] * t[:, 2]
        d = p - self.eye
        depth = d @ axis
        f = 0.5 * width / math.tan(0.5 * fov)
        px = np.floor(f * (d @ right) / depth + 0.5 * width).astype(int)
        py = np.floor(f * (d @ up) / depth + 0.5 * height).astype(int)
        ok = (px >= 0) & (px < width) & (py >= 0) & (py < height)
        pixel = py[ok] * width + px[ok]
        order = np.lexsort((depth[ok], pixel))
        first = order[np.r_[True, pixel[order][1:] != pixel[order][:-1]]]
        self.points = p[ok][first]
        self.depth = depth[ok][first]

    def cloud(self, rng, tips):
        keep = np.ones(len(self.points), bool)
        for tip in tips:
            keep &= np.linalg.norm(self.points - tip, axis=1) > OCCLUDED
        p, depth = self.points[keep], self.depth[keep]
        ray = (p - self.eye) / np.linalg.norm(p - self.eye, axis=1)[:, None]
        sigma = 1e-3 * (depth / 0.25) ** 2
        return (p + ray * (sigma * rng.standard_normal(len(p)))[:, None]).astype(np.float32)


class Instrument:
    """One named instrument of the node: declared on instrument_command, posed on its topic."""

    def __init__(self, name, type_, radius, length=0.0):
        self.name = name
        self.commands = rospy.Publisher("/instrument_command", InstrumentCommand, queue_size=10)
        self.poses = rospy.Publisher(f"/instruments/{name}/pose", PoseStamped, queue_size=1)
        self.declaration = InstrumentCommand(name=name, type=type_, radius=radius, length=length)
        self.tip = None
        self.force = np.zeros(3)
        rospy.Subscriber(f"{NODE}/instruments/{name}/wrench", WrenchStamped, self.on_wrench, queue_size=5)

    def on_wrench(self, w):
        self.force = np.array([w.wrench.force.x, w.wrench.force.y, w.wrench.force.z])

    def declare(self):
        self.commands.publish(self.declaration)

    def grasp(self, closed):
        self.commands.publish(InstrumentCommand(name=self.name, grasp=closed))

    def remove(self):
        self.commands.publish(InstrumentCommand(name=self.name, remove=True))
        self.tip = None

    def pose(self, tip, direction, stamp):
        self.tip = np.asarray(tip, float)
        msg = PoseStamped(header=Header(stamp=stamp, frame_id=FRAME))
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = self.tip
        q = quaternion_z_to(np.asarray(direction, float) / np.linalg.norm(direction))
        msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w = q
        self.poses.publish(msg)


class Session:
    """What the node reports, gathered from its topics."""

    def __init__(self):
        self.lock = threading.Lock()
        self.mesh = None
        self.status = None
        self.targets = None
        self.sent = set()        # stamps (ns) of the poses and clouds sent
        self.latencies = []      # s, an input's stamp -> the first mesh marker that reflects it
        self.seen = set()
        self.mesh_subscriber = rospy.Subscriber(f"{NODE}/mesh", Marker, self.on_mesh, queue_size=5)
        rospy.Subscriber(f"{NODE}/status", SimulationStatus, self.on_status, queue_size=50)
        rospy.Subscriber(f"{NODE}/target_poses", PoseArray, self.on_targets, queue_size=5)

    def on_mesh(self, m):
        arrived = time.time()
        stamp = m.header.stamp.to_nsec()
        with self.lock:
            self.mesh = m
            if stamp in self.sent and stamp not in self.seen:
                self.seen.add(stamp)
                self.latencies.append(arrived - stamp * 1e-9)

    def on_status(self, s):
        with self.lock:
            self.status = s

    def on_targets(self, t):
        with self.lock:
            self.targets = np.array([[p.position.x, p.position.y, p.position.z] for p in t.poses])

    def triangles(self):
        with self.lock:
            return np.array([[p.x, p.y, p.z] for p in self.mesh.points]).reshape(-1, 3, 3)

    def wait_for_equilibrium(self, timeout, who):
        """Waits until the node has published its mesh, targets and an idle status (its
        equilibrium before any input); exits naming `who` after `timeout` seconds."""
        deadline = time.time() + timeout
        while time.time() < deadline and not rospy.is_shutdown():
            with self.lock:
                if self.mesh is not None and self.targets is not None and self.status is not None \
                        and self.status.state == "idle":
                    return
            time.sleep(0.1)
        sys.exit(f"{who}: the node did not reach its equilibrium within {timeout:g} s")


def surface_height(triangles, xy):
    """Height (m) of the upper surface above the point xy: the highest crossing of the vertical
    line through xy with a triangle (barycentric coordinates of xy in the triangles' xy shadow)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2, r = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2], np.asarray(xy) - a[:, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-15
    det = np.where(ok, det, 1.0)
    u = (r[:, 0] * e2[:, 1] - r[:, 1] * e2[:, 0]) / det
    v = (e1[:, 0] * r[:, 1] - e1[:, 1] * r[:, 0]) / det
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
    if not hit.any():
        sys.exit(f"or_demo: no surface above ({xy[0] * 1e3:.0f}, {xy[1] * 1e3:.0f}) mm")
    return float(((1 - u - v) * a[:, 2] + u * b[:, 2] + v * c[:, 2])[hit].max())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--speed", type=float, default=1.0, help="session speed factor (> 0; default 1)")
    args = ap.parse_args(rospy.myargv()[1:])
    if not args.speed > 0:
        ap.error("--speed must be > 0")
    deadline = time.time() + 30
    while not rosgraph.is_master_online():  # run.sh starts the master beside this script
        if time.time() > deadline:
            sys.exit("or_demo: no ROS master at " + rosgraph.get_master_uri())
        time.sleep(0.2)
    rospy.init_node("or_demo", disable_signals=True)
    session = Session()
    rng = np.random.default_rng(0)

    # The pre-operative equilibrium: the node at rest under gravity, before any input.
    print("or_demo: waiting for the node's pre-operative equilibrium ...", flush=True)
    session.wait_for_equilibrium(90, "or_demo")
    scene = yaml.safe_load(open(rospy.get_param(f"{NODE}/scene")))
    tumour_name = scene["probes"][0]["name"]
    with session.lock:
        tumour_preop = session.targets[0].copy()
    preop = session.triangles()
    # The right lobe holds the tumour: its side of the model frame's x (the patient's right).
    side = 1.0 if tumour_preop[0] > 0 else -1.0
    # The intra-operative liver the camera sees: up to 3 mm higher over the tumour.
    lift = 3e-3 * np.exp(-np.sum((preop[..., :2] - tumour_preop[:2]) ** 2, axis=-1) / (2 * 0.04**2))
    truth = preop.copy()
    truth[..., 2] += lift
    camera = Camera(truth, rng)
    cloud_pub = rospy.Publisher("/points", PointCloud2, queue_size=1)

    grasper = Instrument("grasper", "grasper", JAW_RADIUS)
    probe = Instrument("probe", "shaft", PROBE_RADIUS, 0.1)  # a rod with a rounded tip: no tissue closes over it
    time.sleep(1.0)  # subscriptions connect
    grasper_dir = np.array([side, 0.0, 1.0]) / math.sqrt(2)  # from the side, above
    probe_dir = np.array([0.0, 0.0, 1.0])
    probe_xy = tumour_preop[:2].copy()  # the probe presses straight above the tumour

    # Timeline (s of session time): phase boundaries.
    T_GRASP, T_CLOSE, T_LIFTED = 6.0, 8.5, 11.5
    T_PROBE, T_PRESSED, T_SLID, T_OUT = 13.0, 15.0, 18.0, 20.0
    T_LOWER, T_LOWERED, T_OPEN, T_AWAY, T_END = 22.0, 24.0, 24.5, 26.0, 29.0
    phases = [(0.0, "the camera's clouds register"), (T_GRASP, "grasper approaches the right lobe's edge"),
              (T_CLOSE, "grasper closes and lifts the edge 15 mm"), (T_LIFTED, "grasper holds the edge up"),
              (T_PROBE, "probe presses 5 mm above the tumour"), (T_PRESSED, "probe slides 10 mm"),
              (T_SLID, "probe withdraws"), (T_OUT + 1.0, "grasper holds the edge up"),
              (T_LOWER, "grasper lowers the edge"), (T_LOWERED, "grasper opens and withdraws"), (T_AWAY, "at rest")]
    edge = None          # grasp point: the right lobe's lateral edge when the grasper comes
    probe_top = None     # probe start: 4 mm above the surface over the tumour
    print(f"or_demo: {len(camera.points)} camera pixels on the liver; tumour '{tumour_name}' at "
          f"({tumour_preop[0]*1e3:.0f}, {tumour_preop[1]*1e3:.0f}, {tumour_preop[2]*1e3:.0f}) mm; "
          f"session {T_END / args.speed:.0f} s", flush=True)

    start = time.time()
    next_pose = next_cloud = next_line = start
    with session.lock:
        step0 = session.status.step
        clouds0 = session.status.clouds_registered
    last_step, last_line_t = step0, start
    shown = 0  # latencies printed
    rows = []
    closed = False
    grasper_max = probe_max = 0.0
    press = []  # while the probe presses: (its contacts, tip to tumour across (m), tip above the tumour (m))
    sent_clouds = 0
    while not rospy.is_shutdown():
        now = time.time()
        t = (now - start) * args.speed
        if t > T_END:
            break
        stamp = rospy.Time.from_sec(now)
        if now >= next_pose:
            next_pose += POSE_PERIOD
            if T_GRASP <= t < T_AWAY:
                if edge is None:
                    v = session.triangles().reshape(-1, 3)
                    edge = v[np.argmax(side * v[:, 0])]
                    grasper.declare()
                away = edge + 0.03 * grasper_dir
                if t < T_CLOSE - 0.5:
                    tip = lerp(away, edge, (t - T_GRASP) / (T_CLOSE - 0.5 - T_GRASP))
                elif t < T_CLOSE:
                    tip = edge
                elif t < T_LOWER:
                    tip = edge + [0, 0, lerp(0.0, LIFT, (t - T_CLOSE) / (T_LIFTED - T_CLOSE))]
                elif t < T_OPEN:
                    tip = edge + [0, 0, lerp(LIFT, 0.0, (t - T_LOWER) / (T_LOWERED - T_LOWER))]
                else:
                    tip = lerp(edge, away, (t - T_OPEN) / (T_AWAY - T_OPEN))
                want_closed = T_CLOSE <= t < T_OPEN
                if want_closed != closed:
                    grasper.grasp(want_closed)
                    closed = want_closed
                grasper.pose(tip, grasper_dir, stamp)
            elif t >= T_AWAY and grasper.tip is not None:
                grasper.remove()
            if T_PROBE <= t < T_OUT + 1.0:
                if probe_top is None:
                    probe.declare()
                    z = surface_height(session.triangles(), probe_xy)
                    probe_top = np.array([*probe_xy, z + PROBE_RADIUS + 0.004])
                    probe_low = np.array([*probe_xy, z + PROBE_RADIUS - PRESS])
                if t < T_PRESSED:
                    tip = lerp(probe_top, probe_low, (t - T_PROBE) / (T_PRESSED - T_PROBE))
                elif t < T_SLID:
                    tip = lerp(probe_low, probe_low + [SLIDE, 0, 0], (t - T_PRESSED) / (T_SLID - T_PRESSED))
                else:
                    tip = lerp(probe_low + [SLIDE, 0, 0], probe_top + [SLIDE, 0, 0], (t - T_SLID) / (T_OUT - T_SLID))
                probe.pose(tip, probe_dir, stamp)
            elif t >= T_OUT + 1.0 and probe.tip is not None:
                probe.remove()
            with session.lock:
                session.sent.add(stamp.to_nsec())
        if now >= next_cloud:
            with session.lock:
                session.sent.add(stamp.to_nsec())
            next_cloud += CLOUD_PERIOD / args.speed
            tips = [i.tip for i in (grasper, probe) if i.tip is not None]
            cloud_pub.publish(point_cloud2.create_cloud_xyz32(Header(stamp=stamp, frame_id=FRAME),
                                                              camera.cloud(rng, tips)))
            sent_clouds += 1
        grasper_max = max(grasper_max, np.linalg.norm(grasper.force))
        probe_max = max(probe_max, np.linalg.norm(probe.force))
        if T_PRESSED - 0.5 <= t < T_PRESSED and probe.tip is not None:  # pressed in, before the slide
            with session.lock:
                s, targets = session.status, session.targets
            contacts = dict(zip(s.instrument_names, s.instrument_contacts)).get("probe", 0)
            if contacts:
                press.append((contacts, np.linalg.norm(probe.tip[:2] - targets[0][:2]), probe.tip[2] - targets[0][2]))
        if now >= next_line + 1.0:
            next_line += 1.0
            with session.lock:
                s, targets = session.status, session.targets
                latencies = session.latencies[shown:]
                shown = len(session.latencies)
            frames = (s.step - last_step) / (now - last_line_t)
            last_step, last_line_t = s.step, now
            tumour = np.linalg.norm(targets[0] - tumour_preop)
            per = ", ".join(f"{n} {c}" for n, c in zip(s.instrument_names, s.instrument_contacts) if c)
            phase = [text for begin, text in phases if begin <= t][-1]
            latency = f"{np.median(latencies) * 1e3:4.0f} ms" if latencies else "   - ms"
            rows.append((frames, s.active_contacts, s.registration_rms, tumour))
            print(f"{t:5.1f} s  {frames:5.1f} frames/s  latency {latency}  contacts {s.active_contacts:3d}"
                  f"{' (' + per + ')' if per else ''}  registration RMS {s.registration_rms * 1e3:.2f} mm"
                  f" ({s.clouds_registered - clouds0} clouds)  tumour {tumour * 1e3:.2f} mm  | {phase}", flush=True)
        time.sleep(max(0.0, min(next_pose, next_cloud, next_line + 1.0) - time.time()))

    time.sleep(1.0)
    with session.lock:
        s, targets = session.status, session.targets
        latencies = np.array(session.latencies)
    elapsed = time.time() - start
    frames = np.array([r[0] for r in rows])
    print(f"summary: {elapsed:.0f} s; {s.step - step0} simulation frames ({frames.mean():.1f}/s mean, "
          f"{frames.min():.1f}/s lowest second); input -> mesh latency median "
          + (f"{np.median(latencies) * 1e3:.0f} ms, p95 {np.percentile(latencies, 95) * 1e3:.0f} ms "
             f"over {len(latencies)} inputs shown" if len(latencies) else "- (no mesh carried an input's stamp)"))
    print(f"summary: clouds registered {s.clouds_registered - clouds0} of {sent_clouds} sent, registration RMS "
          f"{s.registration_rms * 1e3:.2f} mm at the end; contacts up to {max(r[1] for r in rows)}; largest "
          f"force on the grasper {grasper_max:.3f} N, on the probe {probe_max:.3f} N; refused inputs "
          f"{s.rejected_inputs}; state {s.state}")
    print(f"summary: tumour '{tumour_name}' moved {max(r[3] for r in rows) * 1e3:.2f} mm at most, "
          f"{np.linalg.norm(targets[0] - tumour_preop) * 1e3:.2f} mm at the end (registered to the intra-operative "
          f"liver; pre-operative equilibrium as reference)")
    # The probe must press on the tumour's side of the liver, straight above it.
    if not press:
        rospy.signal_shutdown("done")
        sys.exit("or_demo: FAILED: the probe never touched the liver while it pressed")
    contacts, across, above = press[-1]
    print(f"summary: the probe pressed with {contacts} contacts, its tip {across * 1e3:.1f} mm across from the tumour "
          f"and {above * 1e3:.1f} mm above it")
    rospy.signal_shutdown("done")
    if across > PRESS_ACROSS_MAX or above <= 0:
        sys.exit(f"or_demo: FAILED: the probe pressed {across * 1e3:.1f} mm across from the tumour "
                 f"(at most {PRESS_ACROSS_MAX * 1e3:.0f} mm) and {above * 1e3:.1f} mm above it (must be above)")


if __name__ == "__main__":
    main()
