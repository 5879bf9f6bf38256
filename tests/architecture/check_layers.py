#!/usr/bin/env python3
"""The arrows allowed between imucal's folders (docs/ARCHITECTURE.md), checked on every #include
and every target_link_libraries of the libraries; and the rule that only the SQLite layer
(storage/sqlite.*) calls SQLite. Prints each forbidden arrow with where it is; exit 1 if any.

Usage: check_layers.py SOURCE_DIR
"""
import os
import re
import sys

# folder -> the folders its code may use. Tests (tests/) may use anything.
ALLOWED = {
    "core": set(),
    "motion_programs": {"core"},
    "drivers": {"core"},  # no estimator, no simulation, no storage
    "estimators": {"core", "motion_programs"},
    "storage": {"core"},
    "sim": {"core", "motion_programs", "estimators", "drivers"},
    "pipeline": {"core", "motion_programs", "estimators", "storage"},
    "plan": {"core", "motion_programs", "estimators", "pipeline", "sim"},
    "daemon": {"core", "motion_programs", "drivers", "estimators", "storage", "sim", "pipeline", "plan"},
    "cli": {"core", "motion_programs", "drivers", "estimators", "storage", "sim", "pipeline", "plan", "daemon", "bench"},
    "bench": {"core", "motion_programs", "drivers", "estimators", "storage", "sim", "pipeline", "plan"},
}
TARGETS = {
    "imucal_core": "core", "imucal_motion": "motion_programs", "imucal_drivers": "drivers",
    "imucal_estimators": "estimators", "imucal_storage": "storage", "imucal_sim": "sim",
    "imucal_pipeline": "pipeline", "imucal_plan": "plan", "imucal_daemon": "daemon",
    "imucal_bench_storage": "bench",
}
SQLITE_LAYER = {"storage/sqlite.hpp", "storage/sqlite.cpp"}


def main(root):
    problems = []
    for folder, allowed in ALLOWED.items():
        for dirpath, _, files in os.walk(os.path.join(root, folder)):
            for name in files:
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, root)
                if name == "CMakeLists.txt":
                    text = open(path, encoding="utf-8").read()
                    for m in re.finditer(r"target_link_libraries\(\s*(\w+)([^)]*)\)", text):
                        if TARGETS.get(m.group(1)) != folder:
                            continue
                        for lib in re.findall(r"\bimucal_\w+", m.group(2)):
                            to = TARGETS.get(lib)
                            if to and to != folder and to not in allowed:
                                problems.append(f"{rel}: {m.group(1)} links {lib} ({folder} -> {to})")
                    continue
                if not name.endswith((".cpp", ".hpp")):
                    continue
                text = open(path, encoding="utf-8").read()
                for n, line in enumerate(text.splitlines(), 1):
                    m = re.match(r'\s*#include "([\w.]+)/', line)
                    if m and m.group(1) in ALLOWED and m.group(1) != folder and m.group(1) not in allowed:
                        problems.append(f"{rel}:{n}: includes {m.group(1)}/ ({folder} -> {m.group(1)})")
                    if rel not in SQLITE_LAYER and ("sqlite3_" in line or "<sqlite3.h>" in line):
                        problems.append(f"{rel}:{n}: calls SQLite outside the SQLite layer (storage/sqlite.hpp)")
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} forbidden arrow(s); the allowed ones are in docs/ARCHITECTURE.md")
        return 1
    print(f"layers: every #include and link of {len(ALLOWED)} folders follows docs/ARCHITECTURE.md")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
