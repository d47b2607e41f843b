#!/usr/bin/env bash
# Set up the test environments and run the tests:
# - the whole suite twice: with the pinned (newest) numpy and with numpy 1.26.4, the version ROS 2 Jazzy users
#   have on Ubuntu 24.04; where a ROS 2 Jazzy is sourced, its ROS tests run there against it;
# - the ROS-marked tests once more in .venv-ros-wheels, on the PyPI ROS 2 wheels (requirements-ros-wheels.txt),
#   which any machine can build: so the ROS half is tested without /opt/ros too. SKIP_ROS_WHEELS=1 leaves it out.
# Each run says which ROS 2 it used. Extra arguments go to pytest; pytest's "no tests collected" (exit code 5,
# e.g. a file without ROS tests in the wheels run) is not a failure.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh .venv requirements-test.txt
bash scripts/setup_venv.sh .venv-numpy126 requirements-test.txt
.venv-numpy126/bin/python -m pip install --quiet --disable-pip-version-check numpy==1.26.4
skip_wheels=${SKIP_ROS_WHEELS:-0}
if [ "$skip_wheels" != 1 ]; then
  echo "== .venv-ros-wheels: installing the pinned PyPI ROS 2 wheels (requirements-ros-wheels.txt)"
  bash scripts/without_sourced_ros.sh bash scripts/setup_venv.sh .venv-ros-wheels requirements-ros-wheels.txt --isolated
fi

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

for venv in .venv .venv-numpy126; do
  echo "== $venv: numpy $("$venv/bin/python" -c 'import numpy; print(numpy.__version__)'); $("$venv/bin/python" tests/ros_support.py)"
  run_pytest "$venv/bin/python" -m pytest "$@"
done
if [ "$skip_wheels" != 1 ]; then
  echo "== .venv-ros-wheels, ROS tests only (-m ros): $(bash scripts/without_sourced_ros.sh .venv-ros-wheels/bin/python tests/ros_support.py)"
  run_pytest bash scripts/without_sourced_ros.sh .venv-ros-wheels/bin/python -m pytest "$@" -m ros
fi
exit $status
