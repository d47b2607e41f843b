"""The README's Python API example runs as written, and does what its comments say."""
import contextlib
import io
import math
import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / 'README.md'


def api_example() -> str:
    section = README.read_text().split('## Python API', 1)[1]
    return re.search(r'```python\n(.*?)```', section, re.S).group(1)


def test_the_readme_api_example_runs_verbatim_and_prints_forces_and_an_rmse():
    printed = io.StringIO()
    namespace: dict = {}
    with contextlib.redirect_stdout(printed):
        exec(compile(api_example(), str(README), 'exec'), namespace)
    forces, params = namespace['out'].forces, namespace['controller'].params
    assert len(forces) == 4 and all(math.isfinite(f) and params.F_min <= f <= params.F_max for f in forces)
    assert forces[0] == forces[2] and forces[1] == forces[3]      # level, on the vertical: no torque asked
    lines = printed.getvalue().splitlines()
    assert lines[0] == str(forces)
    flight = namespace['flight']
    rmse = flight.summary['rmse_position_m']
    assert lines[1] == f'RMSE {100 * rmse:.2f} cm'
    assert 0.0 < rmse < 0.01
    assert lines[2] == '(10000,) (10000, 12) (10000, 4)'
    assert rmse == flight.metrics()['rmse_position_m']
    windy, nominal = namespace['windy'], namespace['nominal']
    before, after = windy.controls[5999, 0], windy.controls[-1, 0]
    assert windy.time[5999] < 6.0 <= windy.time[6000]
    assert lines[3] == f"RMSE {100 * windy.summary['rmse_position_m']:.2f} cm, U1 {before:.2f} N -> {after:.2f} N"
    assert windy.summary['flight_ok']
    # the controller takes up the payload: U1 rises towards the extra weight (1.3 - 1.1) m g and stays below it
    # (its sliding surfaces trade a little height for it; the flight still passes its checks)
    assert 0.25 * 0.2 * nominal.m * nominal.g < after - before < 1.2 * 0.2 * nominal.m * nominal.g
