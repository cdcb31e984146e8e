#!/usr/bin/python3
"""The soak's check for non-finite numbers in the node's messages (scripts/soaklib/fields.py):
the mesh marker read in place gives genpy's fields of the same message, and a NaN or infinity
anywhere in a message, nested or in an array, is found.

usage: test/scripts/soak_fields_test.py   (ctest runs it; no master)
"""
import io
import math
import os
import struct
import sys
import unittest

import numpy as np
import rospy
from geometry_msgs.msg import Point, WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

sys.path.insert(0, os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "..", "scripts"))
from soaklib.fields import mesh_marker_fields, non_finite  # noqa: E402


def marker(points=5):
    rng = np.random.default_rng(1)
    m = Marker(ns="liver surface", id=3, type=Marker.TRIANGLE_LIST, text="a label", mesh_resource="package://x")
    m.header.frame_id, m.header.stamp = "liver", rospy.Time(1796418673, 718652700)
    m.pose.position.x, m.pose.orientation.w = 0.25, 1.0
    m.scale.x, m.scale.y, m.scale.z = 1.0, 2.0, 3.0
    m.color = ColorRGBA(0.1, 0.2, 0.3, 0.8)
    m.points = [Point(*p) for p in rng.normal(size=(points, 3))]
    m.colors = [ColorRGBA(*c) for c in rng.uniform(size=(points, 4))]
    return m


def serialized(msg):
    buff = io.BytesIO()
    msg.serialize(buff)
    return buff.getvalue()


class Fields(unittest.TestCase):
    def test_mesh_read_in_place_as_genpy_reads_it(self):
        m = marker()
        stamp, (pose_scale, color, points, colors) = mesh_marker_fields(serialized(m))
        self.assertAlmostEqual(stamp, m.header.stamp.to_sec(), places=6)
        p, o, s = m.pose.position, m.pose.orientation, m.scale
        self.assertEqual(list(pose_scale), [p.x, p.y, p.z, o.x, o.y, o.z, o.w, s.x, s.y, s.z])
        self.assertEqual(list(color), list(np.float32([m.color.r, m.color.g, m.color.b, m.color.a])))
        self.assertEqual(list(points), [c for q in m.points for c in (q.x, q.y, q.z)])
        self.assertEqual(list(colors), list(np.float32([c for q in m.colors for c in (q.r, q.g, q.b, q.a)])))

    def test_mesh_with_a_nan_point(self):
        m = marker()
        m.points[3].y = math.nan
        _, fields = mesh_marker_fields(serialized(m))
        self.assertFalse(all(np.isfinite(f).all() for f in fields))

    def test_truncated_mesh_refused(self):
        raw = serialized(marker())
        with self.assertRaises((struct.error, ValueError)):
            mesh_marker_fields(raw[:len(raw) - 200])

    def test_non_finite_anywhere(self):
        self.assertFalse(non_finite(marker()))
        m = marker()
        m.points[4].z = math.inf
        self.assertTrue(non_finite(m))
        m = marker()
        m.scale.y = -math.inf
        self.assertTrue(non_finite(m))
        array = MarkerArray(markers=[marker(), marker()])
        self.assertFalse(non_finite(array))
        array.markers[1].colors[0].a = math.nan
        self.assertTrue(non_finite(array))
        w = WrenchStamped()
        self.assertFalse(non_finite(w))
        w.wrench.torque.x = math.nan
        self.assertTrue(non_finite(w))
        j = JointState(name=["a", "b"], position=[0.0, 1.0])
        self.assertFalse(non_finite(j))
        j.position = [0.0, math.nan]  # a float64[] field
        self.assertTrue(non_finite(j))


if __name__ == "__main__":
    unittest.main()
