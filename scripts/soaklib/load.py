"""The soak's load on a running liver_sim_node: point clouds at 30 Hz, instrument poses at 1 kHz
(the probe pressing and circling on the phantom's right lobe), a service call every second and
an instrument command every two seconds. Every 100th pose is NaN and every 100th (another)
absurd but finite (1e300 m), every 30th cloud empty, every other set_capsule call out of range
(alternately a modulus of -1 and of 1e300 Pa) and every other command a radius of 1e9 m: the node
must refuse and count them and keep going. Every 1000th pose jumps 3 cm across the lobe and back
(the step stages the move)."""
import math
import threading
import time

import numpy as np
import rospy
from geometry_msgs.msg import PoseStamped
from liver_sim.msg import InstrumentCommand
from liver_sim.srv import SetCapsule
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header
from std_srvs.srv import Trigger

SURFACE_Z = 0.039   # m, sagged surface of the phantom's right lobe under the probe
RADIUS = 0.0025     # m, launch file's probe radius


class Load:
    """The publishers and service clients, run on threads of their own until `stop` is set;
    `sent` counts what went out (record.py)."""

    def __init__(self, points):
        self.sent = {"poses": 0, "nan_poses": 0, "absurd_poses": 0, "jumps": 0, "clouds": 0, "empty_clouds": 0,
                     "service_calls": 0, "refused_service_calls": 0, "resets": 0, "commands": 0, "huge_radii": 0}
        rng = np.random.default_rng(0)
        xyz = np.column_stack([rng.uniform(-0.1, 0.0, points), rng.uniform(-0.05, 0.03, points),
                               rng.uniform(0.02, 0.06, points)]).astype(np.float32)
        self.cloud = point_cloud2.create_cloud_xyz32(Header(frame_id="liver"), xyz)
        self.empty = point_cloud2.create_cloud_xyz32(Header(frame_id="liver"), [])
        self.pose_pub = rospy.Publisher("instruments/tool/pose", PoseStamped, queue_size=1)
        self.command_pub = rospy.Publisher("instrument_command", InstrumentCommand, queue_size=10)
        self.cloud_pub = rospy.Publisher("points", PointCloud2, queue_size=1)
        self.threads = []

    def start(self, stop):
        self.threads = [threading.Thread(target=f, args=(stop,), daemon=True)
                        for f in (self.poses, self.clouds, self.services)]
        for t in self.threads:
            t.start()

    def join(self):
        for t in self.threads:
            t.join(5)

    def poses(self, stop):
        rate = rospy.Rate(1000)
        t0 = time.monotonic()
        while not stop.is_set() and not rospy.is_shutdown():
            t = time.monotonic() - t0
            p = PoseStamped(header=Header(stamp=rospy.Time.now(), frame_id="liver"))
            # Circles of 3 mm at 0.5 Hz, pressing 3-5 mm.
            p.pose.position.x = -0.05 + 0.003 * math.cos(math.pi * t)
            p.pose.position.y = -0.02 + 0.003 * math.sin(math.pi * t)
            p.pose.position.z = SURFACE_Z + RADIUS - 0.004 - 0.001 * math.sin(0.3 * t)
            p.pose.orientation.w = 1.0
            self.sent["poses"] += 1
            if self.sent["poses"] % 1000 < 200:  # a jump of 3 cm across the lobe, 0.2 s there
                p.pose.position.y += 0.03
                self.sent["jumps"] += self.sent["poses"] % 1000 == 0
            if self.sent["poses"] % 100 == 0:
                p.pose.position.x = float("nan")
                self.sent["nan_poses"] += 1
            elif self.sent["poses"] % 100 == 50:
                p.pose.position.x = 1e300
                self.sent["absurd_poses"] += 1
            self.pose_pub.publish(p)
            rate.sleep()

    def clouds(self, stop):
        rate = rospy.Rate(30)
        while not stop.is_set() and not rospy.is_shutdown():
            self.sent["clouds"] += 1
            msg = self.cloud
            if self.sent["clouds"] % 30 == 0:
                msg = self.empty
                self.sent["empty_clouds"] += 1
            msg.header.stamp = rospy.Time.now()
            self.cloud_pub.publish(msg)
            rate.sleep()

    def services(self, stop):
        set_capsule = rospy.ServiceProxy("liver_sim/set_capsule", SetCapsule)
        reset = rospy.ServiceProxy("liver_sim/reset", Trigger)
        k = 0
        while not stop.wait(1.0):
            k += 1
            if k % 10 == 0:
                reset()
                self.sent["resets"] += 1
            elif k % 2:
                r = set_capsule(True, 3.0e6 if k % 4 == 1 else 4.0e6, 93e-6, 0.45)  # valid: E alternates
                self.sent["service_calls"] += 1
                if not r.success:
                    raise RuntimeError("valid set_capsule refused: " + r.message)
            else:
                r = set_capsule(True, -1.0 if k % 4 == 0 else 1e300, 93e-6, 0.45)  # out of range: refused
                self.sent["service_calls"] += 1
                self.sent["refused_service_calls"] += not r.success
            if k % 2 == 0:  # a probe radius, alternately valid and absurd (refused)
                huge = k % 4 == 0
                self.command_pub.publish(InstrumentCommand(name="tool", radius=1e9 if huge else 0.0025))
                self.sent["commands"] += 1
                self.sent["huge_radii"] += huge
