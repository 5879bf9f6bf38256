#!/usr/bin/env python3
"""The arrows allowed between imucal's folders (docs/ARCHITECTURE.md), checked on every #include
and every target_link_libraries of the libraries; and the rules that only the SQLite layer
(storage/sqlite.*) calls SQLite and only the PostgreSQL layer (storage/postgres.*) calls libpq. Prints each forbidden arrow with where it is; exit 1 if any.

Usage: check_layers.py SOURCE_DIR
"""
import os
import re
import sys

# folder -> the folders its code may use. Tests (tests/) may use anything. The daemon's folders
# are checked one by one ("daemon/run"), "daemon" itself being only the files directly in daemon/;
# "daemon/*" allows every one of them.
BELOW_DAEMON = {"core", "motion_programs", "drivers", "estimators", "storage", "sim", "pipeline", "plan"}
# signing uses nothing of imucal (libsodium and JSON only) and is used by the daemon's folders and
# the command line alone: the libraries below the daemon sign nothing.
SIGNING = "signing"
ALLOWED = {
    "core": set(),
    "signing": set(),
    "motion_programs": {"core"},
    "drivers": {"core"},  # no estimator, no simulation, no storage
    "estimators": {"core", "motion_programs"},
    "storage": {"core"},
    "sim": {"core", "motion_programs", "estimators", "drivers"},
    "pipeline": {"core", "motion_programs", "estimators", "storage"},
    "plan": {"core", "motion_programs", "estimators", "pipeline", "sim"},
    "daemon/config": {SIGNING, "core", "motion_programs", "drivers"},
    "daemon/db": {SIGNING, "core", "storage"},
    # The lab's registry (issue 38): its row types are the daemon database's; PostgreSQL through
    # storage's layer.
    "daemon/registry": {"core", "storage", "daemon/db"},
    "daemon/campaign": {SIGNING, "core", "motion_programs", "pipeline", "daemon/config", "daemon/db"},
    "daemon/production": {SIGNING, "core", "daemon/config", "daemon/db", "daemon/registry"},
    "daemon/devices": {SIGNING, "core", "motion_programs", "drivers", "sim", "daemon/config", "daemon/campaign"},
    # The run engine's loop (issue 37) emits documents and stores nothing: no storage, no
    # estimators or pipeline, and of the service database only the run's state machine
    # (RUN_LOOP_FROM_DB below); its subscribers store, alarm, show and estimate.
    "daemon/run": {"core", "motion_programs", "daemon/config", "daemon/db", "daemon/campaign", "daemon/devices"},
    "daemon/subscribers": {SIGNING, "core", "motion_programs", "estimators", "storage", "pipeline", "daemon/config",
                           "daemon/db", "daemon/campaign", "daemon/devices", "daemon/run"},
    "daemon/sequencer": {"core", "daemon/config", "daemon/db", "daemon/campaign", "daemon/devices", "daemon/run",
                         "daemon/subscribers"},
    "daemon/analysis": {SIGNING, "core", "motion_programs", "estimators", "storage", "pipeline"},
    # The HTTP layer translates (issue 37): the estimators, the pipeline and the recordings are
    # reached through the rooms that decide (analysis, campaign, production, run), never directly.
    "daemon/http": (BELOW_DAEMON - {"estimators", "pipeline", "storage"}) |
                   {SIGNING, "daemon/config", "daemon/db", "daemon/registry", "daemon/campaign", "daemon/production",
                    "daemon/devices", "daemon/run", "daemon/subscribers", "daemon/sequencer", "daemon/analysis"},
    "daemon": BELOW_DAEMON | {SIGNING, "daemon/*"},
    "cli": BELOW_DAEMON | {SIGNING, "daemon", "daemon/*", "bench"},
    # The registry's benchmark (bench/bench_registry.cpp, issue 38) measures the registry as the
    # daemon runs it: its database and the registry (with the site's certificate sequence file).
    "bench": BELOW_DAEMON | {"daemon/db", "daemon/registry"},
}
TARGETS = {
    "imucal_core": "core", "imucal_signing": "signing", "imucal_motion": "motion_programs", "imucal_drivers": "drivers",
    "imucal_estimators": "estimators", "imucal_storage": "storage", "imucal_sim": "sim",
    "imucal_pipeline": "pipeline", "imucal_plan": "plan", "imucal_daemon": "daemon",
    "imucal_bench_storage": "bench",
}
for sub in ("config", "db", "registry", "campaign", "production", "devices", "run", "subscribers", "sequencer", "analysis", "http"):
    TARGETS[f"imucal_daemon_{sub}"] = f"daemon/{sub}"
SQLITE_LAYER = {"storage/sqlite.hpp", "storage/sqlite.cpp"}
RUN_LOOP = "daemon/run"
RUN_LOOP_FROM_DB = {"daemon/db/run_state.hpp"}
POSTGRES_LAYER = {"storage/postgres.hpp", "storage/postgres.cpp"}
# libpq's functions (PQexec, PQconnectdb, ...) and its header.
LIBPQ_CALL = re.compile(r"\bPQ[a-z]\w*\s*\(|<libpq-fe\.h>|<postgresql/libpq-fe\.h>")


def unit_of(path):
    """The folder a file (or an included path) belongs to: its top folder, or daemon/<sub>."""
    parts = path.split("/")
    if parts[0] == "daemon" and len(parts) > 2:
        return f"daemon/{parts[1]}"
    return parts[0]


def allows(frm, to):
    allowed = ALLOWED[frm]
    return to == frm or to in allowed or (to.startswith("daemon/") and "daemon/*" in allowed)


def source_problems(rel, text):
    """The forbidden arrows of one source file `rel` (its path under the root) with text `text`."""
    folder = unit_of(rel)
    problems = []
    for n, line in enumerate(text.splitlines(), 1):
        m = re.match(r'\s*#include "([\w./]+)"', line)
        if m and "/" in m.group(1):
            to = unit_of(m.group(1))
            if folder == RUN_LOOP and to in {"storage", "estimators", "pipeline"}:
                problems.append(f"{rel}:{n}: the run loop includes {m.group(1)} ({folder} -> {to}): it emits "
                                "documents, a subscriber (daemon/subscribers) stores and estimates")
            elif folder == RUN_LOOP and to == "daemon/db" and m.group(1) not in RUN_LOOP_FROM_DB:
                problems.append(f"{rel}:{n}: the run loop includes the service database {m.group(1)}: it emits "
                                "documents, a subscriber (daemon/subscribers) stores them")
            elif to in ALLOWED and not allows(folder, to):
                problems.append(f"{rel}:{n}: includes {m.group(1)} ({folder} -> {to})")
        if rel not in SQLITE_LAYER and ("sqlite3_" in line or "<sqlite3.h>" in line):
            problems.append(f"{rel}:{n}: calls SQLite outside the SQLite layer (storage/sqlite.hpp)")
        if rel not in POSTGRES_LAYER and LIBPQ_CALL.search(line):
            problems.append(f"{rel}:{n}: calls libpq outside the PostgreSQL layer (storage/postgres.hpp)")
    return problems


def self_test():
    """The check must find what it is for: a run-loop file that includes storage or the service
    database, and a daemon/http file that includes the pipeline; and pass what is allowed."""
    bad = {
        "daemon/run/engine.cpp": '#include "storage/recorder.hpp"',
        "daemon/run/x.hpp": '#include "daemon/db/daemon_db.hpp"',
        "daemon/run/y.cpp": '#include "pipeline/pipeline.hpp"',
        "daemon/http/api.cpp": '#include "pipeline/pipeline.hpp"',
    }
    good = {
        "daemon/run/engine.cpp": '#include "daemon/db/run_state.hpp"\n#include "daemon/devices/devices.hpp"',
        "daemon/subscribers/run_file.cpp": '#include "storage/recorder.hpp"',
    }
    failures = [f"not found: {rel}: {text}" for rel, text in bad.items() if not source_problems(rel, text)]
    failures += [f"found wrongly: {p}" for rel, text in good.items() for p in source_problems(rel, text)]
    for f in failures:
        print(f)
    print("self test: " + ("FAILED" if failures else f"{len(bad)} forbidden and {len(good)} allowed examples judged right"))
    return 1 if failures else 0


def main(root):
    problems = []
    for dirpath, dirs, files in os.walk(root):
        if dirpath == root:  # only the source folders (not build/, web/, tests/)
            dirs[:] = [d for d in dirs if d in {u.split("/")[0] for u in ALLOWED}]
        for name in files:
            path = os.path.join(dirpath, name)
            rel = os.path.relpath(path, root)
            folder = unit_of(rel)
            if folder not in ALLOWED:
                continue
            if name == "CMakeLists.txt":
                text = open(path, encoding="utf-8").read()
                for m in re.finditer(r"target_link_libraries\(\s*(\w+)([^)]*)\)", text):
                    if TARGETS.get(m.group(1)) != folder:
                        continue
                    for lib in re.findall(r"\bimucal_\w+", m.group(2)):
                        to = TARGETS.get(lib)
                        if to and not allows(folder, to):
                            problems.append(f"{rel}: {m.group(1)} links {lib} ({folder} -> {to})")
                continue
            if not name.endswith((".cpp", ".hpp")):
                continue
            problems += source_problems(rel, open(path, encoding="utf-8").read())
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} forbidden arrow(s); the allowed ones are in docs/ARCHITECTURE.md")
        return 1
    print(f"layers: every #include and link of {len(ALLOWED)} folders follows docs/ARCHITECTURE.md")
    return 0


if __name__ == "__main__":
    sys.exit(self_test() if sys.argv[1] == "--self-test" else main(sys.argv[1]))
