"""State a compiled kernel reads and writes in place: one flat float array, a *store*.

A single-vehicle part of a controller (a network, a law, a rate filter) keeps its state in its
``store``: its arrays are views of it and its scalars sit at fixed slots, so that one compiled call
steps the whole controller on a few arrays (:func:`.controller.cascade_step`). In Python a scalar
still reads and writes as before (a float, None or a float, a bool, a tuple of floats) through a
:class:`Slot`. A part of a batch has no store (``store`` None) and keeps plain attributes.

:func:`rebind` moves the stores of several parts into one larger store (the controller's), their
values kept, so that the controller's kernel reaches every part's state through one array.
"""
from __future__ import annotations

import numpy as np

FLOAT, OPTIONAL, BOOL, TUPLE = 'float', 'optional', 'bool', 'tuple'


class Slot:
    """A scalar attribute kept in the instance's ``store`` at ``index`` (when it has a store), else a plain one.

    ``kind``: FLOAT (a float), OPTIONAL (None or a float: a flag at ``index``, the value after it), BOOL,
    or TUPLE (a tuple of floats of ``length(instance)`` values from ``index`` on).
    """

    def __init__(self, index: int, kind: str = FLOAT, length=None):
        self.index, self.kind, self.length = index, kind, length

    def __set_name__(self, owner, name: str) -> None:
        self.plain = f'{name}__plain'

    def __get__(self, instance, owner=None):
        if instance is None:
            return self
        store = instance.store
        if store is None:
            return instance.__dict__[self.plain]
        i = self.index
        if self.kind == FLOAT:
            return float(store[i])
        if self.kind == OPTIONAL:
            return float(store[i + 1]) if store[i] != 0.0 else None
        if self.kind == BOOL:
            return bool(store[i])
        return tuple(store[i:i + self.length(instance)].tolist())

    def __set__(self, instance, value) -> None:
        store = instance.store
        if store is None:
            instance.__dict__[self.plain] = value
            return
        i = self.index
        if self.kind == OPTIONAL:
            store[i] = 0.0 if value is None else 1.0
            store[i + 1] = 0.0 if value is None else value
        elif self.kind == TUPLE:
            store[i:i + self.length(instance)] = value
        else:
            store[i] = value


def rebind(parts, sizes) -> tuple[np.ndarray, np.ndarray]:
    """(one store holding every part's store in turn, the offset of each part in it): each part's values are
    copied into its slice and ``part.bind(slice)`` makes that slice its store. ``sizes``: each part's store size."""
    offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
    store = np.zeros(int(offsets[-1]))
    for part, start, end in zip(parts, offsets[:-1], offsets[1:]):
        view = store[start:end]
        view[:] = part.store
        part.bind(view)
    return store, offsets[:-1]
