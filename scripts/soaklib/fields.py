"""The floating-point fields of the node's messages, for the soak's check that none is NaN or
infinite."""
import math
import struct

import numpy as np


def non_finite(msg):
    """Whether a floating-point field of a message (nested messages and arrays included) is NaN
    or infinite."""
    for name, kind in zip(msg.__slots__, msg._slot_types):
        value, base = getattr(msg, name), kind.split("[")[0]
        values = value if kind != base else [value]
        if base in ("float32", "float64"):
            if not all(math.isfinite(v) for v in values):
                return True
        elif "/" in base and any(non_finite(v) for v in values):
            return True
    return False


def mesh_marker_fields(raw):
    """Stamp (s) and floating-point fields (pose and scale, color, points, colors) of a serialized
    visualization_msgs/Marker, read in place. The mesh has thousands of points: genpy's
    deserialisation makes an object of each (25 ms a mesh on this machine against 5 us here, a
    quarter of the core the soak shares with its receiver at the node's mesh rate).
    Raises struct.error or ValueError for a message too short for its fields."""
    secs, nsecs = struct.unpack_from("<II", raw, 4)
    o = 12
    for _ in range(2):  # header.frame_id, ns
        o += 4 + struct.unpack_from("<I", raw, o)[0]
    o += 12  # id, type, action
    pose_scale = np.frombuffer(raw, "<f8", 10, o)
    color = np.frombuffer(raw, "<f4", 4, o + 80)
    o += 80 + 16 + 8 + 1  # pose, scale, color, lifetime, frame_locked
    n = struct.unpack_from("<I", raw, o)[0]
    points = np.frombuffer(raw, "<f8", 3 * n, o + 4)
    o += 4 + 24 * n
    n = struct.unpack_from("<I", raw, o)[0]
    colors = np.frombuffer(raw, "<f4", 4 * n, o + 4)
    return secs + 1e-9 * nsecs, (pose_scale, color, points, colors)
