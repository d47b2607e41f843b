#!/usr/bin/env bash
# Set up the test environments and run the whole suite twice: with the pinned (newest) numpy and
# with numpy 1.26.4, the version ROS 2 Jazzy users have on Ubuntu 24.04.
# Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh .venv requirements-test.txt
bash scripts/setup_venv.sh .venv-numpy126 requirements-test.txt
.venv-numpy126/bin/python -m pip install --quiet --disable-pip-version-check numpy==1.26.4
status=0
for venv in .venv .venv-numpy126; do
  echo "== $venv: numpy $("$venv/bin/python" -c 'import numpy; print(numpy.__version__)')"
  "$venv/bin/python" -m pytest "$@" || status=$?
done
exit $status
