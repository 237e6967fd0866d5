"""Pairing each prediction with the measured currents of the same stamp, whichever comes first.

The drive's currents of an IPO cycle carry the cycle's stamp, as the prediction served for it
does; which of the two reaches the predictor first is not fixed. A drive reports its currents
after the command it was given (the prediction first); a replay of a bag publishes each cycle's
recorded currents before the reference it builds for that cycle (the currents first). So each
side waits for the other in a bounded buffer:

- a prediction waits ``prediction_capacity`` cycles (a drive's reporting delay, up to seconds);
- a current waits ``measured_capacity`` cycles (the reference that follows it, even one DDS
  delivers late: right after the predictor subscribes to the reference, reliable repair brought
  the first references of a replay 10 to 20 cycles after their currents on a loaded machine).

An entry pushed out of its buffer has expired: a prediction quietly (nothing measures every
cycle served: a predictor may run with no drive answering), a current counted as unpaired, with
its stamp kept for the offset to the nearest waiting prediction (``offset_ns``): what a user
needs to see why pairing fails. Only equal stamps pair.

The oldest *arrival* is pushed out, not the smallest stamp: after the time base steps back (a
replay's loop, a restarted simulation) the new stamps are the smallest ones, and pushing out by
stamp would drop each new entry at once while the stale ones stayed for good. Within the
buffers, where stamps arrive in order give or take the jitter, the two are the same.

Plain Python (no numpy, no ROS): the items are whatever the caller pairs.
"""

from __future__ import annotations

from typing import Generic, TypeVar

__all__ = ['MEASURED_CAPACITY', 'PREDICTION_CAPACITY', 'StampPairing']

#: Predictions kept waiting for their currents [cycles]: 4 s at the 8 ms IPO period.
PREDICTION_CAPACITY = 512
#: Currents kept waiting for their prediction [cycles]: as many as the predictor's currents
#: subscription queues (0.5 s), room for a reference that DDS delivers late.
MEASURED_CAPACITY = 64

P = TypeVar('P')
M = TypeVar('M')


class StampPairing(Generic[P, M]):
    """Two bounded buffers, one per side, that hand out a pair when a stamp's second side comes.

    Args:
        prediction_capacity: predictions kept waiting [entries].
        measured_capacity: currents kept waiting [entries].

    Raises:
        ValueError: a capacity below 1.
    """

    def __init__(
        self,
        prediction_capacity: int = PREDICTION_CAPACITY,
        measured_capacity: int = MEASURED_CAPACITY,
    ) -> None:
        """Start with nothing waiting."""
        if prediction_capacity < 1 or measured_capacity < 1:
            raise ValueError(
                f'capacities must be at least 1, got {prediction_capacity} (predictions) and '
                f'{measured_capacity} (currents)'
            )
        self.prediction_capacity = prediction_capacity
        self.measured_capacity = measured_capacity
        # Dicts keep insertion order: the first key is the oldest arrival.
        self._predictions: dict[int, P] = {}
        self._measured: dict[int, M] = {}
        #: Pairs handed out.
        self.paired = 0
        #: Currents that expired unpaired, and predictions that did.
        self.unpaired = 0
        self.expired_predictions = 0
        #: Currents expired since the last pair (how long pairing has kept failing).
        self.unpaired_streak = 0
        #: The stamp of the latest current that expired unpaired [ns]; None: none has.
        self.last_unpaired_stamp_ns: int | None = None

    def predicted(self, stamp_ns: int, item: P) -> tuple[P, M] | None:
        """Take a prediction; the pair if its current waits, else None (it waits in turn).

        A second prediction of a stamp that waits replaces the first (the later one was served).
        """
        if stamp_ns in self._measured:
            return self._paired(item, self._measured.pop(stamp_ns))
        waiting = self._predictions
        waiting.pop(stamp_ns, None)  # a replacement arrives now: it goes to the end
        waiting[stamp_ns] = item
        if len(waiting) > self.prediction_capacity:
            del waiting[next(iter(waiting))]
            self.expired_predictions += 1
        return None

    def measured(self, stamp_ns: int, item: M) -> tuple[P, M] | None:
        """Take a current; the pair if its prediction waits, else None (it waits in turn).

        A second current of a stamp that waits replaces the first, which counts as unpaired.
        """
        if stamp_ns in self._predictions:
            return self._paired(self._predictions.pop(stamp_ns), item)
        waiting = self._measured
        if stamp_ns in waiting:  # the replacement arrives now: it goes to the end
            del waiting[stamp_ns]
            self._expire(stamp_ns)
        waiting[stamp_ns] = item
        if len(waiting) > self.measured_capacity:
            oldest = next(iter(waiting))
            del waiting[oldest]
            self._expire(oldest)
        return None

    def _paired(self, prediction: P, current: M) -> tuple[P, M]:
        self.paired += 1
        self.unpaired_streak = 0
        return prediction, current

    def _expire(self, stamp_ns: int) -> None:
        self.unpaired += 1
        self.unpaired_streak += 1
        self.last_unpaired_stamp_ns = stamp_ns

    @property
    def waiting(self) -> tuple[int, int]:
        """(predictions, currents) waiting now."""
        return len(self._predictions), len(self._measured)

    def offset_ns(self) -> int | None:
        """The latest unpaired current's stamp minus the nearest waiting prediction's [ns].

        None when no current has expired or no prediction waits (none was served to learn from).
        """
        stamp = self.last_unpaired_stamp_ns
        if stamp is None or not self._predictions:
            return None
        nearest = min(self._predictions, key=lambda waiting: abs(waiting - stamp))
        return stamp - nearest
