#!/usr/bin/env bash
# The main job: set up .venv, fly the paper's scenario with the NNIT2FSMC on the embedded backend,
# write the summary, the MCAP bag and the review report (plots) under out/paper-nnit2fsmc/.
# Extra arguments go to run_stack.py (e.g. --controller smc-sign --out out/sign); a first argument that is
# not an option is one of run_stack.py's subcommands (campaign, tune, stress, review, export, ...: the flight
# itself takes options only), passed on as it is, so every subcommand run_stack.py has works here too.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh .venv requirements.txt
case "${1:-}" in
  ""|-*) exec .venv/bin/python run_stack.py --backend embedded "$@" ;;   # a flight, on the embedded backend
  *) exec .venv/bin/python run_stack.py "$@" ;;                          # a subcommand
esac
