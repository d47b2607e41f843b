"""Proof that nothing changed (issue 36, item 6): while the code is restructured (the controller registry, the
flight world module, the api/cli layering, a studies package), every flight and a small campaign stay bit for bit
what they were at commit 0ff291a, the last commit before those moves.

:func:`fingerprints` uses only names that existed at 0ff291a and still exist (``flight_stack.api.fly``, the campaign
runner's ``run_campaign`` and ``RunOptions``, ``load_spec``, ``nnit2fsmc_controller.factory.CONTROLLERS``,
``nnit2fsmc_controller.trajectory.SCENARIOS``), so the same function runs on both trees. It flies every built-in kind on every scenario for its first 4 s (the
steps' first 7 s, its first step included; the waypoints scenario whole: its duration is fixed by its last
waypoint, make_scenario accepts only its own 20 s) with the default vehicle and disturbances and the gains packaged
at 0ff291a (tests/data/gains_0ff291a.yaml, which both trees load: the test compares the code, not the packaged
gains, which later tuning changes on purpose), and runs the shipped campaign 'mild-every-perturbation' (every
perturbation on) overridden to 6 flights of 3 s by nnit2fsmc, pid and indi in one worker with those gains (the
campaign runner's ``RunOptions.gains_file``, in both trees). A flight's fingerprint is the sha256 of the raw float64 bytes of its time, state, forces
and controls arrays; the campaign's, the sha256 of its flights.csv without the columns that depend on wall time
(there are none; WALL_TIME_COLUMNS says how they would be found).

Floating point is bit-reproducible on the same machine with the same numpy and numba, not across them: the
recording (tests/data/bit_identical_0ff291a.json) is keyed by numpy version (the suite runs under the pinned numpy
and numpy 1.26.4) and names the numba version and the CPU it was made with; the test skips, saying why, where
those differ. Remake it from a worktree of the recorded commit, so that its packages are the ones imported:

    git worktree add --detach /tmp/base 0ff291a   # from the clone, then from /tmp/base:
    NUMBA_CACHE_DIR=$(mktemp -d) CLONE/.venv/bin/python CLONE/tests/test_bit_identical.py --root /tmp/base \\
        --record CLONE/tests/data/bit_identical_0ff291a.json
    (the same with CLONE/.venv-numpy126/bin/python for numpy 1.26.4; then git worktree remove /tmp/base --force)

``python tests/test_bit_identical.py`` alone prints the current tree's fingerprints as JSON.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

RECORDING = Path(__file__).parent / 'data' / 'bit_identical_0ff291a.json'
GAINS = Path(__file__).parent / 'data' / 'gains_0ff291a.yaml'    #: what every flight flies, in both trees
DURATION = 4.0                    #: [s] flown of every scenario (but those below)
#: 'steps' holds its first setpoint until 5 s (then a 2 s transition): its first 4 s are the hover's, bit for bit
DURATIONS = {'steps': 7.0}
FIXED_LENGTH_SCENARIOS = ('waypoints',)   #: make_scenario accepts only their own duration: flown whole
CAMPAIGN_SPEC = 'mild-every-perturbation'
CAMPAIGN = dict(flights=6, duration=3.0, controllers=['nnit2fsmc', 'pid', 'indi'], workers=1)
#: a flights.csv column whose name contains one of these depends on wall time (batch.COLUMNS has none at 0ff291a)
WALL_TIME_COLUMNS = ('wall', 'elapsed', 'clock', 'timestamp', 'per_s_real')
#: columns flights.csv gained after 0ff291a (each flight's actuator, recorded since it can be drawn per flight):
#: left out, so the flights themselves are compared
ADDED_COLUMNS = ('motor_time_constant_s', 'delay_s')
#: flights changed on purpose since 0ff291a, key prefix -> why: they must now differ from the recording (the change
#: took effect), every other key still equals it
CHANGED_ON_PURPOSE = {
    'fly/se3/': 'issue 37: common.attitude_rates reaches se3 (the packaged flatness; before, it always filtered)',
    'fly/l1-se3/': 'issue 37: common.attitude_rates reaches l1-se3 (as se3)',
}
#: the source folders of the repository (pyproject's pytest pythonpath)
SOURCE_DIRS = ('.', 'ros2_ws/src/quad_msgs_bridge', 'ros2_ws/src/quad_sim', 'ros2_ws/src/nnit2fsmc_controller')


def _digest(*arrays) -> str:
    import numpy as np
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def _csv_digest(path: Path) -> str:
    """sha256 of flights.csv with its wall-time columns (if any) and ADDED_COLUMNS left out, rows in the file's order."""
    rows = list(csv.reader(io.StringIO(path.read_text())))
    keep = [i for i, name in enumerate(rows[0])
            if not any(w in name.lower() for w in WALL_TIME_COLUMNS) and name not in ADDED_COLUMNS]
    text = io.StringIO()
    csv.writer(text, lineterminator='\n').writerows([row[i] for i in keep] for row in rows)
    return hashlib.sha256(text.getvalue().encode()).hexdigest()


def fingerprints(progress=None) -> dict[str, str]:
    """name -> sha256 hex digest: 'fly/KIND/SCENARIO' for every built-in kind on every scenario, and
    'campaign/mild-every-perturbation/flights.csv'. Only names that exist at 0ff291a and now."""
    import flight_stack
    from flight_stack.api import fly
    from flight_stack.campaign.runner import RunOptions, run_campaign
    from flight_stack.campaign.spec import load_spec
    from nnit2fsmc_controller.factory import CONTROLLERS
    from nnit2fsmc_controller.trajectory import SCENARIOS

    result = {}
    for kind in CONTROLLERS:
        for scenario in SCENARIOS:
            duration = None if scenario in FIXED_LENGTH_SCENARIOS else DURATIONS.get(scenario, DURATION)
            flight = fly(kind, scenario, duration=duration, gains=GAINS)
            result[f'fly/{kind}/{scenario}'] = _digest(flight.time, flight.state, flight.forces, flight.controls)
            if progress:
                progress(f'fly/{kind}/{scenario}', result[f'fly/{kind}/{scenario}'])
    spec = Path(flight_stack.__file__).parent / 'campaign' / 'specs' / f'{CAMPAIGN_SPEC}.yaml'
    with tempfile.TemporaryDirectory() as out:
        campaign = load_spec(spec).overridden(flights=CAMPAIGN['flights'], duration=CAMPAIGN['duration'],
                                              controllers=CAMPAIGN['controllers'])
        run_campaign(campaign, Path(out) / 'campaign',
                     RunOptions(workers=CAMPAIGN['workers'], progress=False, gains_file=str(GAINS)))
        key = f'campaign/{CAMPAIGN_SPEC}/flights.csv'
        result[key] = _csv_digest(Path(out) / 'campaign' / 'flights.csv')
    if progress:
        progress(key, result[key])
    return result


def environment() -> dict:
    """What the bits depend on besides the code: numpy, numba, Python, the CPU numba compiles for."""
    import llvmlite.binding
    import numba
    import numpy
    return {'numpy': numpy.__version__, 'numba': numba.__version__, 'python': platform.python_version(),
            'machine': platform.machine(), 'cpu': llvmlite.binding.get_host_cpu_name()}


def _skip_reason(recorded: dict, now: dict) -> str | None:
    entry = recorded['by_numpy'].get(now['numpy'])
    if entry is None:
        return (f"no fingerprints of commit {recorded['commit'][:7]} recorded under numpy {now['numpy']} "
                f"(recorded: numpy {', '.join(sorted(recorded['by_numpy']))}); the bits are per numpy version")
    for name in ('numba', 'machine', 'cpu'):
        if entry[name] != now[name]:
            return (f'recorded with {name} {entry[name]}, this is {name} {now[name]}: floating point is '
                    f'bit-reproducible only on the same one (remake the recording: this module\'s docstring)')
    return None


@pytest.mark.slow
def test_every_flight_and_the_campaign_bit_identical_to_0ff291a():
    """fly() of every kind on every scenario and a small campaign's flights.csv equal, bit for bit, what the code
    of commit 0ff291a gave (tests/data/bit_identical_0ff291a.json), key by key; but the flights changed on purpose
    since (CHANGED_ON_PURPOSE), which must differ."""
    recorded = json.loads(RECORDING.read_text())
    now = environment()
    reason = _skip_reason(recorded, now)
    if reason:
        pytest.skip(reason)
    expected = recorded['by_numpy'][now['numpy']]['fingerprints']
    actual = fingerprints()
    missing = sorted(set(expected) - set(actual))
    new = sorted(set(actual) - set(expected))
    on_purpose = {k for k in expected if k.startswith(tuple(CHANGED_ON_PURPOSE))}
    assert on_purpose, 'CHANGED_ON_PURPOSE names no recorded flight'
    differing = sorted(k for k in set(expected) & set(actual) - on_purpose if expected[k] != actual[k])
    unchanged = sorted(k for k in on_purpose & set(actual) if expected[k] == actual[k])
    problems = ([f'differs from {recorded["commit"][:7]}: {k}' for k in differing]
                + [f'changed on purpose, yet equal to {recorded["commit"][:7]}: {k}' for k in unchanged]
                + [f'not flown now: {k}' for k in missing] + [f'not recorded: {k}' for k in new])
    assert not problems, f'{len(differing)} of {len(expected)} fingerprints differ:\n' + '\n'.join(problems)


def _commit(root: Path) -> tuple[str, bool]:
    """The commit of the tree at ``root``, and whether its tracked files differ from it."""
    head = subprocess.run(['git', '-C', str(root), 'rev-parse', 'HEAD'], capture_output=True, text=True,
                          check=True).stdout.strip()
    dirty = bool(subprocess.run(['git', '-C', str(root), 'status', '--porcelain', '--untracked-files=no'],
                                capture_output=True, text=True, check=True).stdout.strip())
    return head, dirty


def main(argv=None) -> int:
    import argparse
    parser = argparse.ArgumentParser(description='Print (or --record) the bit-equality fingerprints of a tree.')
    parser.add_argument('--root', type=Path, default=Path(__file__).resolve().parents[1],
                        help='the repository tree whose packages to import (default: this file\'s)')
    parser.add_argument('--record', type=Path, metavar='PATH',
                        help='add them to PATH (JSON keyed by numpy version) for the tree\'s commit')
    args = parser.parse_args(argv)
    root = args.root.resolve()
    sys.path[:0] = [str(root / d) for d in SOURCE_DIRS]
    import flight_stack
    import nnit2fsmc_controller
    import quad_msgs_bridge
    for module in (flight_stack, nnit2fsmc_controller, quad_msgs_bridge):
        if not Path(module.__file__).resolve().is_relative_to(root):
            parser.error(f'{module.__name__} was imported from {module.__file__}, not from {root}')
    commit, dirty = _commit(root)
    print(f'tree {root} at {commit}{" (with changes)" if dirty else ""}; flight_stack from {flight_stack.__file__}',
          file=sys.stderr)
    env = environment()
    print(f'environment: {env}', file=sys.stderr)
    result = fingerprints(progress=lambda key, digest: print(f'{key} {digest}', file=sys.stderr, flush=True))
    if args.record is None:
        print(json.dumps(result, indent=1))
        return 0
    if dirty:
        parser.error(f'{root} has uncommitted changes: record a clean commit')
    recorded = json.loads(args.record.read_text()) if args.record.exists() else {'commit': commit, 'by_numpy': {}}
    if recorded['commit'] != commit:
        parser.error(f'{args.record} holds commit {recorded["commit"]}, the tree is at {commit}')
    recorded['by_numpy'][env['numpy']] = {**env, 'fingerprints': result}
    args.record.parent.mkdir(parents=True, exist_ok=True)
    args.record.write_text(json.dumps(recorded, indent=1, sort_keys=True) + '\n')
    print(f'recorded {len(result)} fingerprints under numpy {env["numpy"]} in {args.record}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
