"""The entry points as a new user meets them: ``python3 run_stack.py`` with a Python that lacks the stack's
packages, and what ``--help`` tells (subcommands, caps)."""
import inspect
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent


def bare_python(*args, cwd, env=None):
    """This interpreter without its site-packages (-S): numpy, numba, ... cannot be imported."""
    environment = {k: v for k, v in os.environ.items() if k not in ('PYTHONPATH', 'NNIT2FSMC_REEXEC')}
    return subprocess.run([sys.executable, '-S', *map(str, args)], cwd=cwd, capture_output=True, text=True,
                          timeout=HANG_TIMEOUT_S, env={**environment, **(env or {})})


def test_run_stack_without_the_packages_and_without_a_venv_says_how_to_run_in_one_line(tmp_path):
    shutil.copy(ROOT / 'run_stack.py', tmp_path / 'run_stack.py')      # a clone without .venv
    result = bare_python(tmp_path / 'run_stack.py', '--duration', '1', cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in result.stderr, result.stderr
    assert lines[0].startswith('error: ') and 'numba' in lines[0] and 'bash scripts/fly.sh' in lines[0]


@pytest.mark.skipif(not (ROOT / '.venv' / 'bin' / 'python').exists(), reason='no .venv in this clone')
def test_run_stack_without_the_packages_runs_again_with_the_clone_s_venv():
    result = bare_python(ROOT / 'run_stack.py', '--help', cwd=ROOT)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('usage: run_stack.py')


def test_help_names_the_subcommands_and_the_caps():
    result = subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), '--help'], cwd=ROOT, capture_output=True,
                            text=True, timeout=HANG_TIMEOUT_S)
    assert result.returncode == 0, result.stderr
    text = ' '.join(result.stdout.split())
    for subcommand in ('campaign', 'tune', 'stress', 'review', 'recover', 'rosbag2-qos'):
        assert f'run_stack.py {subcommand}' in text, subcommand
    from flight_stack.fleet import MAX_VEHICLES
    assert f'at most {MAX_VEHICLES}' in text


@pytest.mark.slow
def test_setup_venv_runs_pip_only_when_the_requirements_change(tmp_path):
    """The second call finds the stamp of the same requirements and leaves pip alone (here: any pip run
    after the first call fails, on a constraints file that does not exist, and the second call still
    succeeds); a changed requirements file runs pip again (and so fails here)."""
    requirements = tmp_path / 'requirements.txt'
    requirements.write_text('# nothing to install\n')
    venv = tmp_path / 'venv'

    def setup(**env):
        return subprocess.run(['bash', str(ROOT / 'scripts' / 'setup_venv.sh'), str(venv), str(requirements)],
                              capture_output=True, text=True, timeout=HANG_TIMEOUT_S,
                              env={**os.environ, 'PYTHON': sys.executable, **env})

    first = setup()
    assert first.returncode == 0, first.stderr
    assert (venv / '.installed-requirements.txt.sha256').exists()
    pip_fails = {'PIP_CONSTRAINT': str(tmp_path / 'absent-constraints.txt')}
    again = setup(**pip_fails)
    assert again.returncode == 0, again.stderr                      # pip was not run
    requirements.write_text('# nothing to install, changed\n')
    changed = setup(**pip_fails)
    assert changed.returncode != 0 and 'absent-constraints.txt' in changed.stderr, changed.stderr   # pip ran


def run_stack_subcommands() -> list[str]:
    """The subcommands run_stack.py dispatches (flight_stack.cli.run: ``argv[:1] == ['review']``, ...)."""
    from flight_stack import cli
    return sorted(set(re.findall(r"\['([a-z][a-z0-9-]*)'\]", inspect.getsource(cli.run))))


@pytest.mark.skipif(not (ROOT / '.venv' / 'bin' / 'python').exists(), reason='no .venv in this clone')
def test_fly_sh_passes_every_subcommand_of_run_stack_on():
    """Issue 35: `bash scripts/fly.sh tune|stress|export ...` said `unrecognized arguments`: fly.sh passed on
    only the subcommands it listed. Each one now gets its own parser (its usage line names it)."""
    subcommands = run_stack_subcommands()
    assert {'campaign', 'tune', 'stress', 'review', 'recover', 'export', 'rosbag2-qos'} <= set(subcommands)
    for subcommand in subcommands:
        result = subprocess.run(['bash', str(ROOT / 'scripts' / 'fly.sh'), subcommand, '--help'], cwd=ROOT,
                                capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
        assert result.returncode == 0, (subcommand, result.stderr)
        usage = rf'usage: (run_stack\.py )?{re.escape(subcommand)} '
        assert re.match(usage, result.stdout), (subcommand, result.stdout)
    flight = subprocess.run(['bash', str(ROOT / 'scripts' / 'fly.sh'), '--help'], cwd=ROOT, capture_output=True,
                            text=True, timeout=HANG_TIMEOUT_S)
    assert flight.returncode == 0 and flight.stdout.startswith('usage: run_stack.py [-h]'), flight.stderr
