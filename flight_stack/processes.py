"""Child processes of the ROS backend: started like ``ros2 launch`` would, stopped cleanly.

Each node runs in its own process; its output lines are forwarded with a ``[name]`` prefix.
Stopping sends SIGINT, then SIGTERM, then SIGKILL, each after a grace period.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Sequence

from . import PACKAGE_DIRS


def node_command(package: str, executable: str, module: str) -> list[str]:
    """How to start a node: its installed executable (as ``ros2 run`` would find it) if the package
    is installed in a sourced workspace, else its module from this source tree."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_prefix
        try:
            installed = Path(get_package_prefix(package)) / 'lib' / package / executable
        except (PackageNotFoundError, OSError):   # OSError: no AMENT_PREFIX_PATH (as with the PyPI ROS 2 wheels)
            installed = None
    except ImportError:
        installed = None
    if installed is not None and installed.exists():
        return [str(installed)]
    return [sys.executable, '-m', module]


def source_tree_environment() -> dict[str, str]:
    """Environment in which ``python -m <node module>`` imports the packages of this source tree."""
    env = dict(os.environ)
    paths = [str(p) for p in PACKAGE_DIRS] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p]
    env['PYTHONPATH'] = os.pathsep.join(paths)
    env.setdefault('PYTHONUNBUFFERED', '1')
    return env


class NodeProcess:
    """One node in its own process, its output forwarded line by line with a prefix."""

    def __init__(self, name: str, command: Sequence[str], env: dict[str, str], quiet: bool = False):
        self.name = name
        self.command = list(command)
        self.process = subprocess.Popen(self.command, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, bufsize=1, start_new_session=True)
        self.lines: list[str] = []
        self._quiet = quiet
        self._reader = threading.Thread(target=self._forward, daemon=True)
        self._reader.start()

    def _forward(self) -> None:
        for line in self.process.stdout:
            line = line.rstrip('\n')
            self.lines.append(line)
            if not self._quiet or 'ERROR' in line or 'FATAL' in line or 'WARN' in line:
                print(f'[{self.name}] {line}', flush=True)

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def stop(self, grace: float = 5.0) -> int:
        """SIGINT, then SIGTERM and SIGKILL if it does not exit within ``grace`` seconds each."""
        return stop_all([self], grace)[self.name]


def stop_all(processes: Sequence[NodeProcess], grace: float = 5.0) -> dict[str, int]:
    """Stop processes together: SIGINT to all, then SIGTERM and SIGKILL to those still running ``grace``
    seconds after each; {name: exit code}. (One by one, the last nodes of a fleet waited seconds without
    odometry and warned about it.)"""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        running = [proc for proc in processes if proc.process.poll() is None]
        for proc in running:
            try:
                proc.process.send_signal(sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + grace
        for proc in running:
            try:
                proc.process.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                print(f'[{proc.name}] did not stop after {sig.name}', flush=True)
    codes = {proc.name: proc.process.wait() for proc in processes}
    for proc in processes:
        proc._reader.join(timeout=2.0)
    return codes


def wait_for_exit(processes: Sequence[NodeProcess], until: NodeProcess, timeout: float,
                  poll: float = 0.05) -> NodeProcess | None:
    """Wait until ``until`` exits; return the first other process that exits before it (a failure)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for proc in processes:
            if proc is not until and proc.returncode is not None:
                return proc
        if until.returncode is not None:
            return None
        time.sleep(poll)
    raise TimeoutError(f'{until.name} did not finish within {timeout:g} s of wall time')
