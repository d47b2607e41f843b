"""Random streams: one per purpose and flight, from (seed, flight index); draws independent of the batch."""
import numpy as np
import pytest

from quad_msgs_bridge.validation import ParameterError
from quad_sim.perturbations import BLOCK_STEPS, FlightStreams, SensorErrors, SensorNoise, Wind, flight_streams
from quad_sim.perturbations.streams import REFILL_CHUNK, StandardNormals


def test_streams_are_the_spawned_children_of_the_flights_seed_sequence():
    """flight_streams(seed, k).<purpose> = child number <purpose> of SeedSequence(seed, spawn_key=(k,))."""
    children = np.random.SeedSequence(entropy=42, spawn_key=(17,)).spawn(len(FlightStreams._fields))
    streams = flight_streams(42, 17)
    for child, generator in zip(children, streams):
        reference = np.random.Generator(np.random.PCG64(child))
        assert generator.standard_normal(5).tolist() == reference.standard_normal(5).tolist()
    assert streams._fields == ('vehicle', 'wind', 'turbulence', 'sensor_noise', 'sensor_bias', 'actuator')  # only appended


def test_streams_are_reproducible_and_distinct():
    first, again = flight_streams(3, 5), flight_streams(3, 5)
    for a, b in zip(first, again):
        assert a.random(4).tolist() == b.random(4).tolist()
    draws = [g.standard_normal(20000) for g in (*flight_streams(3, 5), *flight_streams(3, 6), *flight_streams(4, 5))]
    correlation = np.corrcoef(draws)
    # 18 streams, pairwise sample correlations of 20,000 draws: std 0.007, all below 5 sigma
    assert np.all(np.abs(correlation - np.eye(len(draws))) < 0.035)


@pytest.mark.parametrize('seed, flight', [(-1, 0), (0, -2), (1.5, 0), (0, '3'), (True, 0)])
def test_invalid_seed_or_flight_is_refused(seed, flight):
    with pytest.raises(ParameterError, match='seed|flight_index'):
        flight_streams(seed, flight)


def test_a_flight_draws_the_same_alone_or_in_a_batch_of_seven():
    """Flight 12 alone, and at position 3 of a batch of 7 with other flights: identical turbulence and noise."""
    flights = [40, 2, 7, 12, 0, 99, 5]
    steps = 3 * BLOCK_STEPS + 11
    alone = flight_streams(9, 12)
    wind_alone = Wind(1e-3, mean_speed=3.0, turbulence='moderate', rng=alone.turbulence)
    noise_alone = SensorNoise(SensorErrors(0.01, 0.02, 0.01, 0.02), SensorErrors(0.01, 0.01, 0.01, 0.01),
                              alone.sensor_noise, alone.sensor_bias)
    streams = [flight_streams(9, f) for f in flights]
    wind_batch = Wind(1e-3, mean_speed=3.0, turbulence='moderate', rng=[s.turbulence for s in streams])
    noise_batch = SensorNoise(SensorErrors(0.01, 0.02, 0.01, 0.02), SensorErrors(0.01, 0.01, 0.01, 0.01),
                              [s.sensor_noise for s in streams], [s.sensor_bias for s in streams])
    np.testing.assert_array_equal([b[3] for b in noise_batch.bias], noise_alone.bias)
    state = [0.1 * i for i in range(12)]
    batch_state = [np.full(7, v) for v in state]
    for _ in range(steps):
        np.testing.assert_allclose([a[3] for a in wind_batch.step()], wind_alone.step(), rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose([m[3] for m in noise_batch.measure(batch_state)], noise_alone.measure(state),
                                   rtol=1e-13, atol=1e-15)


def test_standard_normals_continue_the_generators_sequence_across_blocks():
    width = 3
    single = StandardNormals(np.random.default_rng(5), width)
    batch = StandardNormals([np.random.default_rng(4), np.random.default_rng(5)], width)
    reference = np.random.default_rng(5).standard_normal((3 * BLOCK_STEPS, width))
    for k in range(3 * BLOCK_STEPS):
        row = single.next()
        assert isinstance(row[0], float)
        assert row == reference[k].tolist()
        np.testing.assert_array_equal(batch.next()[:, 1], reference[k])


def test_every_vehicle_of_a_batch_larger_than_a_refill_chunk_draws_its_own_sequence():
    """A batch of two refill chunks and a part of a third: vehicle k's draws are generator k's own,
    in order, across two blocks (the chunks are only a way to fill a block)."""
    size, width = 2 * REFILL_CHUNK + 5, 4
    batch = StandardNormals([np.random.default_rng(100 + k) for k in range(size)], width)
    rows = np.array([batch.next() for _ in range(2 * BLOCK_STEPS)])    # (step, draw, vehicle)
    for k in (0, REFILL_CHUNK - 1, REFILL_CHUNK, 2 * REFILL_CHUNK, size - 1):
        reference = np.random.default_rng(100 + k).standard_normal((2 * BLOCK_STEPS, width))
        np.testing.assert_array_equal(rows[:, :, k], reference)


def test_one_stream_alone_is_that_field_of_the_flights_streams():
    """flight_stream(seed, k, purpose): the Generator flight_streams(seed, k).<purpose> is (a campaign builds
    only the streams its perturbations draw from); an unknown purpose or a bad seed is refused."""
    from quad_sim.perturbations.streams import flight_stream
    streams = flight_streams(5, 31)
    for purpose in FlightStreams._fields:
        assert flight_stream(5, 31, purpose).random(6).tolist() == getattr(streams, purpose).random(6).tolist()
    with pytest.raises(ParameterError, match='purpose'):
        flight_stream(5, 31, 'gusts')
    with pytest.raises(ParameterError, match='seed'):
        flight_stream(-1, 31, 'wind')
