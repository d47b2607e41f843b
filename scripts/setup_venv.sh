#!/usr/bin/env bash
# Create (or reuse) a virtual environment and install pinned requirements into it.
# Usage: scripts/setup_venv.sh VENV_DIR REQUIREMENTS_FILE [--isolated]
# The venv sees the system site packages (--system-site-packages keeps a sourced ROS 2's rclpy importable)
# unless --isolated is given (the ROS 2 wheels venv, which must not mix with an installed ROS 2).
# Works on a fresh Debian/Ubuntu machine with only Python 3.11+; installs python3-venv with apt
# when the interpreter cannot create venvs and we may use apt (root or passwordless sudo).
set -euo pipefail
venv=$1; requirements=$2
case "${3:-}" in
  "") venv_options=(--system-site-packages) ;;
  --isolated) venv_options=() ;;
  *) echo "error: unknown option '$3' (only --isolated)" >&2; exit 2 ;;
esac
python=${PYTHON:-python3}
"$python" - <<'PY' || { echo "error: Python 3.11 or newer is needed (found $("$python" --version 2>&1))" >&2; exit 1; }
import sys
sys.exit(0 if sys.version_info >= (3, 11) else 1)
PY
if [ ! -x "$venv/bin/python" ]; then
  if ! "$python" -m venv "${venv_options[@]}" "$venv" 2>/dev/null; then
    rm -rf "$venv"
    version=$("$python" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
    if command -v apt-get >/dev/null && { [ "$(id -u)" = 0 ] || sudo -n true 2>/dev/null; }; then
      sudo_cmd=$([ "$(id -u)" = 0 ] && echo "" || echo "sudo -n")
      $sudo_cmd apt-get update -qq && $sudo_cmd apt-get install -y -qq "python$version-venv" || $sudo_cmd apt-get install -y -qq python3-venv
      "$python" -m venv "${venv_options[@]}" "$venv"
    else
      echo "error: '$python -m venv' does not work here; install the venv module (sudo apt install python3-venv)" >&2
      exit 1
    fi
  fi
  touch "$venv/COLCON_IGNORE"   # colcon must not crawl the venv
fi
# pip runs once per content of the requirements files (this one and those it includes with -r, all
# requirements*.txt beside it): a stamp in the venv holds their hash, so a later call only compares it.
stamp="$venv/.installed-$(basename "$requirements").sha256"
hash=$(cat "$(dirname "$requirements")"/requirements*.txt "$requirements" | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$hash" ]; then
  # --no-compile: Python compiles what is imported when it is first imported; byte-compiling every installed file
  # (torch's thousands) cost more CPU than the set-up's downloads and unpacking together
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-compile -r "$requirements"
  echo "$hash" > "$stamp"
fi
