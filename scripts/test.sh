#!/usr/bin/env bash
# Set up the test environments and run the tests:
# - the whole suite with the pinned (newest) numpy, then every test not marked slow once more with numpy 1.26.4, the
#   version ROS 2 Jazzy users have on Ubuntu 24.04 (the slow tests, long flights, campaigns and package builds, drive
#   the same modules as the others for longer, and run once); where a ROS 2 Jazzy is sourced, its ROS tests run
#   there against it;
# - the ROS-marked tests once more in .venv-ros-wheels, on the PyPI ROS 2 wheels (requirements-ros-wheels.txt),
#   which any machine can build: so the ROS half is tested without /opt/ros too. SKIP_ROS_WHEELS=1 leaves it out;
# - the tests of the plant rotorpy-batched (-m rotorpy_batched) once more in .venv-rotorpy-batched, which adds torch
#   (requirements-rotorpy-batched.txt) to the test requirements. SKIP_ROTORPY_BATCHED=1 leaves it out.
# - the PX4 SITL lane (-m px4, docs/PX4.md): flights on PX4 SITL's SIH quadrotor over uXRCE-DDS, where PX4 SITL
#   (PX4_DIR: the PX4-Autopilot folder with build/px4_sitl_default), the Micro XRCE-DDS Agent (MicroXRCEAgent on
#   PATH) and px4_msgs (importable by the lane's interpreter: PX4_PYTHON, default .venv-ros-wheels/bin/python, with
#   its colcon install sourced) are found; elsewhere it prints what is missing and skips, in a second. SKIP_PX4=1
#   leaves it out.
# The four environments are set up at the same time, and the first run starts as soon as .venv is ready (the tests
# needing the CPUs to themselves wait for every set-up to end); each run spreads its tests over one pytest-xdist
# worker per CPU (TEST_WORKERS=N sets another count; the tests sharing a module-scoped flight stay on one worker:
# conftest.py).
# --quick (first argument): the lane to run before every commit: .venv only, without the tests marked slow or ros.
# Each run says which ROS 2 it used. Extra arguments go to pytest; pytest's "no tests collected" (exit code 5,
# e.g. a file without ROS tests in the wheels run) is not a failure.
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0
if [ "${1:-}" = --quick ]; then quick=1; shift; fi
skip_wheels=${SKIP_ROS_WHEELS:-0}
skip_batched=${SKIP_ROTORPY_BATCHED:-0}
if [ $quick = 1 ]; then skip_wheels=1; skip_batched=1; fi
workers=${TEST_WORKERS:-$(nproc 2>/dev/null || echo 2)}
parallel=(-n "$workers" --dist loadgroup)

setups=()
bash scripts/setup_venv.sh .venv requirements-test.txt & venv_setup=$!
if [ $quick = 0 ]; then
  { bash scripts/setup_venv.sh .venv-numpy126 requirements-test.txt &&
    { [ "$(.venv-numpy126/bin/python -c 'import numpy; print(numpy.__version__)')" = 1.26.4 ] ||
      .venv-numpy126/bin/python -m pip install --quiet --disable-pip-version-check --no-compile numpy==1.26.4; }; } & setups+=($!)
fi
if [ "$skip_wheels" != 1 ]; then
  echo "== .venv-ros-wheels: installing the pinned PyPI ROS 2 wheels (requirements-ros-wheels.txt)"
  bash scripts/without_sourced_ros.sh bash scripts/setup_venv.sh .venv-ros-wheels requirements-ros-wheels.txt \
    --isolated & setups+=($!)
fi
if [ "$skip_batched" != 1 ]; then
  bash scripts/setup_venv.sh .venv-rotorpy-batched requirements-rotorpy-batched.txt & setups+=($!)
fi
wait "$venv_setup"
wait_for_setups() { for setup in "${setups[@]}"; do wait "$setup"; done; setups=(); }

status=0
run_pytest() {
  local code=0
  "$@" || code=$?
  if [ $code = 5 ]; then
    echo "(no tests selected here)"
  elif [ $code != 0 ]; then
    status=$code
  fi
}

# The marker expression of the extra arguments (-m EXPR), the others apart: each run adds its own to it.
user_marks=''; others=()
while [ $# -gt 0 ]; do
  case "$1" in
    -m) user_marks="($2)"; shift 2 ;;
    -m*) user_marks="(${1#-m})"; shift ;;
    *) others+=("$1"); shift ;;
  esac
done

run_suite() {   # run_suite MARKS PYTHON...: the tests of MARKS spread over the workers, then the exclusive ones alone
  local selected=$1; shift
  if [ -n "$user_marks" ]; then selected="${selected:+$selected and }$user_marks"; fi
  run_pytest "$@" -m pytest "${parallel[@]}" "${others[@]}" -m "${selected:+$selected and }not exclusive"
  wait_for_setups
  run_pytest "$@" -m pytest "${others[@]}" -m "${selected:+$selected and }exclusive"
}

if [ $quick = 1 ]; then
  echo "== .venv, quick lane (-m 'not slow and not ros'): numpy $(.venv/bin/python -c 'import numpy; print(numpy.__version__)')"
  run_pytest .venv/bin/python -m pytest "${parallel[@]}" "${others[@]}" -m "${user_marks:+$user_marks and }not slow and not ros"
  exit $status
fi
echo "== .venv, every test: numpy $(.venv/bin/python -c 'import numpy; print(numpy.__version__)'); $(.venv/bin/python tests/ros_support.py)"
run_suite '' .venv/bin/python
echo "== .venv-numpy126, the tests not marked slow (-m 'not slow'): numpy $(.venv-numpy126/bin/python -c 'import numpy; print(numpy.__version__)'); $(.venv-numpy126/bin/python tests/ros_support.py)"
run_suite 'not slow' .venv-numpy126/bin/python
if [ "$skip_wheels" != 1 ]; then
  echo "== .venv-ros-wheels, ROS tests only (-m ros): $(bash scripts/without_sourced_ros.sh .venv-ros-wheels/bin/python tests/ros_support.py)"
  run_suite ros bash scripts/without_sourced_ros.sh .venv-ros-wheels/bin/python
fi
if [ "${SKIP_PX4:-0}" != 1 ]; then
  px4_python=${PX4_PYTHON:-.venv-ros-wheels/bin/python}
  px4_missing=''
  if [ ! -x "$px4_python" ]; then
    px4_missing="no interpreter $px4_python (set PX4_PYTHON, or let this script build .venv-ros-wheels)"
  else
    px4_missing=$("$px4_python" - <<'PY' 2>&1 || true
import sys
sys.path[:0] = ['.', 'ros2_ws/src/quad_msgs_bridge', 'ros2_ws/src/quad_sim', 'ros2_ws/src/nnit2fsmc_controller']
from flight_stack.px4_sitl import find_px4
from quad_msgs_bridge.validation import ParameterError
try:
    import rclpy  # noqa: F401
    find_px4()
except (ImportError, ParameterError) as error:
    print(error)
PY
)
  fi
  if [ -n "$px4_missing" ]; then
    echo "== PX4 SITL lane skipped: $px4_missing"
  else
    echo "== PX4 SITL lane (-m px4): PX4_DIR=$PX4_DIR, $(command -v MicroXRCEAgent || true), $px4_python"
    run_pytest "$px4_python" -m pytest "${others[@]}" -m "${user_marks:+$user_marks and }px4"
  fi
fi
if [ "$skip_batched" != 1 ]; then
  echo "== .venv-rotorpy-batched, the plant rotorpy-batched's tests (-m rotorpy_batched): torch $(.venv-rotorpy-batched/bin/python -c 'import torch; print(torch.__version__)')"
  run_suite rotorpy_batched .venv-rotorpy-batched/bin/python
fi
exit $status
