#!/usr/bin/env bash
# Fresh-machine setup, idempotent: creates .venv (python3.11) in the repo root, installs the
# project (with its test and cluster extras: the tests run a local Ray cluster) + pinned ROS 2
# Jazzy wheels (requirements-ros.txt), and builds the interface package
# msgs_spec/ (clnn_ros_msgs) into the venv with cmake. No ROS install or sourced ROS env needed;
# nothing is exported outside this script. A second run only checks two stamp files.
#   env: PYTHON (interpreter for a new venv, default python3.11)
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV="$ROOT/.venv"
PY_NEW=${PYTHON:-python3.11}
LOGS="$VENV/setup-logs"
PIP_STAMP="$VENV/.setup-pip.sha256"
MSGS_STAMP="$VENV/.setup-msgs.sha256"
MSGS_SRC="$ROOT/msgs_spec"
MSGS_BUILD="$VENV/build-msgs/clnn_ros_msgs"

# A sourced ROS env (or another venv's bootstrapped python) must not leak into the build.
unset AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH PYTHONPATH \
      _ROS_WHEELS_BOOTSTRAP_COMPLETE VIRTUAL_ENV PYTHONHOME || true
export PIP_DISABLE_PIP_VERSION_CHECK=1
# Keep DDS discovery on loopback unless the user chose otherwise (nothing here should talk DDS).
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}

T_ALL=$EPOCHREALTIME
t0=0
since() { # seconds since an $EPOCHREALTIME value, one decimal
  local d=$(( (${EPOCHREALTIME//[.,]/} - ${1//[.,]/}) / 100000 ))
  printf '%d.%d' $((d / 10)) $((d % 10))
}
phase() { t0=$EPOCHREALTIME; printf 'setup: %-34s' "$1"; }
done_() { printf '%s (%s s)\n' "${1:-done}" "$(since "$t0")"; }
fail() { # fail LOG MESSAGE
  printf 'FAILED\nsetup: %s; last lines of %s:\n' "$2" "$1" >&2
  grep -v 'is ignored: it is neither a file nor a directory' "$1" | tail -n 60 >&2 || true
  exit 1
}
hash_files() { # sha256 over the names and contents of the given files
  local f
  for f in "$@"; do printf '%s\n' "${f#"$ROOT"/}"; cat "$f"; done | sha256sum | cut -d' ' -f1
}

# --- 1. venv -------------------------------------------------------------------------------
# One setup at a time (e.g. two test runs started together): lock this script's own file.
if command -v flock >/dev/null; then exec 9<"${BASH_SOURCE[0]}"; flock 9; fi

phase "venv ($VENV)"
if [ -x "$VENV/bin/python" ]; then
  "$VENV/bin/python" -S -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' \
    || { printf 'FAILED\nsetup: %s is not Python 3.11; remove %s and rerun\n' "$VENV/bin/python" "$VENV" >&2; exit 1; }
  done_ "exists"
else
  command -v "$PY_NEW" >/dev/null || { echo "FAILED: $PY_NEW not found (set PYTHON=...)" >&2; exit 1; }
  "$PY_NEW" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
    || { echo "FAILED: $PY_NEW is not Python 3.11 (the ROS Jazzy wheels are cp311)" >&2; exit 1; }
  mkdir -p "$(dirname "$VENV")"
  "$PY_NEW" -m venv "$VENV" 2>/tmp/clnn_setup_venv.$$.log || fail /tmp/clnn_setup_venv.$$.log "python -m venv failed"
  rm -f /tmp/clnn_setup_venv.$$.log
  done_ "created"
fi
mkdir -p "$LOGS"

# --- 2. pip: project + pinned ROS wheels -----------------------------------------------------
phase "pip install"
EXTRAS="test,cluster"  # cluster: Ray, for clnn-reproduce --ray and tests/test_cluster.py
pip_hash="$(hash_files "$ROOT/pyproject.toml" "$ROOT/requirements-ros.txt") extras=$EXTRAS"
if [ -f "$PIP_STAMP" ] && [ "$(cat "$PIP_STAMP")" = "$pip_hash" ]; then
  done_ "up to date"
else
  rm -f "$PIP_STAMP"
  ( cd "$ROOT" && "$VENV/bin/python" -m pip install -e ".[$EXTRAS]" -r requirements-ros.txt ) \
    > "$LOGS/pip.log" 2>&1 || fail "$LOGS/pip.log" "pip install failed"
  echo "$pip_hash" > "$PIP_STAMP"
  done_
fi

# --- 3. re-point the wheels' exported CMake files at this venv's Python/numpy headers -------
# (they name the wheel-build machine's /opt/python/cp311-cp311/... include dirs)
phase "fix cmake include paths"
mapfile -d '' stale < <(grep -rlZ "/opt/python/cp311-cp311" "$VENV/share" --include='*.cmake' 2>/dev/null || true)
if [ "${#stale[@]}" -eq 0 ]; then
  done_ "nothing to fix"
else
  read -r PYINC NPINC < <("$VENV/bin/python" -c \
    "import sysconfig, numpy; print(sysconfig.get_paths()['include'], numpy.get_include())")
  sed -i -e "s#/opt/python/cp311-cp311/include/python3\.11#$PYINC#g" \
         -e "s#/opt/python/cp311-cp311/lib/python3\.11/site-packages/numpy/_core/include#$NPINC#g" \
         "${stale[@]}"
  if left=$(grep -rl "/opt/python/cp311-cp311" "$VENV/share" --include='*.cmake'); then
    printf 'FAILED\nsetup: unexpected /opt/python paths left in:\n%s\n' "$left" >&2
    grep -rh "/opt/python/cp311-cp311" "$VENV/share" --include='*.cmake' | head -5 >&2
    exit 1
  fi
  done_ "${#stale[@]} files"
fi

# --- 4. build + install msgs_spec/ (clnn_ros_msgs) into the venv -----------------------------
phase "build clnn_ros_msgs"
mapfile -t msg_files < <(find "$MSGS_SRC" -type f | LC_ALL=C sort)
# (the ROS wheel pins are part of it: a build against other rosidl versions is redone)
msgs_hash=$(hash_files "$ROOT/requirements-ros.txt" "${msg_files[@]}")
SITE="$VENV/lib/python3.11/site-packages"
if [ -f "$MSGS_STAMP" ] && [ "$(cat "$MSGS_STAMP")" = "$msgs_hash" ] \
   && [ -f "$SITE/clnn_ros_msgs/msg/__init__.py" ]; then
  done_ "up to date"
else
  rm -f "$MSGS_STAMP"
  CMAKE=$(command -v cmake || true)
  if [ -z "$CMAKE" ]; then
    "$VENV/bin/python" -m pip install "cmake>=3.22,<4" > "$LOGS/cmake-pip.log" 2>&1 \
      || fail "$LOGS/cmake-pip.log" "no cmake on PATH and pip install cmake failed"
    CMAKE="$VENV/bin/cmake"
  fi
  rm -rf "$MSGS_BUILD"
  "$CMAKE" -S "$MSGS_SRC" -B "$MSGS_BUILD" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
      -DCMAKE_PREFIX_PATH="$VENV" -DCMAKE_INSTALL_PREFIX="$VENV" \
      -DPython3_EXECUTABLE="$VENV/bin/python" > "$LOGS/msgs-configure.log" 2>&1 \
    || fail "$LOGS/msgs-configure.log" "cmake configure of msgs_spec failed"
  "$CMAKE" --build "$MSGS_BUILD" -j"$(nproc)" > "$LOGS/msgs-build.log" 2>&1 \
    || fail "$LOGS/msgs-build.log" "cmake build of msgs_spec failed"
  "$CMAKE" --install "$MSGS_BUILD" > "$LOGS/msgs-install.log" 2>&1 \
    || fail "$LOGS/msgs-install.log" "cmake install of msgs_spec failed"
  [ -f "$SITE/clnn_ros_msgs/msg/__init__.py" ] \
    || fail "$LOGS/msgs-install.log" "clnn_ros_msgs was not installed into $SITE"
  echo "$msgs_hash" > "$MSGS_STAMP"
  done_
fi

printf 'setup: ready in %s s (python: %s)\n' "$(since "$T_ALL")" "$VENV/bin/python"
