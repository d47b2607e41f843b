"""read_flight of an MCAP bag decodes a block of messages at a time: the same Flight as reading it message by
message, the slow way's fallback when a topic's layout changes, and memory that does not grow with the bag."""
import math
import tracemalloc

import numpy as np
import pytest

from quad_msgs_bridge.bag.flight_bag import FlightBag
from quad_msgs_bridge.fast_cdr import odometry_encoder
from quad_msgs_bridge.review import flight_from_bag
from quad_msgs_bridge.review.flight_data import SERIES
from quad_msgs_bridge.review.flight_from_bag import read_flight
from quad_msgs_bridge.state import odometry_from_state
from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS = load_vehicle_file()[0]
SLOPES = (1.0, 1.0, 2.0, 3.0, 3.0, 2.0)


def write_synthetic_bag(path, steps: int, dt: float = 1e-3, every_frame_id=None, references: int | None = None,
                        **custom):
    """A bag of ``steps`` control steps of a vehicle wobbling around a moving reference (no flight: the messages
    are what FlightBag writes for such steps). ``every_frame_id(k)``: the odometry's child frame id at step k
    (the default one when None). ``references``: only the first that many steps' references are written (the
    others lost, as a killed controller's last ones were by the recorder)."""
    rng = np.random.default_rng(3)
    with FlightBag.create(path, PARAMS, 1.0, controller='nnit2fsmc', **custom) as bag:
        for k in range(steps):
            t = k * dt
            state = [math.sin(t), math.cos(t), 1.0 + 0.01 * rng.standard_normal(), 0.1, 0.2, 0.0,
                     0.05 * math.sin(3 * t), -0.04 * math.cos(2 * t), 0.3 * t, 0.01, 0.02, 0.3]
            forces = tuple(2.0 + 0.2 * rng.standard_normal(4))
            controls = (sum(forces), 0.01 * rng.standard_normal(), 0.01 * rng.standard_normal(), 0.001)
            diagnostics = [list(rng.standard_normal(6)) for _ in range(3)]
            if every_frame_id is not None:
                bag._encode_odometry = odometry_encoder('odom', every_frame_id(k))
            if references is not None and k == references:
                bag._reference = None
            bag.record_step(odometry_from_state(t, state), forces, controls, (math.sin(t), math.cos(t), 1.0),
                            0.3 * t - 0.01, *diagnostics, SLOPES)
    return path


def read_by_messages(bag, monkeypatch):
    """read_flight through the message-by-message path (the one every other storage takes)."""
    def refuse(*args, **kwargs):
        raise flight_from_bag.UnsupportedLayout('taking the message-by-message path')
    with monkeypatch.context() as patch:
        patch.setattr(flight_from_bag, '_read_blocks', refuse)
        return read_flight(bag)


def assert_same_flight(a, b):
    assert a.steps == b.steps and a.stride == b.stride
    for name in SERIES:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert_close(a.metrics(), b.metrics(), 'metrics')


def assert_close(got, expected, where: str) -> None:
    """Equal to 1e-12 relative through nested dicts and lists (sums over blocks of different sizes round
    differently)."""
    if isinstance(expected, dict):
        assert got.keys() == expected.keys(), where
        for key in expected:
            assert_close(got[key], expected[key], f'{where}.{key}')
    elif isinstance(expected, list):
        assert len(got) == len(expected), where
        for k, (x, y) in enumerate(zip(got, expected)):
            assert_close(x, y, f'{where}[{k}]')
    elif isinstance(expected, float):
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-15), where
    else:
        assert got == expected, where


def test_the_block_reading_equals_the_message_by_message_reading(tmp_path, monkeypatch):
    bag = write_synthetic_bag(tmp_path / 'bag', 3000)
    blocks = read_flight(bag)
    assert blocks.steps == 3000 and blocks.time[-1] == pytest.approx(2.999)
    assert_same_flight(blocks, read_by_messages(bag, monkeypatch))


def test_a_flight_longer_than_the_rows_kept_reads_the_same_both_ways(tmp_path, monkeypatch):
    """Past MAX_ROWS steps the rows thin out and the metrics come from the sums of every step."""
    bag = write_synthetic_bag(tmp_path / 'bag', 70_000)
    blocks = read_flight(bag)
    assert blocks.stride == 2 and blocks.steps == 70_000
    assert_same_flight(blocks, read_by_messages(bag, monkeypatch))


def test_a_topic_whose_layout_changes_is_read_message_by_message(tmp_path, monkeypatch):
    """Odometry whose child frame id changes (a longer name) has no fixed layout: the reader falls back to the
    message-by-message path and still gives every step."""
    bag = write_synthetic_bag(tmp_path / 'bag', 500, every_frame_id=lambda k: 'base_link' if k < 250 else 'quad/base')
    taken = []
    original = flight_from_bag._read_steps
    monkeypatch.setattr(flight_from_bag, '_read_steps', lambda *a: taken.append(1) or original(*a))
    flight = read_flight(bag)
    assert taken and flight.steps == 500
    assert flight.summary is None and any(note.startswith('no summary: the flight of 0.499 s is not longer than the '
                                                          'settling window') for note in flight.warnings)


def test_steps_whose_reference_was_lost_are_left_out_the_same_both_ways(tmp_path, monkeypatch):
    """The references end 1,000 steps before the other messages (a recorder lost a killed controller's last
    references, tests/test_ros_nodes.py): the steps before read as usual, the others are left out and the
    reading says so, by blocks as by messages."""
    bag = write_synthetic_bag(tmp_path / 'bag', 3000, references=2000)
    blocks = read_flight(bag)
    assert blocks.steps == 2000 and blocks.time[-1] == pytest.approx(1.999)
    assert any('1000 control steps without odometry or reference' in note for note in blocks.warnings), \
        blocks.warnings
    assert_same_flight(blocks, read_by_messages(bag, monkeypatch))


def test_a_non_finite_value_in_a_bag_is_refused_naming_the_topic(tmp_path):
    bag = tmp_path / 'bag'
    with FlightBag.create(bag, PARAMS, 0.1, controller='nnit2fsmc') as written:
        for k in range(10):
            forces = (1.0, float('nan') if k == 7 else 1.0, 1.0, 1.0)
            written.record_step(odometry_from_state(k * 1e-3, [0.0] * 2 + [1.0] + [0.0] * 9), forces,
                                (4.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.0, [0.0] * 6, [0.0] * 6, [0.0] * 6, SLOPES)
    with pytest.raises(ValueError, match='non-finite value in rotor_forces'):
        read_flight(bag)


def peak_read_bytes(bag) -> int:
    tracemalloc.start()
    try:
        read_flight(bag)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_the_memory_of_reading_a_bag_does_not_grow_with_its_length(tmp_path):
    """Bags of 80 s and 160 s at 1 kHz (both past MAX_ROWS, so both keep 40,000 rows): the peak of what the
    read allocates (tracemalloc: Python objects and numpy arrays) grows by less than 20 kB per second of
    flight from the one to the other; the rows kept are about 14 MB and a block of messages about 50 MB, while
    holding every step would add 344 kB per second and the decoded messages several MB per second."""
    short, long = 80, 160
    small = write_synthetic_bag(tmp_path / 'short', short * 1000)
    large = write_synthetic_bag(tmp_path / 'long', long * 1000)
    read_flight(small)                      # imports and compiled kernels outside the measurement
    growth = (peak_read_bytes(large) - peak_read_bytes(small)) / (long - short)
    print(f'{growth / 1e3:.1f} kB per second of flight')
    assert growth < 20e3
