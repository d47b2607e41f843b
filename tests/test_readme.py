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
