#!/usr/bin/env bash
# Installs every Debian 12 package imucal needs to build and test. Idempotent: packages already
# present are left alone, and apt-get update runs only when something is missing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libmodbus-dev libboost1.81-dev libboost-url1.81-dev nlohmann-json3-dev libspdlog-dev libfmt-dev
  libsqlite3-dev sqlite3 libgtest-dev libgmock-dev libcli11-dev libbenchmark-dev libarchive-dev
)
# libsodium: the password hashes of imucald's users (Argon2id, daemon/config) and the lab's Ed25519
# signatures of certificates and test reports with their SHA-256 and base64 (signing/, docs/signing.md).
packages+=(libsodium-dev)
# The browser tests (tests/browser, ctest label `browser`): Debian's Chromium driven by Playwright,
# and Node.js with npm. nodejs and npm are added only when their commands are missing, so a Node.js
# installed another way (NodeSource's nodejs bundles npm and conflicts with Debian's npm) is kept.
# Debian 12's nodejs is v18: tests/browser pins playwright-core 1.61, the last for Node 18.
packages+=(chromium fonts-dejavu-core)
# The chamber driver's conformance tests (tests/drivers/test_drivers_pymodbus.cpp) run it against a
# Modbus TCP and RTU server imucal did not write: Debian's pymodbus (3.0), with python3-serial-asyncio
# for its RTU server (a Recommends of python3-pymodbus, which --no-install-recommends would skip).
packages+=(python3-pymodbus python3-serial-asyncio)
# The static check (scripts/static-check.sh): clang-tidy and clang-query of LLVM 16, Debian 12's
# newest (14, the default, lacks the checks of optional access the check is growing into), and
# clang-16's preprocessor for the keys of the check's cache.
packages+=(clang-tidy-16 clang-tools-16 clang-16)
# The soak tests (tests/daemon/test_daemon_chaos.cpp) take the stacks of an imucald whose run
# stopped moving, so a hang seen once in CI says where it waits.
packages+=(gdb)
# The registry on PostgreSQL (issue 38, storage/postgres.hpp): libpq to build against, and Debian's
# server (initdb, pg_ctl in /usr/lib/postgresql/15/bin) for the tests, which start a private server
# of their own in a temporary directory (tests/storage/postgres_server.hpp); the cluster Debian
# creates and starts with the package is not used.
packages+=(libpq-dev postgresql)
command -v node >/dev/null 2>&1 || packages+=(nodejs)
command -v npm >/dev/null 2>&1 || packages+=(npm)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}"
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -q
  "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all packages present"
fi
