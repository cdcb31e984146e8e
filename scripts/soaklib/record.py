"""A soak run's raw data, what the judge reads: one JSON object, written by `soak.py --record`,
read back by `soak.py --judge` and the tests (test/scripts/soak_judge_test.py).

Times are in seconds: `arrival`, `window`, stalls, collections and latency times on this
computer's monotonic clock, stamps on the node's wall clock.

  format          1
  node_rate       the node's ~rate (Hz)
  fault_every     its ~test_fault_every (0: no injected faults)
  max_gap         the largest ~status gap asserted at any speed (s)
  warmup_s        how long the warm-up lasted, before the window
  window          [start, end] of the judged part of the run
  clock_offset    wall clock - monotonic clock at the end (used when no status arrived)
  node_alive      the node's process at the end
  rss_mb          [start, end] (end null when the node had gone)
  at_start        {"rejected_inputs", "faults"} of the last status before the window, and
                  {"sent"}: the counts of `sent` then
  sent            what the load generator sent (load.py), counted from its start
  statuses        [arrival, stamp, step, state, text, rejected_inputs, faults] of every ~status
                  received in the soak's own process
  latency         [arrival, pose stamp -> mesh marker (s)] of every mesh marker with a stamp
  non_finite_on   the topics on which a NaN or infinity was published
  receiver        {"core", "exit_code", "arrivals": [[monotonic, wall, stamp]], "collections":
                  [[start, end]] of its garbage collections over 5 ms} (receive.py)
  watches         [[core, null or {"stalls": [[start, end]], "share", "top"}]] for each watched
                  core (watch.py)
"""
import collections
import json
import math

FORMAT = 1

Status = collections.namedtuple("Status", "arrival stamp step state text rejected_inputs faults")


def status_row(arrival, m):
    """A ~status message received at `arrival` as a row of `statuses`."""
    return [arrival, m.header.stamp.to_sec(), m.step, m.state, m.text, m.rejected_inputs, m.faults]


def finite_or_none(x):
    return x if x is not None and math.isfinite(x) else None


def save(record, path):
    with open(path, "w") as f:
        json.dump(record, f, allow_nan=False)
        f.write("\n")


def load(path):
    with open(path) as f:
        record = json.load(f)
    if record.get("format") != FORMAT:
        raise ValueError("%s: not a soak record of format %d" % (path, FORMAT))
    return record
