#!/usr/bin/python3
"""launch/playback.launch on a short recorded session (test/playback.test):
- the bag's clock starts only after the node said it reached its pre-operative equilibrium (a
  bag started with the node keeps it from ever converging: no colour reference);
- the press is coloured: some mesh vertex during the bag shows a warm colour, while the pale tissue
  tone and its shading keep blue/red at 0.8 (the mesh stays pale throughout without a reference);
- no tf transform is sent twice with the same child frame and stamp, during the bag or in the
  3 s after it ended with the clock standing still (what listeners report as TF_REPEATED_DATA),
  and the probe's tip frame did go out (the check is not vacuous)."""
import threading
import time
import unittest

import rospy
import rostest
from rosgraph_msgs.msg import Clock
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker

from liver_sim.msg import SimulationStatus

PALE_BLUE_OVER_RED = 0.80  # the unmoved tissue tone (mesh_marker.cpp), any shading
WARM = 0.6                 # blue/red below it: about 0.55 mm of displacement at the 5 mm scale


class Playback(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.equilibrium_at = None  # wall times
        self.first_clock_at = None
        self.clock_changed_at = None
        self.clock = None
        self.warmest = 1.0          # lowest blue/red of a vertex while the bag plays
        self.sent = {}              # (child frame, stamp) -> times sent
        self.frames = set()
        rospy.Subscriber("/liver_sim/status", SimulationStatus, self.on_status)
        rospy.Subscriber("/clock", Clock, self.on_clock)
        rospy.Subscriber("/liver_sim/mesh", Marker, self.on_mesh)
        rospy.Subscriber("/tf", TFMessage, self.on_tf)

    def on_status(self, s):
        with self.lock:
            if self.equilibrium_at is None and (s.state == "converged" or (s.state == "idle" and s.step > 0)):
                self.equilibrium_at = time.monotonic()

    def on_clock(self, c):
        with self.lock:
            now = time.monotonic()
            if self.first_clock_at is None:
                self.first_clock_at = now
            if c.clock != self.clock:
                self.clock, self.clock_changed_at = c.clock, now

    def on_mesh(self, m):
        with self.lock:
            playing = self.first_clock_at is not None
        if playing and m.colors:
            warmest = min(c.b / c.r for c in m.colors if c.r > 0.05)
            with self.lock:
                self.warmest = min(self.warmest, warmest)

    def on_tf(self, msg):
        with self.lock:
            for t in msg.transforms:
                key = (t.child_frame_id, t.header.stamp.to_nsec())
                self.sent[key] = self.sent.get(key, 0) + 1
                self.frames.add(t.child_frame_id)

    def test_plays_after_equilibrium_coloured_without_repeated_tf(self):
        deadline = time.monotonic() + 120
        ended = False
        while time.monotonic() < deadline and not ended:
            time.sleep(0.2)
            with self.lock:
                # The bag has ended when its clock stood still for 3 s (it plays at 30 Hz).
                ended = self.clock_changed_at is not None and time.monotonic() - self.clock_changed_at > 3.0
        self.assertTrue(ended, "the bag did not play to its end")
        with self.lock:
            self.assertIsNotNone(self.equilibrium_at, "the node never said it reached its equilibrium")
            self.assertGreater(self.first_clock_at, self.equilibrium_at, "the bag played before the equilibrium")
            self.assertLess(self.warmest, WARM, f"the press is not coloured (blue/red {self.warmest:.2f}; "
                                                f"pale tissue {PALE_BLUE_OVER_RED})")
            self.assertIn("tool_tip", self.frames)
            repeated = {k: n for k, n in self.sent.items() if n > 1}
            self.assertEqual(repeated, {}, "transforms sent again with the same stamp")


if __name__ == "__main__":
    rospy.init_node("playback_test")
    rostest.rosrun("liver_sim", "playback", Playback)
