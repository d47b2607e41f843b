"""Random streams of a flight, and standard normal draws that do not depend on the batch.

Every random element of a flight draws from its own :class:`numpy.random.Generator`, seeded by
``SeedSequence(entropy=campaign seed, spawn_key=(flight index, purpose))``: the child a
``SeedSequence(seed, spawn_key=(flight,)).spawn(...)`` would give, but addressed by a fixed purpose
number, so adding a purpose later changes no existing stream. A flight's draws therefore depend
only on (seed, flight index), never on the batch it flies in, the worker or the machine.

:class:`StandardNormals` serves a consumer ``width`` draws per step. One vehicle draws from its
Generator; a batch holds one Generator per vehicle. Both draw blocks of :data:`BLOCK_STEPS` rows
with the same call (``standard_normal((BLOCK_STEPS, width))``), so vehicle k sees the same
sequence whatever the batch size, and a batch step costs a slice, not B Python calls.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from quad_msgs_bridge.validation import ParameterError

#: Rows (steps) drawn per refill. 128 steps x 12 values x 8 bytes = 12 kB per vehicle: a batch of
#: 10,000 vehicles holds 123 MB for the widest consumer (twice that while refilling); the B Python
#: calls of a refill are spread over 128 steps.
BLOCK_STEPS = 128
#: Vehicles whose draws are transposed into a batch's block at a time, and the padding [values] of
#: their scratch rows (a speed choice only: the draws are the same whatever they are).
REFILL_CHUNK = 64
SCRATCH_PAD = 8


class FlightStreams(NamedTuple):
    """The independent random streams of one flight, one per purpose (the field order is the
    purpose number in the seed: never reorder, only append)."""

    vehicle: np.random.Generator       #: the campaign runner's sampling of the true vehicle
    wind: np.random.Generator          #: the campaign runner's sampling of the mean wind
    turbulence: np.random.Generator    #: Dryden white noise (:class:`~.wind.DrydenTurbulence`)
    sensor_noise: np.random.Generator  #: odometry white noise (:class:`~.sensor_noise.SensorNoise`)
    sensor_bias: np.random.Generator   #: odometry per-flight bias (:class:`~.sensor_noise.SensorNoise`)
    actuator: np.random.Generator      #: a flight's motor time constant and delay, when drawn (quad_sim.world)


def flight_streams(seed: int, flight_index: int) -> FlightStreams:
    """The streams of flight ``flight_index`` of a campaign seeded with ``seed`` (both integers >= 0)."""
    return FlightStreams(*(flight_stream(seed, flight_index, purpose) for purpose in FlightStreams._fields))


def flight_stream(seed: int, flight_index: int, purpose: str) -> np.random.Generator:
    """The stream ``purpose`` (a field name of :class:`FlightStreams`) of flight ``flight_index`` of a campaign
    seeded with ``seed``, alone: the same Generator as that field of :func:`flight_streams` (a campaign
    builds only the streams its perturbations draw from; each costs tens of microseconds)."""
    for name, value in (('seed', seed), ('flight_index', flight_index)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ParameterError(f'{name}: expected an integer >= 0, got {value!r}')
    if purpose not in FlightStreams._fields:
        raise ParameterError(f'purpose: {purpose!r} is not one of {", ".join(FlightStreams._fields)}')
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(
        entropy=int(seed), spawn_key=(int(flight_index), FlightStreams._fields.index(purpose)))))


def check_rng(name: str, rng) -> np.random.Generator | list[np.random.Generator]:
    """``rng`` as one Generator (one vehicle) or a non-empty list of Generators (a batch, one per vehicle)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, Sequence) and rng and all(isinstance(g, np.random.Generator) for g in rng):
        return list(rng)
    raise ParameterError(f'{name}: expected a numpy Generator (one vehicle) or a non-empty list of them '
                         f'(a batch, one per vehicle), got {type(rng).__name__}')


def batch_size(rng) -> int | None:
    """B for a list of Generators, None for a single one."""
    return None if isinstance(rng, np.random.Generator) else len(rng)


def check_batch(**values) -> int | None:
    """The common batch size B of per-vehicle arrays and Generator lists (None: all single values),
    or ParameterError naming the value whose size differs."""
    sizes = {}
    for name, value in values.items():
        if isinstance(value, np.ndarray):
            sizes[name] = value.size
        elif isinstance(value, list):
            sizes[name] = len(value)
    for name, size in sizes.items():
        first = next(iter(sizes))
        if size != sizes[first]:
            raise ParameterError(f'{name}: {size} vehicles, but {first} has {sizes[first]}')
    return next(iter(sizes.values()), None)


class StandardNormals:
    """``width`` standard normal draws per call of :meth:`next`, per vehicle.

    One vehicle (``rng`` a Generator): a list of ``width`` floats. A batch (``rng`` a list of B
    Generators): a (width, B) array view, row j holding draw j of every vehicle.
    """

    def __init__(self, rng, width: int):
        self._rng = check_rng('rng', rng)
        self._width = width
        self._size = batch_size(self._rng)
        self._block = None
        self._row = BLOCK_STEPS

    def next(self):
        if self._row == BLOCK_STEPS:
            self._refill()
        row = self._block[self._row]
        self._row += 1
        return row

    def _refill(self) -> None:
        shape = (BLOCK_STEPS, self._width)
        if self._size is None:
            self._block = self._rng.standard_normal(shape).tolist()
        else:
            # (step, draw, vehicle). Each generator fills its own rows of a small scratch that stays
            # in cache, transposed into the block REFILL_CHUNK vehicles at a time; the scratch rows are
            # padded so that they do not all fall on the same cache sets (a multiple of 4 kB apart).
            block = np.empty((*shape, self._size))
            count = BLOCK_STEPS * self._width
            scratch = np.empty((REFILL_CHUNK, count + SCRATCH_PAD))
            draws = scratch[:, :count].reshape(REFILL_CHUNK, *shape)
            for start in range(0, self._size, REFILL_CHUNK):
                generators = self._rng[start:start + REFILL_CHUNK]
                for generator, rows in zip(generators, scratch):
                    generator.standard_normal(count, out=rows[:count])
                block[:, :, start:start + len(generators)] = draws[:len(generators)].transpose(1, 2, 0)
            self._block = block
        self._row = 0
