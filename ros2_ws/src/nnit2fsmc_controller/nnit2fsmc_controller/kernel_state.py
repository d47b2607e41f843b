"""State a compiled kernel reads and writes in place: one flat float array, a *store*.

A single-vehicle part of a controller (today the NNIT2FSMC law and its network) keeps its state in its
``store``: its arrays are views of it and its scalars sit at fixed slots, so that one compiled call
steps it on two arrays (its store and its constants: :func:`.axis_laws.nnit2fsmc_law_step`) instead of a
dozen arguments numba must type one by one. In Python a scalar still reads and writes as before (a
float, None or a float, a bool, a tuple of floats) through a :class:`Slot`, so the node, a retune
(:mod:`.tuning`) and the tests see the same attributes. A part of a batch has no store (``store``
None) and keeps plain attributes. A part's store can be a slice of a larger one (``bind``): the way
towards one compiled step of the whole controller (docs/SPEED.md).
"""
from __future__ import annotations

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

