"""The span of absolute times the importer keeps is stated as the code bounds it."""

from __future__ import annotations

from datetime import UTC, datetime

from id_learning.dataset import import_stamps
from id_learning.dataset.import_stamps import _EPOCH_SPAN_S, absolute_start_ns


def _date(seconds: int) -> str:
    return datetime.fromtimestamp(seconds, UTC).date().isoformat()


def test_the_docstrings_name_the_bounds_absolute_start_ns_applies() -> None:
    low, high = (_date(bound) for bound in _EPOCH_SPAN_S)
    assert (low, high) == ('2000-01-01', '2038-01-19')  # int32 seconds of a message stamp
    for text in (import_stamps.__doc__, absolute_start_ns.__doc__):
        assert text is not None
        words = ' '.join(text.split())
        assert '2000' in words
        assert '2038' in words
        assert '2100' not in words
