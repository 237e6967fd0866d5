"""The command stream: tau_u as a forward command controller gets it, ramped around stale episodes.

With ``command_topic`` the predictor node sends each tau_u it publishes as a command too. A
forward command controller holds its last command until the next, so when the reference goes
stale the command must not stay at a stale torque; nor may it drop to zero, or come back from
there, in one message (that would be a jolt of the whole torque). The command stream therefore
moves by at most one IPO period's worth of the slew limit per message,

    |command_k - command_(k-1)| <= slew * T    per joint,    slew = torque limit / torque_rise_s,

T the IPO period: no more than the controller may apply in one cycle (``predictor.output`` gives
tau_u the same bound per period of its stamps). It

- follows tau_u while the reference is live: the same torque, unless tau_u stepped further in one
  sample (after skipped cycles or a silence its bound spans more than one period), in which case
  the command catches up over the next messages;
- ramps to zero once the reference is stale (``zero_command_on_stale``): one command per IPO
  period, each one step closer to zero, the last exactly zero; a command at the torque limit
  reaches zero within ceil(torque_rise_s / T) messages (7 at the defaults, 50 ms and 8 ms);
- ramps back from wherever the ramp has brought it when the reference resumes, towards tau_u at
  the same rate, until it has caught up (tau_u itself continues from its last published value).

The first command is the first tau_u: there is no command before it to move from. Every command
lies within the torque limits in force (``torque_limit_scale`` times the limits, the clamp
last): a limit lowered at runtime below the last command brings the next one to it at once, the
one step that may exceed the bound above.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from id_learning.predictor.feedforward import FeedForwardPredictor

__all__ = ['CommandStream']


class CommandStream:
    """The commands of one predictor core, slew-limited per message and ramped when stale.

    Args:
        core: the predictor whose tau_u is sent (its slew limit, period and stale flag are read
            at each message, so a runtime change of ``torque_rise_s`` applies at once).
        ramp_on_stale: ramp the command to zero when the reference goes stale; False: the last
            command stays (the controller holds it) and the stream continues from it.
    """

    def __init__(self, core: FeedForwardPredictor, ramp_on_stale: bool = True) -> None:
        self._core = core
        self.ramp_on_stale = ramp_on_stale
        #: The last command given to publish [N*m], or None before the first.
        self.last: np.ndarray | None = None
        #: A ramp to zero is under way (``ramp`` gives its commands).
        self.is_ramping = False

    @property
    def step(self) -> np.ndarray:
        """(n,) the largest change from one command to the next [N*m]: slew times one period."""
        step: np.ndarray = self._core.output.slew * self._core.config.period_s
        return step

    def _move(self, target: np.ndarray) -> np.ndarray:
        last = self.last
        if last is None:
            out = np.array(target, dtype=float)
        else:
            bound, change = self.step, target - last
            within = np.abs(change) <= bound  # those get the target exactly
            out = np.where(within, target, last + np.clip(change, -bound, bound))
        limit = self._core.output.limit  # the clamp last: a lowered limit holds at once
        clamped: np.ndarray = np.clip(out, -limit, limit)
        self.last = clamped
        return clamped

    def follow(self, tau: np.ndarray) -> np.ndarray:
        """The command for a published tau_u: moved towards it by at most ``step``."""
        self.is_ramping = False
        return self._move(np.asarray(tau, dtype=float))

    def went_stale(self) -> bool:
        """The reference has just gone stale; whether a ramp to zero starts.

        None starts without ``ramp_on_stale`` or before the first command (nothing to ramp).
        """
        self.is_ramping = self.ramp_on_stale and self.last is not None
        return self.is_ramping

    def ramp(self) -> np.ndarray | None:
        """The next command of the ramp to zero (call once per IPO period), or None.

        None: no ramp under way (it has reached zero, or the reference is live again).
        """
        if not self.is_ramping or self.last is None or not self._core.is_stale:
            self.is_ramping = False
            return None
        out = self._move(np.zeros_like(self.last))
        if not out.any():  # at zero: the ramp's last command
            self.is_ramping = False
        return out
