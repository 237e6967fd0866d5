"""The per-sample guards that need no history: stamps, joints, shapes and finite values.

A sender's columns are reordered to the model's joint order by name (any order is accepted; the
orders seen are cached, at most 64 of them, so a bad sender cannot grow the cache forever).

A header stamp is judged by ``id_learning.header_stamps`` (``stamp_problem``), the rule the bag
readers use too.
"""

from __future__ import annotations

import math

import numpy as np

from id_learning.header_stamps import NS_PER_S
from id_learning.header_stamps import header_stamp_problem as stamp_problem
from id_learning.predictor.outcome import Reject
from id_learning.predictor.sample import ReferenceSample

__all__ = ['NS_PER_S', 'SampleCheck', 'stamp_problem']

#: The column order of a sender whose joint order is the model's (no reordering).
_IDENTITY = np.arange(0)
#: A sample's (q, v, a) in the model's joint order; a None when the sample carries none.
Checked = tuple[np.ndarray, np.ndarray, np.ndarray | None]


class SampleCheck:
    """Joints, shapes and finite values of one sample, in the model's joint order."""

    def __init__(self, joint_names: tuple[str, ...]) -> None:
        self.joint_names = joint_names
        self._n = len(joint_names)
        self._index = {name: k for k, name in enumerate(joint_names)}
        self._orders: dict[tuple[str, ...], np.ndarray | None] = {}

    def _order(self, names: tuple[str, ...]) -> np.ndarray | None:
        order = self._orders.get(names)
        if order is None and names not in self._orders:
            if names == self.joint_names:
                order = _IDENTITY
            elif len(names) == self._n and set(names) == set(self.joint_names):
                order = np.array([names.index(name) for name in self.joint_names])
            if len(self._orders) < 64:
                self._orders[names] = order
        return order

    def __call__(self, sample: ReferenceSample) -> Checked | tuple[Reject, str]:
        """(q, v, a) in the model's order, or (why, what) the sample is refused."""
        if sample.lacks is not None:
            return Reject.SHAPE, f'{sample.lacks}: no joint values to predict from'
        names = tuple(sample.names)
        if len(names) != self._n:
            return Reject.JOINT_COUNT, (
                f'{len(names)} joints {list(names)}, the model has {self._n}: '
                f'{list(self.joint_names)}'
            )
        order = self._order(names)
        if order is None:
            missing = [name for name in self.joint_names if name not in names]
            extra = [name for name in names if name not in self._index]
            return Reject.JOINT_NAMES, (
                f'joint names {list(names)} do not match the model '
                f'{list(self.joint_names)} (missing {missing}, unexpected {extra})'
            )
        arrays = [sample.q, sample.v] + ([] if sample.a is None else [sample.a])
        for label, values in zip(('q', 'v', 'a'), arrays, strict=False):
            if np.shape(values) != (self._n,):
                return Reject.SHAPE, (
                    f'{label} has shape {np.shape(values)}, expected ({self._n},): one value per '
                    'joint'
                )
            kind = np.asarray(values).dtype.kind
            if kind not in 'iuf':  # complex, bool, text or objects: no joint value
                return Reject.SHAPE, (
                    f'{label} holds {np.asarray(values).dtype} values, expected real numbers'
                )
        if order is _IDENTITY:  # the sender's order is the model's: no copy needed
            q, v = np.asarray(sample.q, float), np.asarray(sample.v, float)
            a = None if sample.a is None else np.asarray(sample.a, float)
        else:
            q, v = np.asarray(sample.q, float)[order], np.asarray(sample.v, float)[order]
            a = None if sample.a is None else np.asarray(sample.a, float)[order]
        # One test of all values first (a sum is finite only if every term is); the
        # per-quantity search runs only when it fails.
        total = np.add.reduce(q) + np.add.reduce(v) + (0.0 if a is None else np.add.reduce(a))
        if not math.isfinite(total):
            checks: tuple[tuple[str, np.ndarray | None], ...] = (('q', q), ('v', v), ('a', a))
            for label, checked in checks:
                if checked is not None and not np.isfinite(checked).all():
                    j = int(np.argmax(~np.isfinite(checked)))
                    return Reject.NON_FINITE, f'{label} of {self.joint_names[j]} is {checked[j]}'
        return q, v, a
