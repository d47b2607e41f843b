#!/usr/bin/env bash
# Run a command with any sourced ROS 2 taken out of the environment: what the ROS 2 wheels venv
# (.venv-ros-wheels) needs, as a sourced Jazzy's PYTHONPATH (Python 3.12 modules), LD_LIBRARY_PATH (its
# librcl, Fast DDS, ...) and RMW_IMPLEMENTATION would otherwise win over the wheels' own.
# Usage: scripts/without_sourced_ros.sh COMMAND [ARGS...]
# PATH, PYTHONPATH and LD_LIBRARY_PATH lose their entries inside the sourced installations (AMENT_PREFIX_PATH,
# COLCON_PREFIX_PATH) and keep the others; the ROS 2 variables go. Kept: ROS_DOMAIN_ID,
# ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_LOCALHOST_ONLY (they choose the DDS graph, not the ROS).
# A ROS 2 wheels venv's bootstrapper sets LD_LIBRARY_PATH to its own ros_*.libs and lib/ (a node of one wheels venv
# starting one of another, e.g. Jazzy-series and Kilted-series wheels): that venv counts as a sourced installation.
set -euo pipefail
IFS=: read -ra roots <<< "${AMENT_PREFIX_PATH:-}:${COLCON_PREFIX_PATH:-}"
IFS=: read -ra library_entries <<< "${LD_LIBRARY_PATH:-}"
for entry in "${library_entries[@]}"; do
  if [[ "$entry" == */lib/python3*/site-packages/ros_*.libs ]]; then roots+=("${entry%%/lib/python3*}"); fi
done

outside_ros() {   # the entries of the path list $1 that are not inside a sourced installation
  local entry root kept=()
  IFS=: read -ra entries <<< "$1"
  for entry in "${entries[@]}"; do
    for root in "${roots[@]}"; do
      if [ -n "$root" ] && [[ "$entry" == "$root" || "$entry" == "$root"/* ]]; then continue 2; fi
    done
    kept+=("$entry")
  done
  (IFS=:; echo "${kept[*]}")
}

PATH=$(outside_ros "${PATH:-}")
python_path=$(outside_ros "${PYTHONPATH:-}")
library_path=$(outside_ros "${LD_LIBRARY_PATH:-}")
unset PYTHONPATH LD_LIBRARY_PATH AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH PKG_CONFIG_PATH \
  ROS_DISTRO ROS_VERSION ROS_PYTHON_VERSION RMW_IMPLEMENTATION _ROS_WHEELS_BOOTSTRAP_COMPLETE
if [ -n "$python_path" ]; then export PYTHONPATH=$python_path; fi
if [ -n "$library_path" ]; then export LD_LIBRARY_PATH=$library_path; fi
exec "$@"
