#!/usr/bin/python3
"""Every tool's --help: exit status 0, the text on standard output, and each option that the
text names explained on a line of its own (an indented line that starts with it, or with a short
option before it as CLI11 lists "-h,--help", or lists it after a comma).

usage: test/help_check.py TOOL...   (ctest runs it on the built tools)
"""
import os
import re
import subprocess
import sys

failures = []
for tool in sys.argv[1:]:
    name = os.path.basename(tool)
    run = subprocess.run([tool, "--help"], capture_output=True, text=True, timeout=60)
    if run.returncode != 0:
        failures.append(f"{name} --help exits {run.returncode}")
    if not run.stdout.strip():
        failures.append(f"{name} --help prints nothing on standard output")
    explained = set()
    for line in run.stdout.splitlines():
        body = line.strip()
        start = re.match(r"(-\w,\s*)?(--[\w-]+)", body)
        if line[:1].isspace() and start:
            explained.add(start.group(2))
            explained |= set(re.findall(r",\s*(--[\w-]+)", body))
    for option in sorted(set(re.findall(r"--[a-z][\w-]*", run.stdout)) - explained):
        failures.append(f"{name} --help names {option} without explaining it")
print("\n".join(failures) or f"{len(sys.argv) - 1} tools: --help exits 0 and explains every option")
sys.exit(1 if failures else 0)
