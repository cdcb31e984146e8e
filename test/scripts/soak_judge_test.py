#!/usr/bin/python3
"""The soak's judge (scripts/soaklib/judge.py) on recorded data: soak_excerpt.json, 15 s of a real
60 s soak of the phantom on a loaded two-core machine (its "note" says which part). Each check
passes on the record as it came, except the frame rate, which the load kept at about half the
node's rate; and each check fails on a copy doctored to violate it (the frame rate: passes on a
copy with twice the frames). Only the check under test is asserted on a doctored copy.

usage: test/scripts/soak_judge_test.py   (ctest runs it; no master, no node)
"""
import copy
import json
import os
import sys
import unittest

HERE = os.path.dirname(os.path.realpath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
from soaklib import judge  # noqa: E402
from soaklib.record import Status  # noqa: E402

with open(os.path.join(HERE, "soak_excerpt.json")) as f:
    RECORDED = json.load(f)

ALIVE = "node alive"
FLOWING = "status kept flowing (messages in both halves of the run)"
RECEIVED = "the status receiver (a process of its own) received statuses"
MEMORY = "memory flat (end <= 1.1 start + 20 MB)"
EVERY_STEP = "every step's status received (the step counter never skips)"
FINITE = "nothing non-finite published (status, wrench, mesh, instruments, vessels)"
REFUSED = "refused inputs counted (all refused service calls, at most every invalid message)"
FAULTS = "injected faults counted, and the node stepped on after them"
HEARTBEATS = "heartbeats while the injected delays held steps up"
HELD_UP = "the held-up steps' statuses say so (as many as one injection in five, within 10% + 2)"
MAX_GAP = "no status gap above 10 s"
RECEIVER_GAPS = "status gaps <= two frames at the receiver (the node's part)"
STAMP_GAPS = "status stamps (when the node published) <= two frames apart while the machine ran"
FRAME_RATE = "frame rate >= 90% of the node's rate (outside the injected delays)"
QUEUE = "no growing queue (late latency <= 2 x early + 0.2 s)"


def verdicts(record):
    _, checks, timing = judge.judge(record)
    return dict(checks, **timing)


def statuses(record):
    return [Status(*s) for s in record["statuses"]]


def in_window(record, t):
    return record["window"][0] <= t <= record["window"][1]


class Judge(unittest.TestCase):
    def setUp(self):
        self.record = copy.deepcopy(RECORDED)
        self.start, self.end = RECORDED["window"]

    def fails(self, check, record=None):
        self.assertFalse(verdicts(record or self.record)[check], check)

    def test_recorded(self):
        v = verdicts(self.record)
        self.assertEqual([k for k, ok in v.items() if not ok], [FRAME_RATE])
        self.assertEqual(set(v), {ALIVE, FLOWING, RECEIVED, MEMORY, EVERY_STEP, FINITE, REFUSED, FAULTS, HEARTBEATS,
                                  HELD_UP, MAX_GAP, RECEIVER_GAPS, STAMP_GAPS, FRAME_RATE, QUEUE})

    def test_the_judge_keeps_its_record(self):
        judge.judge(self.record)
        self.assertEqual(self.record, RECORDED)

    def test_node_gone(self):
        self.record["node_alive"] = False
        self.fails(ALIVE)

    def test_status_stopped_halfway(self):
        half = (self.start + self.end) / 2
        self.record["statuses"] = [s for s in self.record["statuses"] if s[0] < half]
        self.fails(FLOWING)

    def test_receiver_received_one(self):
        arrivals = self.record["receiver"]["arrivals"]
        self.record["receiver"]["arrivals"] = [a for a in arrivals if not in_window(self.record, a[0])][:1]
        self.fails(RECEIVED)

    def test_memory_grew(self):
        start = self.record["rss_mb"][0]
        self.record["rss_mb"][1] = 1.1 * start + 20.5
        self.fails(MEMORY)
        self.record["rss_mb"][1] = None  # the node's memory unread: gone
        self.fails(MEMORY)

    def test_a_status_lost(self):
        s = statuses(self.record)
        # A status whose neighbours are the steps before and after it: without it, a step skipped.
        i = next(i for i in range(1, len(s) - 1) if in_window(self.record, s[i].arrival)
                 and s[i - 1].step == s[i].step - 1 and s[i + 1].step == s[i].step + 1)
        del self.record["statuses"][i]
        self.fails(EVERY_STEP)

    def test_non_finite_published(self):
        self.record["non_finite_on"] = ["mesh"]
        self.fails(FINITE)

    def test_refusals_not_counted(self):
        self.record["sent"]["refused_service_calls"] += 1000  # more refused calls than the node counted
        self.fails(REFUSED)

    def test_more_refusals_than_invalid_inputs(self):
        self.record["at_start"]["rejected_inputs"] -= 10000
        self.fails(REFUSED)

    def test_faults_not_counted(self):
        last_faults = statuses(self.record)[-1].faults
        self.record["at_start"]["faults"] = last_faults
        for s in self.record["statuses"]:
            s[6] = last_faults
        self.fails(FAULTS)

    def test_no_step_after_the_last_fault(self):
        s = statuses(self.record)
        last_fault = max(i for i, m in enumerate(s) if m.state == "fault" and in_window(self.record, m.arrival))
        self.record["statuses"] = self.record["statuses"][:last_fault + 1]
        self.fails(FAULTS)

    def test_no_heartbeat_while_held_up(self):
        for s in self.record["statuses"]:
            if s[3] == "busy":
                s[4] = "a frame in progress for 40 ms"
        self.fails(HEARTBEATS)

    def test_more_steps_say_held_up_than_injected(self):
        said = 0
        for s in self.record["statuses"]:
            if s[3] == "iterating" and judge.HELD_UP_TEXT not in s[4] and in_window(self.record, s[0]) and said < 6:
                s[4] += "; " + judge.HELD_UP_TEXT
                said += 1
        self.fails(HELD_UP)

    def test_a_gap_longer_than_max_gap(self):
        self.record["receiver"]["arrivals"] = [a for a in self.record["receiver"]["arrivals"]
                                               if not self.start + 2 < a[0] < self.start + 13]
        self.fails(MAX_GAP)

    def test_a_receiver_gap_the_node_made(self):
        # 0.2 s of statuses lost at the receiver: their stamps 0.2 s apart, the receiver running.
        mid = (self.start + self.end) / 2
        self.record["receiver"]["arrivals"] = [a for a in self.record["receiver"]["arrivals"]
                                               if not mid < a[0] < mid + 0.2]
        self.fails(RECEIVER_GAPS)

    def test_a_stamp_gap_and_the_machine_standing_still(self):
        mid = (self.start + self.end) / 2
        self.record["statuses"] = [s for s in self.record["statuses"] if not mid < s[0] < mid + 0.2]
        self.fails(STAMP_GAPS)
        # Every watched core kept from running over the gap (the stamps are on the wall clock).
        offset = judge.np.median([w - m for m, w, _ in self.record["receiver"]["arrivals"]])
        stamps = [s[1] - offset for s in self.record["statuses"]]
        before = max(t for t in stamps if t <= mid)
        after = min(t for t in stamps if t >= mid + 0.2)
        for _, watch in self.record["watches"]:
            watch["stalls"].append([before, after])
        self.assertTrue(verdicts(self.record)[STAMP_GAPS])
        self.record["watches"][0][1]["top"] = False  # a watch below the top priority: not judged
        self.fails(STAMP_GAPS)

    def test_frame_rate(self):
        for s in self.record["statuses"]:
            s[2] *= 2  # twice the frames in the same time
        self.assertTrue(verdicts(self.record)[FRAME_RATE])
        self.fails(FRAME_RATE, RECORDED)

    def test_growing_queue(self):
        for lat in self.record["latency"]:
            if lat[0] >= self.end - (self.end - self.start) / 3:
                lat[1] += 1.0
        self.fails(QUEUE)


if __name__ == "__main__":
    unittest.main()
