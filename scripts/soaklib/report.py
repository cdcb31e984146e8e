"""The soak's report: the judge's measures and verdicts of a record, rounded for reading (times
to the millisecond; judged before rounding), as the JSON that soak.py prints and writes."""
import json

import numpy as np

from . import judge


def rounded(times):
    """A dict of times in seconds, to the millisecond."""
    return {k: round(v, 3) for k, v in times.items()}


def round_or_none(x, digits):
    return None if x is None or x != x else round(x, digits)


def report(record):
    """The report of a run's record, its checks and timing checks last."""
    m, checks, timing = judge.judge(record)
    watches = [w for _, w in record["watches"]]
    late_by, lat = m["late_by"], m["latency"]
    stalls, machine, collections = m["stalls"], m["machine"], m["collections"]
    r = {
        "warmup_s": round(record["warmup_s"], 1),
        "duration_s": round(m["span"], 1),
        "node_alive": record["node_alive"],
        "sent": m["sent"],
        "rss_mb": {"start": round_or_none(record["rss_mb"][0], 1), "end": round_or_none(record["rss_mb"][1], 1)},
        "status_messages": len(m["window"]),
        "status_messages_at_the_receiver": len(m["received"]),
        "status_receiver_exit_code": record["receiver"]["exit_code"],
        "status_max_gap_s": round(max(m["gaps"]), 3) if m["gaps"] else None,
        # How much later than usual (the median) statuses arrived after their stamps.
        "status_delivered_late_by_s": {q: round(float(np.percentile(late_by, p)), 4) if late_by else None
                                       for q, p in (("p99", 99), ("p99.9", 99.9), ("max", 100))},
        "status_gaps_over_two_frames": sum(1 for g in m["gaps"] if g > m["two_frames"]),
        "status_gaps_over_two_frames_apart": [rounded(g) for g in m["long_gaps"]],
        "receiver_garbage_collections_over_5ms": {"count": len(collections),
                                                  "max_s": round(max((e - s for s, e in collections), default=0.0), 3)},
        "receiver_core_stalls_over_10ms": {"count": len(stalls),
                                           "max_s": round(max((e - s for s, e in stalls), default=0.0), 3)},
        "cores_watched": {"cores": [core for core, _ in record["watches"]],
                          "watched_at_the_top_priority": [bool(w and w["top"]) for w in watches],
                          "machine_stalls_judged": m["machine_judged"],
                          "processor_share_max": round(max((w["share"] for w in watches if w), default=0.0), 4)},
        # Times at which every watched core had been kept from running for over 10 ms.
        "machine_stalls": {"count": len(machine),
                           "max_s": round(max((e - s for s, e in machine), default=0.0), 3),
                           "total_s": round(sum(e - s for s, e in machine), 3)},
        "status_max_stamp_gap_s": round(max(m["stamp_gaps"]), 3) if m["stamp_gaps"] else None,
        "status_stamp_gaps_over_two_frames": len(m["long_stamp_gaps"]),
        "status_stamp_gaps_over_two_frames_apart": [rounded(g) for g in m["long_stamp_gaps"]],
        "status_busy": m["busy"],
        "status_busy_in_a_frame_of_0.2_s_or_more": m["busy_long"],
        "longest_frame_s": round(max(m["frame_gaps"]), 3) if m["frame_gaps"] else None,
        "status_steps_skipped": m["skipped"],
        "mesh_markers": len(lat),
        "latency_s": {"early_median": round(float(np.median(m["early"])), 3) if m["early"] else None,
                      "late_median": round(float(np.median(m["late"])), 3) if m["late"] else None,
                      "max": round(max(l for _, l in lat), 3) if lat else None},
        "frames": {"asked_hz": record["node_rate"], "achieved_hz": round(m["achieved_hz"], 2),
                   "dropped": int(round(max(0.0, record["node_rate"] * m["span"] - m["frames"]))),
                   "done": m["frames"],
                   "held_up_on_purpose": {"steps": m["held_steps"], "s": round(m["held_s"], 1),
                                          "expected_steps": round(m["delays_expected"], 1)},
                   "achieved_outside_the_injected_delays_hz": round(m["kept_hz"], 2)},
        "refused_inputs_counted": judge.refused_counted(record, m),
        "faults": {"injected_every_frames": record["fault_every"],
                   "counted": judge.faults_counted(record, m),
                   "fault_statuses": m["fault_statuses"],
                   "steps_after_the_last_fault": m["steps_after_fault"]},
        "non_finite_published_on": sorted(record["non_finite_on"]),
        "timing_checks": timing,
        "checks": checks,
    }
    return r


def failed(r, timing=True):
    """The names of the report's failed checks (with the timing checks unless told not to)."""
    checks = list(r["checks"].items()) + (list(r["timing_checks"].items()) if timing else [])
    return [name for name, ok in checks if not ok]


def text(r):
    return json.dumps(r, indent=2)
