"""PX4 SITL (its built-in SIH simulator) and the Micro XRCE-DDS Agent for one flight: found, started, stopped.

``run_stack.py --plant px4-sitl`` flies PX4's own simulated quadrotor instead of our simulator: the ROS backend
(flight_stack.ros_backend) starts, through :class:`Px4Sitl`, the Agent (``MicroXRCEAgent udp4 -p PORT``) and
PX4 SITL (``build/px4_sitl_default/bin/px4 -d -i N -w WORKDIR build/px4_sitl_default/etc`` with
``PX4_SYS_AUTOSTART=10040``, airframe ``sihsim_quadx``, headless), then our nodes with the PX4 bridge node
(quad_sim.px4_node) in place of the simulator node. Nothing of PX4, the Agent or px4_msgs is part of this stack:
the user builds them by PX4's guides (docs/PX4.md) and names them: ``--px4-dir`` or ``PX4_DIR`` (the
PX4-Autopilot folder holding ``build/px4_sitl_default``), ``MicroXRCEAgent`` on PATH or ``--xrce-agent``, and
px4_msgs importable (a sourced colcon install). :func:`find_px4` refuses in one line, before anything starts,
naming everything that is missing.

One flight, one of everything: each run takes its own SITL instance N (PX4's daemon lock, its MAVLink ports and
MAV_SYS_ID N + 1), its own Agent UDP port and its own ROS_DOMAIN_ID, held by a lock file for the run's life, and
a fresh PX4 working directory (PX4's parameters start from the airframe's defaults every time), so concurrent
runs and tests do not meet. PX4 SITL runs in real time (SIH steps every 4 ms of wall time); nothing waits for
our nodes: the ROS backend's realtime mode.

Parameters set at start (a ``px4-rc.params`` that PX4's rcS sources from PATH, "user defined params", after the
airframe): see :data:`PX4_PARAMETERS`.
"""
from __future__ import annotations

import fcntl
import importlib.util
import os
import shutil
import socket
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from quad_msgs_bridge.validation import ParameterError

#: SIH quadrotor X (ROMFS/px4fmu_common/init.d-posix/airframes/10040_sihsim_quadx)
SIH_QUADX_AUTOSTART = 10040
#: the build folder inside the PX4-Autopilot folder (``make px4_sitl_default``)
BUILD = Path('build') / 'px4_sitl_default'
AGENT = 'MicroXRCEAgent'
#: the SITL instances, ROS domains and lock files a run chooses from (instance 0 is left to a user's own SITL)
INSTANCES = range(1, 30)
DOMAIN_BASE = 60                 #: ROS_DOMAIN_ID of instance N: DOMAIN_BASE + N
LOCK_DIR = Path(tempfile.gettempdir())

#: PX4 parameters for an offboard flight without RC, joystick or ground station (name, value, why)
PX4_PARAMETERS = (
    ('COM_RC_IN_MODE', 4, 'no manual control input at all (RC and joystick disabled): arming and offboard do not '
                          'wait for one (docs.px4.io "Offboard Mode")'),
    ('NAV_RCL_ACT', 0, 'RC loss: no failsafe action (there is no RC to lose)'),
    ('NAV_DLL_ACT', 0, 'ground-station data link loss: no failsafe action (there is no ground station)'),
    ('COM_OBL_RC_ACT', 4, 'offboard loss: Land (the default 0, Position mode, needs a manual control input)'),
    ('COM_OF_LOSS_T', 1.0, 'offboard loss after 1 s without OffboardControlMode (PX4\'s default; SITL\'s rcS '
                           'autoconfig sets 0.5 s)'),
    ('COM_DISARM_PRFLT', 30.0, 'armed but not taken off: disarm after 30 s (default 10 s), room for a slow start'),
)


@dataclass(frozen=True)
class Px4Install:
    """Where PX4 SITL, the Agent and px4_msgs were found."""

    px4_dir: Path          #: the PX4-Autopilot folder
    binary: Path           #: build/px4_sitl_default/bin/px4
    data: Path             #: build/px4_sitl_default/etc (ROMFS: rcS, airframes)
    agent: Path            #: MicroXRCEAgent
    px4_msgs: Path         #: share/px4_msgs/msg (the message definitions the bag's schemas come from)


def find_px4(px4_dir: str | Path | None = None, agent: str | Path | None = None) -> Px4Install:
    """PX4 SITL from ``px4_dir`` (None: env PX4_DIR), the Agent ``agent`` (None: MicroXRCEAgent on PATH) and
    px4_msgs (importable, with its ``.msg`` files); ParameterError in one line naming every missing piece."""
    from quad_msgs_bridge.px4 import px4_msgs_definitions
    missing = []
    binary = data = None
    folder = px4_dir if px4_dir is not None else os.environ.get('PX4_DIR')
    if not folder:
        missing.append('PX4 SITL (give --px4-dir or set PX4_DIR to the PX4-Autopilot folder holding '
                       f'{BUILD}: make px4_sitl_default)')
    else:
        binary, data = Path(folder) / BUILD / 'bin' / 'px4', Path(folder) / BUILD / 'etc'
        if not (binary.is_file() and os.access(binary, os.X_OK)) or not (data / 'init.d-posix' / 'rcS').is_file():
            missing.append(f'PX4 SITL ({binary} or {data}/init.d-posix/rcS not found: build it with '
                           'make px4_sitl_default in that PX4-Autopilot folder)')
    found_agent = shutil.which(str(agent)) if agent is not None else shutil.which(AGENT)
    if found_agent is None:
        missing.append(f'the Micro XRCE-DDS Agent ({agent} is not an executable)' if agent is not None else
                       f'the Micro XRCE-DDS Agent ({AGENT} is not on PATH; or give --xrce-agent PATH)')
    definitions = None
    if importlib.util.find_spec('px4_msgs') is None:
        missing.append('px4_msgs (not importable: build it with colcon and source its install/setup.bash)')
    else:
        try:
            definitions = px4_msgs_definitions()
        except FileNotFoundError as error:
            missing.append(str(error))
    if missing:
        raise ParameterError('--plant px4-sitl: missing ' + '; '.join(missing) + ' (docs/PX4.md)')
    return Px4Install(Path(folder), binary, data, Path(found_agent), definitions)


def free_udp_port() -> int:
    """A UDP port free on localhost now (the Agent's)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


@dataclass
class Px4Slot:
    """A SITL instance, its ROS domain and Agent port, held (a lock file) until :meth:`release`."""

    instance: int
    domain_id: int
    port: int
    _lock: object = field(default=None, repr=False)

    @property
    def target_system(self) -> int:
        """PX4's MAV_SYS_ID in SITL (rcS: instance + 1), which vehicle commands name."""
        return self.instance + 1

    @property
    def namespace(self) -> str:
        """The prefix of PX4's topics: rcS names instance N's client px4_N."""
        return f'px4_{self.instance}' if self.instance else ''

    def release(self) -> None:
        if self._lock is not None:
            self._lock.close()
            self._lock = None


def take_slot() -> Px4Slot:
    """The first SITL instance no other run holds (its lock file and PX4's own daemon lock free)."""
    for instance in INSTANCES:
        lock = open(LOCK_DIR / f'nnit2fsmc-px4-sitl-{instance}.lock', 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        if _px4_daemon_running(instance):
            lock.close()
            continue
        return Px4Slot(instance, DOMAIN_BASE + instance, free_udp_port(), lock)
    raise RuntimeError(f'no free PX4 SITL instance among {INSTANCES.start}..{INSTANCES.stop - 1}')


def _px4_daemon_running(instance: int) -> bool:
    """True if a PX4 SITL of ``instance`` runs (it holds an flock on /tmp/px4_lock-N, platforms/posix/.../main.cpp)."""
    path = Path('/tmp') / f'px4_lock-{instance}'
    if not path.exists():
        return False
    try:
        with open(path, 'r') as handle:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(handle, fcntl.LOCK_UN)
    except OSError:
        return True
    return False


def parameters_script(parameters=PX4_PARAMETERS) -> str:
    """The ``px4-rc.params`` rcS sources: one ``param set`` per parameter, with its reason."""
    lines = ['#!/bin/sh', '# written by flight_stack.px4_sitl for an offboard flight without RC (docs/PX4.md)']
    for name, value, why in parameters:
        lines += [f'# {why}', f'param set {name} {value}']
    return '\n'.join(lines) + '\n'


class Px4Sitl:
    """PX4 SITL (SIH, headless) and the Agent of one flight, as :class:`flight_stack.processes.NodeProcess`es."""

    def __init__(self, install: Px4Install, slot: Px4Slot, env: dict[str, str], quiet: bool = True,
                 keep_workdir: bool = False):
        self.install, self.slot, self.quiet = install, slot, quiet
        self.workdir = Path(tempfile.mkdtemp(prefix=f'nnit2fsmc-px4-{slot.instance}-'))
        self.keep_workdir = keep_workdir
        params_dir = self.workdir / 'params'
        params_dir.mkdir()
        (params_dir / 'px4-rc.params').write_text(parameters_script())
        self.env = dict(env)
        self.env.update({'ROS_DOMAIN_ID': str(slot.domain_id), 'PX4_SYS_AUTOSTART': str(SIH_QUADX_AUTOSTART),
                         'PX4_UXRCE_DDS_PORT': str(slot.port), 'PX4_SIM_SPEED_FACTOR': '1'})
        self.px4_env = dict(self.env)
        # rcS appends its own folder to PATH and sources px4-rc.params from it: ours comes first
        self.px4_env['PATH'] = f'{params_dir}{os.pathsep}{self.install.binary.parent}{os.pathsep}' \
                               f'{self.env.get("PATH", "")}'
        self.processes: list = []

    def start(self) -> list:
        """Start the Agent, then PX4; the processes (to watch and stop)."""
        from .processes import NodeProcess
        rootfs = self.workdir / 'rootfs'
        rootfs.mkdir()
        self.processes.append(NodeProcess('xrce-agent', [str(self.install.agent), 'udp4', '-p', str(self.slot.port)],
                                          self.env, quiet=True))
        self.processes.append(NodeProcess('px4', [str(self.install.binary), '-d', '-i', str(self.slot.instance),
                                                  '-w', str(rootfs), str(self.install.data)],
                                          self.px4_env, quiet=True))
        return list(self.processes)

    def describe(self) -> str:
        return (f'PX4 SITL (SIH, airframe {SIH_QUADX_AUTOSTART}) instance {self.slot.instance}, Agent udp4 port '
                f'{self.slot.port}, ROS_DOMAIN_ID {self.slot.domain_id}')

    def close(self) -> None:
        """Remove the working directory (unless kept) and release the slot; the processes are stopped by the caller."""
        if not self.keep_workdir:
            shutil.rmtree(self.workdir, ignore_errors=True)
        self.slot.release()
