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
                  quad_msgs_bridge/review quad_msgs_bridge/record quad_msgs_bridge/recover quad_msgs_bridge/merge \
                  quad_msgs_bridge/rosbag2_qos; do
  package=${executable%%/*}
  if [ -x "install/$package/lib/$executable" ]; then
    echo "installed: install/$package/lib/$executable"
  else
    echo "MISSING: install/$package/lib/$executable (ros2 run $package ${executable##*/} would fail)" >&2
    status=1
  fi
done
[ $status = 0 ] || exit $status

# The installed executables run with every import they need: the bag tools without ROS; with ROS, each node
# through `ros2 run` with its installed params file, refusing an invalid value (exit 2, naming it).
set +u; source install/setup.bash; set -u
for tool in review recover merge rosbag2_qos; do
  install/quad_msgs_bridge/lib/quad_msgs_bridge/$tool --help >/dev/null
  echo "runs: $tool --help"
done
if ! "${colcon[0]}" -c 'import rclpy' 2>/dev/null; then
  echo "skipped: ros2 run of the nodes (rclpy cannot be imported: source /opt/ros/jazzy/setup.bash first)"
  exit 0
fi
check_refuses() {   # package executable params-file-or-none bad-parameter
  local output code=0 params=()
  [ "$3" = none ] || params=(--params-file "install/$1/share/$1/config/$3")
  output=$(ros2 run "$1" "$2" --ros-args "${params[@]}" -p "$4" 2>&1) || code=$?
  if [ $code = 2 ] && grep -q "parameter ${4%%:=*}" <<<"$output"; then
    echo "runs: ros2 run $1 $2 (refused $4)"
  else
    echo "FAILED: ros2 run $1 $2 ${params[*]} -p $4 exited $code:" >&2
    echo "$output" >&2
    status=1
  fi
}
check_refuses quad_sim quad_sim quad_sim.yaml mode:=warp
check_refuses nnit2fsmc_controller nnit2fsmc_controller controller.yaml controller:=lqr
check_refuses nnit2fsmc_controller trajectory trajectory.yaml scenario:=loop
check_refuses quad_msgs_bridge record none settle_time:=-1.0
exit $status
