"""What makes a ROS header stamp (builtin_interfaces/Time) no time: one rule for every door.

``nanosec`` lies in [0, 1e9) and, for a time since 1970, ``sec`` >= 0; folded into nanoseconds
anything else reads as another time (``nanosec = 1.5e9`` is 1.5 s later) rather than a refused
one. The bag readers, inspect, the replay and the predictor all ask ``header_stamp_problem``; it
lives here, apart from both the bag and the predictor packages, so that neither loads the other.
"""

from __future__ import annotations

__all__ = ['NS_PER_S', 'header_stamp_problem']

NS_PER_S = 1_000_000_000


def header_stamp_problem(sec: int, nanosec: int) -> str | None:
    """What makes a header stamp no time, in words, or None for a valid one."""
    if not 0 <= nanosec < NS_PER_S:
        return f'nanosec {nanosec} is not in [0, 1e9) (sec {sec})'
    if sec < 0:
        return f'sec {sec} is negative (nanosec {nanosec}): before 1970'
    return None
