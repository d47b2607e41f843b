#!/usr/bin/env bash
# Build the ROS 2 workspace with colcon from .venv, run colcon test, fail on any test failure,
# and check that every executable is installed where `ros2 run` looks for it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh .venv requirements-test.txt
colcon=("$PWD/.venv/bin/python" -m colcon)
cd ros2_ws
rm -rf build install log
"${colcon[@]}" build --event-handlers console_cohesion- summary+
"${colcon[@]}" test --event-handlers console_cohesion- summary+
"${colcon[@]}" test-result --verbose
status=0
for executable in quad_sim/quad_sim nnit2fsmc_controller/nnit2fsmc_controller nnit2fsmc_controller/trajectory \
                  quad_msgs_bridge/review quad_msgs_bridge/record; do
  package=${executable%%/*}
  if [ -x "install/$package/lib/$executable" ]; then
    echo "installed: install/$package/lib/$executable"
  else
    echo "MISSING: install/$package/lib/$executable (ros2 run $package ${executable##*/} would fail)" >&2
    status=1
  fi
done
exit $status
