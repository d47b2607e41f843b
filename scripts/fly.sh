#!/usr/bin/env bash
# The main job: set up .venv, fly the paper's scenario with the NNIT2FSMC on the embedded backend,
# write the summary, the MCAP bag and the review report (plots) under out/paper-nnit2fsmc/.
# Extra arguments go to run_stack.py (e.g. --controller smc-sign --out out/sign).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh .venv requirements.txt
case "${1:-}" in
  campaign|review|recover|rosbag2-qos) exec .venv/bin/python run_stack.py "$@" ;;   # subcommands
  *) exec .venv/bin/python run_stack.py --backend embedded "$@" ;;
esac
