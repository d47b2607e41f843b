"""``run_stack.py study``: every module of flight_stack/studies/ is a study the command lists and runs, and an
unknown name is refused with the list."""
import subprocess
import sys
from pathlib import Path

import pytest

from flight_stack.studies import cli
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
STUDIES = sorted(path.stem.replace('_', '-') for path in (ROOT / 'flight_stack' / 'studies').glob('*.py')
                 if path.stem not in ('__init__', *cli.HELPERS))


def study(*argv):
    return subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), 'study', *argv], capture_output=True,
                          text=True, timeout=HANG_TIMEOUT_S)


def test_the_list_names_every_study_module_with_its_table_and_doc():
    listed = study('--list')
    assert listed.returncode == 0, listed.stderr
    rows = dict(line.split(None, 1) for line in listed.stdout.splitlines())
    assert sorted(rows) == STUDIES
    for name, description in rows.items():
        assert 'table' in description and ('docs/' in description or 'README' in description), (name, description)


def test_an_unknown_study_exits_2_with_the_list():
    refused = study('no-such-study')
    assert refused.returncode == 2 and refused.stdout == ''
    assert "no study 'no-such-study'" in refused.stderr
    assert all(name in refused.stderr for name in STUDIES)


#: the subcommand that flies, of a study that has several
FLYING = {'scoreboard': ['run']}


@pytest.mark.parametrize('name', STUDIES)
def test_every_study_has_its_options_and_an_out_folder(name):
    shown = study(name, *FLYING.get(name, []), '--help')
    assert shown.returncode == 0, shown.stderr
    assert f'run_stack.py study {name}' in shown.stdout and '--out DIR' in shown.stdout


def test_indi_lag_cells_take_the_true_lag_or_a_factor_and_count_failures_as_the_largest_error():
    from flight_stack.studies.indi_lag import assumed, cell
    assert assumed('true', 0.0153, 0.045) == 0.045 and assumed('2', 0.0153, 0.045) == pytest.approx(0.0306)
    flights = [{'finished': True, 'rmse_position_m': 0.01}] * 18 + [{'finished': False, 'rmse_position_m': 0.02}] * 2
    # p50 of eighteen 1 cm and two failures (1 m each) is 1 cm; p95 lies between the 19th and 20th value, both
    # failures: said as such, not as the 1 m they are counted as
    assert cell(flights, 1.0) == '18/20: 1.00 / failed'
    # p95 of 19 finished and one failure interpolates between the 19th (finished) and the 20th: a failure enters it
    assert cell(flights[:1] * 19 + flights[-1:], 1.0) == '19/20: 1.00 / failed'
    assert cell(flights[:1] * 20, 1.0) == '20/20: 1.00 / 1.00'


@pytest.mark.parametrize('option, value', [('--lags', 'abc'), ('--lags', '-1'), ('--factors', 'twice')])
def test_indi_lag_refuses_a_bad_list_naming_the_option_before_flying(tmp_path, option, value):
    refused = study('indi-lag', '--out', str(tmp_path), option, value)
    assert refused.returncode == 2 and refused.stderr.startswith(f'error: {option}: '), refused.stderr
    assert not (tmp_path / 'indi-lag').exists()
