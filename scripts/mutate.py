#!/usr/bin/env python3
"""Mutation testing of the physics core: does the fast test suite notice wrong physics?

Each mutation is a small change of the source (a sign flip, a dropped term, an off-by-one, a
wrong factor) given as (file, exact original text, replacement). One at a time, the script
applies it, rebuilds the core and the fast physics test binaries, runs them (each under
a timeout, stopping at the first failure) and restores the source. A mutation is *killed* when
a test fails (or times out), *survives* when every test passes. A mutation whose original text
is no longer in the file (or occurs more than once) is reported "not applicable" and not run, so
the list stays valid as the code evolves. Mutations marked equivalent cannot change any result
(the reason is given); they are run to confirm that they survive and are not counted.

    scripts/mutate.py                  # every mutation (about an hour on 2 shared cores)
    scripts/mutate.py --only NS1,MM1   # some of them
    scripts/mutate.py --list           # the list and whether each applies, nothing built

Run after a build (scripts/test.sh). Prints a Markdown table and the kill rate; exits non-zero
when the unmutated suite fails or a source could not be restored.
"""
import argparse
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

from mutations import MUTATIONS  # the list, beside this script

REPO = pathlib.Path(__file__).resolve().parent.parent
BUILD = REPO / "build" / "ws" / "build"
BIN = REPO / "build" / "ws" / "devel" / "lib" / "liver_sim"
BACKUP = REPO / "build" / "mutation_backup"

# The fast physics tests, in the order they run (cheapest and most discriminating first), each
# stopping at its first failure; the slow ones (phantom frames, Hertz refinement, the haptic
# tracking run) are filtered out or not listed. Last, the reduced stress matrix's expected outcomes.
FAIL_FAST = "--gtest_fail_fast"
TESTS = [
    ("model_tests", [FAIL_FAST, "--gtest_filter=-*VascularisedLiver*"]),
    ("simulation_tests", [FAIL_FAST, "--gtest_filter=-*OneIterationPerHapticFrame*:LiverPhantom.*"]),
    ("geometry_tests", [FAIL_FAST, "--gtest_filter=ClosestOnTriangle.*:ClosestPoints.*"]),
    ("contact_tests", [FAIL_FAST, "--gtest_filter=-Hertz*:NodeCompliance.*:InstrumentDrawing.*"]),
    ("stepper_tests", [FAIL_FAST, "--gtest_filter=Probe.*:TimeBudget.*"]),
    ("io_tests", [FAIL_FAST, "--gtest_filter=VesselTree.*"]),
    ("registration_tests", [FAIL_FAST, "--gtest_filter=PhantomRegistration.ACloudsFrame*"]),
    ("stress", ["--quick"]),
]



def run(cmd, timeout, log):
    """Runs cmd (niced) with a timeout; returns (return code or 'timeout', seconds)."""
    start = time.monotonic()
    with open(log, "a") as out:
        out.write("$ " + " ".join(map(str, cmd)) + "\n")
        out.flush()
        proc = subprocess.Popen(["nice", "-n", "19"] + list(map(str, cmd)), stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the process group this call started
            proc.wait()
            rc = "timeout"
    return rc, time.monotonic() - start


def build(tests, log, timeout):
    """Builds the given test binaries only (and the core's parts they link)."""
    rc, _ = run(["make", "-C", BUILD, "-j2"] + [name for name, _ in tests], timeout, log)
    return rc == 0


def run_tests(tests, log, timeout):
    """Runs the tests in order; returns the first failing test binary, or None."""
    for name, args in tests:
        rc, _ = run([BIN / name] + args, timeout, log)
        if rc != 0:
            return f"{name} ({'timeout' if rc == 'timeout' else 'failed'})"
    return None


def applicable(m):
    text = (REPO / m.path).read_text()
    count = text.count(m.original)
    return "ok" if count == 1 else ("not applicable (text gone)" if count == 0 else f"not applicable ({count} matches)")


def restore_leftovers():
    """A run killed mid-mutation left its backup: put the original back."""
    if not BACKUP.exists():
        return
    for saved in BACKUP.rglob("*"):
        if saved.is_file():
            target = REPO / saved.relative_to(BACKUP)
            shutil.copy2(saved, target)
            print(f"restored {target} from an interrupted run", file=sys.stderr)
    shutil.rmtree(BACKUP)


def mutate_and_test(m, tests, log, build_timeout, test_timeout):
    source = REPO / m.path
    original = source.read_text()
    saved = BACKUP / m.path
    saved.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy2(source, saved)
    try:
        source.write_text(original.replace(m.original, m.replacement, 1))
        if not build(tests, log, build_timeout):
            return "build error"
        failed = run_tests(tests, log, test_timeout)
        return f"killed by {failed}" if failed else "survived"
    finally:
        source.write_text(original)
        saved.unlink()


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", help="comma-separated mutation keys")
    parser.add_argument("--list", action="store_true", help="list the mutations and whether each applies")
    parser.add_argument("--tests", help="comma-separated test binaries of the fast set to run (default: all)")
    parser.add_argument("--budget", type=float, default=120, help="minutes; mutations beyond it are not run")
    parser.add_argument("--test-timeout", type=float, default=240, help="seconds per test binary")
    parser.add_argument("--build-timeout", type=float, default=900, help="seconds per build")
    parser.add_argument("--log", default=str(REPO / "build" / "mutate.log"))
    args = parser.parse_args()

    selected = MUTATIONS
    if args.only:
        keys = args.only.split(",")
        unknown = set(keys) - {m.key for m in MUTATIONS}
        if unknown:
            parser.error("unknown mutation(s): " + ", ".join(sorted(unknown)))
        selected = [m for m in MUTATIONS if m.key in keys]
    if args.list:
        for m in selected:
            print(f"{m.key:5} {m.path:36} {applicable(m):28} {m.what}" + (" [equivalent]" if m.equivalent else ""))
        return 0

    tests = TESTS
    if args.tests:
        names = args.tests.split(",")
        tests = [t for t in TESTS if t[0] in names]
        if len(tests) != len(names):
            parser.error("--tests takes names among " + ", ".join(name for name, _ in TESTS))

    restore_leftovers()
    open(args.log, "w").close()
    start = time.monotonic()
    print("unmutated build and tests ...", file=sys.stderr)
    if not build(tests, args.log, args.build_timeout) or run_tests(tests, args.log, args.test_timeout):
        print(f"the unmutated suite does not pass: see {args.log}", file=sys.stderr)
        return 1

    rows = []
    for m in selected:
        status = applicable(m)
        if status == "ok":
            if (time.monotonic() - start) / 60 > args.budget:
                status = "not run (budget)"
            else:
                print(f"{m.key}: {m.what} ...", file=sys.stderr)
                status = mutate_and_test(m, tests, args.log, args.build_timeout, args.test_timeout)
                print(f"{m.key}: {status}", file=sys.stderr)
        rows.append((m, status))
    # The build again matches the source.
    if not build(tests, args.log, args.build_timeout):
        print("warning: the rebuild of the restored sources failed", file=sys.stderr)

    print("| mutation | file | change | result |\n|---|---|---|---|")
    for m, status in rows:
        shown = status
        if m.equivalent:
            shown = ("equivalent (survives): " if status == "survived" else f"CLAIMED EQUIVALENT, {status}: ") + m.equivalent
        print(f"| {m.key} | {m.path.split('/')[-1]} | {m.what} | {shown} |")
    counted = [(m, s) for m, s in rows if not m.equivalent and (s.startswith("killed") or s == "survived")]
    killed = sum(s.startswith("killed") for _, s in counted)
    survivors = [m.key for m, s in counted if s == "survived"]
    print(f"\nkilled {killed} of {len(counted)} ({100 * killed / max(1, len(counted)):.0f}%); "
          f"survivors: {', '.join(survivors) or 'none'}; "
          f"{sum(1 for m, _ in rows if m.equivalent)} equivalent; "
          f"{sum(1 for _, s in rows if not (s.startswith('killed') or s == 'survived'))} not counted otherwise; "
          f"{(time.monotonic() - start) / 60:.0f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
