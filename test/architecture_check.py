#!/usr/bin/env python3
"""The core's parts keep to their link lists (doc/architecture.md).

Usage: architecture_check.py SOURCE_DIR PARTS_FILE

PARTS_FILE is written by CMakeLists.txt at configure time, one line per part: "name: part part ...",
the parts its library links. A part's sources (src/core/NAME) and headers (include/liver_sim/NAME)
may include the headers of its own part and of the parts it links, directly or through them, and
no ROS header; every folder under src/core is a part. Exits 1 naming each violation.
"""
import pathlib
import re
import sys

ROS_PREFIXES = ("ros/", "tf2", "sensor_msgs/", "geometry_msgs/", "visualization_msgs/", "std_msgs/",
                "std_srvs/", "diagnostic_", "dynamic_reconfigure/", "pcl_conversions/", "rosbag/")
INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]', re.M)


def read_parts(path):
    parts = {}
    for line in pathlib.Path(path).read_text().splitlines():
        if line.strip():
            name, _, deps = line.partition(":")
            parts[name.strip()] = deps.split()
    return parts


def reachable(parts, name):
    seen, todo = {name}, [name]
    while todo:
        for dep in parts[todo.pop()]:
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return seen


def violations(source_dir, parts):
    root = pathlib.Path(source_dir)
    found = []
    for folder in sorted((root / "src" / "core").iterdir()):
        if folder.is_dir() and folder.name not in parts:
            found.append(f"src/core/{folder.name}: a folder that is no part (no liver_sim_part in CMakeLists.txt)")
    for name in sorted(parts):
        allowed = reachable(parts, name)
        files = list((root / "src" / "core" / name).glob("**/*.[ch]*")) + \
            list((root / "include" / "liver_sim" / name).glob("**/*.h"))
        if not files:
            found.append(f"part {name}: no source or header")
        for f in sorted(files):
            rel = f.relative_to(root)
            for kind, header in INCLUDE.findall(f.read_text(errors="replace")):
                if header.startswith(ROS_PREFIXES):
                    found.append(f"{rel}: includes the ROS header <{header}>; the core is ROS-free")
                elif header.startswith("liver_sim/"):
                    pieces = header.split("/")
                    other = pieces[1] if len(pieces) > 2 else None
                    if other is None or other not in parts:
                        found.append(f"{rel}: includes {header}, which is in no part")
                    elif other not in allowed:
                        found.append(f"{rel}: part {name} includes {header}, but does not link part {other} "
                                     f"(links: {', '.join(sorted(allowed - {name})) or 'none'})")
                elif kind == '"' and not (f.parent / header).exists():
                    found.append(f"{rel}: includes \"{header}\", not a file of its own folder")
    return found


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    parts = read_parts(sys.argv[2])
    found = violations(sys.argv[1], parts)
    for v in found:
        print(v)
    print(f"architecture_check: {len(parts)} parts, {len(found)} violations")
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
