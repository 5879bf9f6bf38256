#!/usr/bin/env bash
# The static check of CI (called by scripts/test.sh): clang-tidy 16 with the checks of .clang-tidy
# (dangling handles, use after move, unchecked optional access, the compiler's lifetime warnings)
# and clang-query 16 with scripts/static/lifetimes.query (ranges and references into a temporary),
# over every C++ source of the project, tests included. Zero findings, or it fails and lists them.
# A file clang-tidy or clang-query could not finish (a crash: clang-tidy 16's optional-access
# analysis dies on some structured bindings, .clang-tidy says which) is a finding too: its other
# checks did not run either. Each file's seconds go to $out/times.txt; the slowest are printed.
# The matches are first run on scripts/static/dangling_examples.cpp, whose lines marked BAD they
# must all find and whose lines marked ok none, so that a query that stopped matching fails here.
# A file whose check found nothing is remembered (a cache, as ccache is for the compiler): keyed
# by the tools' versions, the checks' configuration and the file's whole preprocessed translation
# unit (clang-16 -E, every header included, the checkout's path taken out), so a file is checked
# again whenever anything it sees changes; a file with findings is always checked again. The cache
# is $IMUCAL_STATIC_CACHE (default ~/.cache/imucal-static-check); IMUCAL_STATIC_CACHE=off checks all.
# Usage: scripts/static-check.sh [--optional] [FILE...]   (default: every source in the compile
# database). --optional: clang-tidy's bugprone-unchecked-optional-access alone, each file limited
# to 120 s (a quick look while mending its findings or a slow function; CI's mode runs it too,
# with the other checks and without a limit).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc)
out=build/static-check
mkdir -p "$out"
tidy_args=(--quiet)
query=scripts/static/lifetimes.query
timeout_s=""
if [ "${1:-}" = "--optional" ]; then
  shift
  tidy_args=(--quiet "--checks=-*,bugprone-unchecked-optional-access")
  query=""
  timeout_s=120
  out=build/static-check-optional
  mkdir -p "$out"
fi
export STATIC_TIDY_ARGS="${tidy_args[*]}" STATIC_QUERY="$query" STATIC_TIMEOUT_S="$timeout_s"
export STATIC_TIMEOUT="${timeout_s:+timeout $timeout_s}"
export STATIC_CPU_LIMIT_S=${IMUCAL_STATIC_CPU_LIMIT_S:-600}  # CPU seconds per clang-tidy run

# A compile database of single sources (not the unity files the presets build): configure only.
cmake -S . -B build/tidy -G Ninja -DCMAKE_BUILD_TYPE=Release -DIMUCAL_UNITY=OFF \
      -DCMAKE_EXPORT_COMPILE_COMMANDS=ON >"$out/configure.log"

# The check of the checker.
examples=scripts/static/dangling_examples.cpp
[ -z "$query" ] || clang-query-16 -f "$query" "$examples" -- -std=c++20 2>/dev/null |
  sed -n "s|^.*/$examples:\([0-9]*\):[0-9]*: note: \"dangling.*|\1|p" | sort -n | uniq >"$out/examples.found"
grep -n '// BAD' "$examples" | grep -v 'clang Wdangling' | cut -d: -f1 >"$out/examples.expected"
if [ -n "$query" ] && ! diff -u "$out/examples.expected" "$out/examples.found"; then
  echo "static-check: $query no longer finds exactly the BAD lines of $examples (diff above: lines expected, found)"
  exit 1
fi

# Each source with the command that preprocesses it as clang-tidy sees it (the cache's key):
# "file<TAB>command" lines, the compile database's command run by clang-16 with -E.
python3 - "$@" >"$out/sources" <<'PY'
import json, os, shlex, sys
root = os.getcwd()
wanted = {os.path.normpath(f) for f in sys.argv[1:]}
for e in json.load(open("build/tidy/compile_commands.json")):
    f = os.path.relpath(e["file"], root)
    if f.startswith(("build/", "..")) or (wanted and f not in wanted):
        continue
    args = shlex.split(e["command"])
    pp = ["clang++-16"]
    skip = False
    for a in args[1:]:
        if skip:
            skip = False
        elif a == "-o":
            skip = True
        elif a != "-c":
            pp.append(a)
    pp[-1:-1] = ["-E", "-Wno-everything"]
    print(f + "\t" + "cd " + shlex.quote(e["directory"]) + " && " + shlex.join(pp))
PY
# Once per file: a source compiled twice (tests/storage/test_recorder_crash.cpp, with two sets of
# defines) is checked by its first command, and two parallel checks of it raced on its log files.
cut -f1 "$out/sources" | awk '!seen[$0]++' >"$out/files"
if (($#)) && [ "$(wc -l <"$out/files")" -ne $# ]; then
  echo "static-check: not every file named is a source of the compile database (build/tidy):"
  printf '%s\n' "$@" | sort | comm -23 - <(sort "$out/files")
  exit 1
fi

# What every file's key starts with: the tools, the checks and their configuration.
cache=${IMUCAL_STATIC_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/imucal-static-check}
if [ "$cache" != off ]; then
  mkdir -p "$cache"
  { clang-tidy-16 --version; clang-query-16 --version; clang++-16 --version
    echo "$STATIC_TIDY_ARGS|$STATIC_QUERY|$STATIC_TIMEOUT_S"
    cat .clang-tidy tests/.clang-tidy scripts/static/*; } | sha256sum | cut -c1-64 >"$out/config.key"
fi
export STATIC_CACHE="$cache" STATIC_CONFIG_KEY="$(cat "$out/config.key" 2>/dev/null || true)" STATIC_ROOT="$PWD"
echo "static-check: $(wc -l <"$out/files") sources, clang-tidy and clang-query on $jobs cores"

# Both tools on every file; each file's findings to a log of its own (parallel runs interleave).
rm -rf "$out/logs" "$out/times.txt" "$out/cached.txt" && mkdir -p "$out/logs" && touch "$out/times.txt"
started=$EPOCHREALTIME
check_one() {
  local f=$1 log=$2/logs/$(echo "$1" | tr / _) rc=0 start=$EPOCHREALTIME key=""
  if [ "$STATIC_CACHE" != off ]; then
    # The translation unit as clang sees it, with the checkout's path taken out (a clean clone
    # elsewhere has the same key); a file that does not preprocess is checked (and fails there).
    if bash -c "$(awk -F'\t' -v f="$f" '$1 == f { print $2; exit }' "$2/sources")" >"$log.i" 2>/dev/null; then
      key=$( { echo "$STATIC_CONFIG_KEY $f"; sed "s|$STATIC_ROOT/||g" "$log.i"; } | sha256sum | cut -c1-64)
    fi
    rm -f "$log.i"
    if [ -n "$key" ] && [ -e "$STATIC_CACHE/$key" ]; then
      : >"$log.tidy"
      echo "$f" >>"$2/cached.txt"
      return 0
    fi
  fi
  # --optional limits each file (its analysis can run for many minutes); the check of CI does not:
  # a limit on wall time fails on a loaded machine (program.cpp took over 120 s beside the
  # sanitizer build at nice 19), and its checks end on their own.
  # CI's mode limits the CPU time instead, which a loaded machine does not stretch: clang 16's
  # optional analysis sometimes runs away on a file that takes seconds the next time (cli/main.cpp:
  # 18 min of CPU once on 2026-11-27, 9 s when run again), so a file that reaches the limit is
  # checked a second time, and only a second run away is a finding.
  local attempt
  for attempt in 1 2; do
    rc=0
    # shellcheck disable=SC2086  # the arguments are words
    (ulimit -S -t "$STATIC_CPU_LIMIT_S"; exec $STATIC_TIMEOUT clang-tidy-16 -p build/tidy $STATIC_TIDY_ARGS "$f") >"$log.tidy" 2>&1 || rc=$?
    [ $rc -eq 152 ] || break  # 128 + SIGXCPU: the CPU limit
  done
  # Exit 1 with findings is a finished run; a timeout (124), a signal (>= 128: a crash) or
  # another failure without a finding to show for it means the file was not checked.
  if [ $rc -eq 152 ]; then
    echo "$f:1:1: error: clang-tidy used over $STATIC_CPU_LIMIT_S s of CPU on this file twice (not checked): split the function the optional analysis cannot finish (.clang-tidy)" >>"$log.tidy"
  elif [ $rc -eq 124 ] && [ -n "$STATIC_TIMEOUT_S" ]; then
    echo "$f:1:1: error: clang-tidy took over $STATIC_TIMEOUT_S s on this file (not checked)" >>"$log.tidy"
  elif [ $rc -ge 128 ] || { [ $rc -ne 0 ] && ! grep -qE '^[^ ].*:[0-9]+:[0-9]+: (warning|error):' "$log.tidy"; }; then
    echo "$f:1:1: error: clang-tidy failed on this file (exit $rc: $(grep -m1 -A1 'Processing' "$log.tidy" | tail -n 1 | sed 's/^[[:space:]]*//')) (not checked)" >>"$log.tidy"
  fi
  local mid=$EPOCHREALTIME
  if [ -n "$STATIC_QUERY" ]; then
    rc=0
    clang-query-16 -p build/tidy -f "$STATIC_QUERY" "$f" >"$log.query" 2>&1 || rc=$?
    [ $rc -lt 128 ] || echo "$f:1:1: note: \"dangling: clang-query failed on this file (exit $rc; not checked)\"" >>"$log.query"
  fi
  local end=$EPOCHREALTIME
  # Wall seconds: clang-tidy, clang-query (one line per file; parallel runs append whole lines).
  awk -v a="$start" -v b="$mid" -v c="$end" -v f="$f" 'BEGIN { printf "%.1f %.1f %s\n", b - a, c - b, f }' >>"$2/times.txt"
  # Remembered only when both tools finished and found nothing.
  # (The same two patterns as the findings below.)
  if [ -n "$key" ] && ! grep -qE '^[^ ].*:[0-9]+:[0-9]+: (warning|error):' "$log.tidy" &&
     ! { grep -sE '^[^ ].*:[0-9]+:[0-9]+: note: "dangling' "$log.query" | grep -qv '^/usr/'; }; then
    touch "$STATIC_CACHE/$key"
  fi
}
export -f check_one
xargs -P "$jobs" -I{} bash -c 'check_one "$1" "$2"' _ {} "$out" <"$out/files"

# A finding is a clang-tidy warning or error, or a clang-query match in the project's own files
# (clang-tidy's HeaderFilterRegex does that for it); a header's finding is reported by each source
# that includes it, so each is listed once.
cat "$out"/logs/*.tidy | grep -E '^[^ ].*:[0-9]+:[0-9]+: (warning|error):' | sort -u >"$out/findings.txt" || true
cat "$out"/logs/*.query 2>/dev/null | grep -E '^[^ ].*:[0-9]+:[0-9]+: note: "dangling' | grep -v '^/usr/' | sort -u >>"$out/findings.txt" || true
n=$(wc -l <"$out/findings.txt")
wall=$(awk -v a="$started" -v b="$EPOCHREALTIME" 'BEGIN { print b - a }')
echo "static-check: the slowest files (wall seconds of clang-tidy, clang-query; all in $out/times.txt):"
sort -rn "$out/times.txt" | head -n 5 | sed 's/^/  /'
if ((n)); then
  cat "$out/findings.txt"
  echo "static-check: $n finding(s) (each file's full output: $out/logs/)"
  exit 1
fi
printf 'static-check: no findings (%d sources, %d of them unchanged since a clean check, in %.0f s)\n' \
  "$(wc -l <"$out/files")" "$(cat "$out/cached.txt" 2>/dev/null | wc -l)" "$wall"
