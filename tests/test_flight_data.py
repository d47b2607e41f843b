"""A flight as data: fly() returns a Flight, read_flight(bag) returns the same Flight, rows are thinned out by
the documented rule with exact metrics, and the memory of a flight does not grow with its length."""
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flight_stack.api import Flight, fly, read_flight
from quad_msgs_bridge.review.flight_data import SERIES, FlightLog
from quad_msgs_bridge.review.metrics import FlightRecord, flight_metrics
from quad_msgs_bridge.state import STATE_NAMES

ROOT = Path(__file__).resolve().parent.parent
ARRAYS = tuple(SERIES)


@pytest.fixture(scope='module')
def flown_with_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp('flight') / 'run'
    return fly('nnit2fsmc', 'paper', duration=3.0, out=out), out


def test_the_flown_flight_equals_the_flight_read_back_from_its_bag(flown_with_bag):
    """Tolerance 0 for every series but the reference yaw: the bag holds every float64 as flown, and the
    flight records the state as its odometry message gives it back (the same conversion). The reference
    yaw travels as an orientation (control/reference is a PoseStamped: a quaternion) and comes back through
    atan2, within 1e-15 rad; so the metrics that use it (rmse_yaw_rad) agree to 1e-12 relative."""
    flown, out = flown_with_bag
    read = read_flight(out / 'bag')
    assert isinstance(flown, Flight) and isinstance(read, Flight)
    assert flown.steps == read.steps == 3000 and flown.stride == read.stride == 1
    for name in ARRAYS:
        a, b = getattr(flown, name), getattr(read, name)
        assert a.shape == b.shape and a.shape[0] == 3000, name
        if name == 'reference_yaw':
            assert np.abs(a - b).max() <= 1e-15 and not np.array_equal(a, np.zeros_like(a))
        else:
            assert np.array_equal(a, b), name
    flown_metrics, read_metrics = flown.metrics(), read.metrics()
    assert read_metrics['rmse_yaw_rad'] == pytest.approx(flown_metrics['rmse_yaw_rad'], rel=1e-12)
    assert {k: v for k, v in read_metrics.items() if k != 'rmse_yaw_rad'} \
        == {k: v for k, v in flown_metrics.items() if k != 'rmse_yaw_rad'}
    summary = flown.summary
    assert {key: summary[key] for key in flown.metrics()} == flown.metrics()
    assert read.settle_time == flown.settle_time == summary['settle_time_s']
    assert read.path == out / 'bag' and read.label == 'nnit2fsmc'


def test_read_flight_gives_the_summary_fly_gives(flown_with_bag, tmp_path):
    """Issue 35: read_flight(bag).summary was None, so the README's flight.summary['rmse_position_m'] raised.
    Beside the run's summary.json every key is fly()'s (rmse_yaw_rad to 1e-12, as above); a bag alone gives
    every key but those only the run knows (gains, physics rate, plant, wall time, disturbances)."""
    from quad_msgs_bridge.review.summary import RUN_ONLY_KEYS
    flown, out = flown_with_bag
    read = read_flight(out / 'bag').summary
    assert list(read) == list(flown.summary)
    assert read['rmse_yaw_rad'] == pytest.approx(flown.summary['rmse_yaw_rad'], rel=1e-12)
    assert {k: v for k, v in read.items() if k != 'rmse_yaw_rad'} \
        == {k: v for k, v in flown.summary.items() if k != 'rmse_yaw_rad'}
    assert read['vehicle'] == 'paper' and read['flight_ok'] and read['controller'] == 'nnit2fsmc'
    assert 100 * read['rmse_position_m'] > 0      # the README's line
    alone = tmp_path / 'bag'
    shutil.copytree(out / 'bag', alone)
    summary = read_flight(alone).summary
    run_only = RUN_ONLY_KEYS[0] + RUN_ONLY_KEYS[1]
    assert list(summary) == [key for key in flown.summary if key not in run_only]
    assert {k: v for k, v in summary.items() if k != 'rmse_yaw_rad'} \
        == {k: v for k, v in flown.summary.items() if k not in run_only and k != 'rmse_yaw_rad'}


@pytest.mark.parametrize('bag', [42, None, '', ['out/bag']])
def test_read_flight_names_its_argument_when_it_is_not_a_path(bag):
    from flight_stack.api import ParameterError
    with pytest.raises(ParameterError, match=r'^read_flight: bag: expected the path of a bag folder or \.mcap file'):
        read_flight(bag)


def test_a_flight_has_the_time_series_with_their_shapes_and_units(flown_with_bag):
    flown, _ = flown_with_bag
    assert flown.time[0] == 0.0 and flown.time[-1] == pytest.approx(2.999)
    assert flown.state.shape == (3000, 12) and flown.forces.shape == (3000, 4) and flown.corrective.shape == (3000, 6)
    assert np.allclose(np.diff(flown.time), 0.001)
    # the state is the paper's: z climbs towards the reference and the rotor forces hold up the vehicle
    assert abs(flown.state[-1, 2] - flown.reference_position[-1, 2]) < 0.05
    assert flown.forces.sum(axis=1)[-1] == pytest.approx(flown.controls[-1, 0])
    columns = flown.columns()
    assert list(columns)[:13] == ['time', *STATE_NAMES] and len(columns) == 1 + 12 + 4 + 4 + 4 + 18
    assert np.array_equal(columns['fuzzy_theta'], flown.corrective[:, 4])
    assert isinstance(flown.record, FlightRecord) and np.array_equal(flown.record.yaw, flown.state[:, 8])


def test_to_pandas_says_how_to_get_pandas_when_it_is_missing(flown_with_bag, monkeypatch):
    flown, _ = flown_with_bag
    monkeypatch.setitem(sys.modules, 'pandas', None)
    with pytest.raises(ImportError, match='pip install pandas'):
        flown.to_pandas()


def test_to_pandas_gives_one_column_per_series_indexed_by_time(flown_with_bag):
    pytest.importorskip('pandas', reason='pandas is not installed (requirements-test.txt pins it)')
    flown, _ = flown_with_bag
    frame = flown.to_pandas()
    names = flown.unit_names()
    assert frame.shape == (3000, 42) and list(frame.columns) == [names[name] for name in list(flown.columns())[1:]]
    assert frame.index.name == 'time_s' and np.array_equal(frame.index.to_numpy(), flown.time)
    assert np.array_equal(frame['U4_Nm'].to_numpy(), flown.controls[:, 3])
    assert frame.loc[1.5, 'z_m'] == flown.state[1500, 2]      # a row by its sim time [s]


def test_to_pandas_names_its_columns_with_units_as_the_export_does(flown_with_bag, tmp_path):
    """Issue 35: to_pandas' columns had no units while the CSV export's do; both take them from Flight.unit_names."""
    pytest.importorskip('pandas', reason='pandas is not installed (requirements-test.txt pins it)')
    from flight_stack.export import export_flight
    flown, out = flown_with_bag
    header = export_flight(out / 'bag', tmp_path / 'flight.csv').read_text().splitlines()[0].split(',')
    frame = flown.to_pandas()
    assert [frame.index.name, *frame.columns] == header
    assert header[:5] == ['time_s', 'x_m', 'y_m', 'z_m', 'vx_mps'] and 'U4_Nm' in header and 'nn_z_N' in header


def synthetic_steps(count: int):
    """``count`` control steps, 0.5 s apart (several fuzzy-share windows), of a vehicle wobbling around its
    reference."""
    rng = np.random.default_rng(5)
    for k in range(count):
        t = k * 0.5
        state = [0.01 * math.sin(t), 0.0, 1.0 + 0.01 * rng.standard_normal()] + [0.0] * 5 + [0.02 * t] + [0.0] * 3
        forces = list(1.5 + 0.1 * rng.standard_normal(4))
        controls = [sum(forces), *(0.01 * rng.standard_normal(3))]
        yield (t, state, (0.0, 0.0, 1.0), 0.0, forces, controls, list(rng.standard_normal(6)),
               list(rng.standard_normal(6)), list(rng.standard_normal(6)))


def test_a_full_log_keeps_every_stride_th_step_and_its_metrics_stay_those_of_every_step():
    log = FlightLog(settle_time=2.0, f_min=0.0, f_max=3.0, max_rows=8)
    steps = list(synthetic_steps(40))
    for step in steps:
        log.add(*step)
    flight = log.flight(PARAMS_STUB)
    # 40 steps into 8 rows: stride 1 -> 2 (at step 8) -> 4 (16) -> 8 (32): rows of steps 0, 8, 16, 24, 32
    assert flight.stride == 8 and flight.steps == 40
    assert np.array_equal(flight.time, [steps[k][0] for k in range(0, 40, 8)])
    assert np.array_equal(flight.forces[2], steps[16][4])
    every_step = FlightRecord(*(np.array([s[i] for s in steps]) for i in (0,)),
                              position=np.array([s[1][:3] for s in steps]), yaw=np.array([s[1][8] for s in steps]),
                              reference_position=np.array([s[2] for s in steps]),
                              reference_yaw=np.array([s[3] for s in steps]),
                              forces=np.array([s[4] for s in steps]), controls=np.array([s[5] for s in steps]),
                              surfaces=np.array([s[6] for s in steps]), equivalent=np.array([s[7] for s in steps]),
                              corrective=np.array([s[8] for s in steps]))
    expected = flight_metrics(every_step, 2.0, 0.0, 3.0, arm_length=PARAMS_STUB.d)
    got = flight.metrics()
    assert len(got['fuzzy_share']['x']) == 4      # 19.5 s in windows of 5 s
    assert got['chattering_moment_nm_per_s'] is not None
    assert_close(got, expected, 'metrics')


def assert_close(got, expected, where: str) -> None:
    """``got`` equals ``expected`` to 1e-12 relative, through nested dicts and lists of figures."""
    if isinstance(expected, dict):
        assert set(got) == set(expected), where
        for key in expected:
            assert_close(got[key], expected[key], f'{where}.{key}')
    elif isinstance(expected, (list, tuple)):
        assert len(got) == len(expected), where
        for k, (a, b) in enumerate(zip(got, expected)):
            assert_close(a, b, f'{where}[{k}]')
    elif isinstance(expected, (int, float)) and not isinstance(expected, bool):
        assert got == pytest.approx(expected, rel=1e-12, abs=0.0), where
    else:
        assert got == expected, where


class PARAMS_STUB:
    F_min, F_max, d = 0.0, 3.0, 0.2   # rotor limits [N], arm length [m]


@pytest.mark.parametrize('max_rows', [1, 3])
def test_a_log_refuses_a_row_limit_it_cannot_halve(max_rows):
    with pytest.raises(ValueError, match='max_rows'):
        FlightLog(1.0, 0.0, 3.0, max_rows=max_rows)


def peak_rss_kb(duration: float, out: Path, bag: bool) -> int:
    """Peak resident set [kB] of run_stack.py flying ``duration`` [s] of the hover scenario."""
    process = subprocess.Popen([sys.executable, str(ROOT / 'run_stack.py'), '--backend', 'embedded', '--quiet',
                                '--scenario', 'hover', '--duration', repr(duration), '--out', str(out)]
                               + ([] if bag else ['--no-bag']), cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, process.stderr.read()
    return usage.ru_maxrss


@pytest.mark.slow
@pytest.mark.parametrize('bag', [False, True], ids=['no bag', 'bag'])
def test_the_memory_of_a_flight_does_not_grow_with_its_length(tmp_path, bag):
    """Before, a flight cost about 2.5 MB per simulated second (a 600 s flight peaked at 1.5 GB). Now the rows
    stop growing at MAX_ROWS (65.5 s at 1 kHz): flights of 80 s and 160 s both keep 40,000 rows (every 2nd and
    every 4th step), and from the one to the other the peak grows by less than 50 kB per simulated second (a
    bound 50 times below the old cost; rows kept at every step would add 344 kB/s)."""
    short, long = 80.0, 160.0
    rss_short = peak_rss_kb(short, tmp_path / 'short', bag)
    rss_long = peak_rss_kb(long, tmp_path / 'long', bag)
    growth = (rss_long - rss_short) / (long - short)
    print(f'peak RSS {rss_short / 1024:.1f} MB ({short:g} s), {rss_long / 1024:.1f} MB ({long:g} s): '
          f'{growth:.1f} kB per simulated second')
    assert growth < 50.0
