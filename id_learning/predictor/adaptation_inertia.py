"""Online adaptation of the whole linear-in-parameters physics: friction and the rigid body.

tau_u = model + sum_j theta_j . [tanh(v_j / v_eps), v_j, 1] + Y_base(q, v, a) delta_beta:
per joint a Coulomb level, a viscous coefficient and an offset (as ``FrictionAdapter``), and a
change delta_beta of the robot's base inertial parameters (``physics.base_parameters``), shared
by every joint (a tool change, a payload the model did not see). All of them are estimated
together, by one recursive least squares with a vector output (every joint of a sample at once,
each weighted by its running error scale): estimated apart, the friction offsets would chase
the slowly varying gravity error along the motion and the two would never settle. The
correction is clipped per joint to ``bound_share`` of its torque limit. A sample with any joint
beyond the gate is not learnt from (the outputs share the parameters); the covariance
safeguards are ``stabilised``; the estimate stays within ``ESTIMATE_PRIOR_STDS`` prior standard
deviations and the error scale within the torque limit (as the friction adapter's).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from id_learning.errors import ConfigError
from id_learning.physics.base_parameters import base_parameters
from id_learning.physics.friction import coulomb
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.predictor.adaptation_store import ESTIMATE_PRIOR_STDS
from id_learning.robot.config import RobotConfig

__all__ = ['InertiaAdapter', 'stabilised']

#: Prior standard deviation of each base parameter's change: this share of its nominal value
#: plus ``_PRIOR_FLOOR`` (SI units), so that parameters the URDF sets to zero can move too.
_PRIOR_SHARE = 0.1
_PRIOR_FLOOR = 1.0


@dataclass
class InertiaAdapter:
    """Vector-output RLS on friction terms and a change of the base inertial parameters.

    Args:
        robot: the robot config (URDF, limits, drives).
        joints: the joint order of the samples (the model's).
        period_s: the update period [s].
        time_constant_s: memory of the forgetting factor [s].
        bound_share: the correction per joint is clipped to this share of its torque limit.
        smoothing_velocity: v_eps of the Coulomb columns [rad/s].
        gate_sigmas: a sample with a joint's error beyond this many error scales is not learnt.
        friction_prior: prior std of the friction terms, as a share of the torque limit (and of
            it over the velocity limit for viscous).
        max_variance: cap on each parameter's variance, as a multiple of its prior one.

    Raises:
        ConfigError: ``joints`` are not the robot's joints (in any order).
    """

    robot: RobotConfig
    joints: tuple[str, ...]
    period_s: float
    time_constant_s: float
    bound_share: float
    smoothing_velocity: float = 0.01
    gate_sigmas: float = 6.0
    friction_prior: float = 0.01
    max_variance: float = 1.0
    updates: int = field(default=0, init=False)
    gated: int = field(default=0, init=False)
    resets: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        """Find the base parameters and start at no change with the prior covariance."""
        dynamics = RigidBodyDynamics.from_config(self.robot)
        base = base_parameters(dynamics, self.robot.limits)
        self.names = base.names
        if sorted(self.joints) != sorted(self.robot.joints):
            raise ConfigError(
                f'rigid-body adaptation needs every joint of robot {self.robot.name} '
                f'{list(self.robot.joints)}; the model has {list(self.joints)}'
            )
        order = [self.robot.joints.index(name) for name in self.joints]
        self._order = order
        self._base = dynamics.sample_regressor(base.independent)
        n = len(order)
        limit = self.robot.limits.torque[order]
        friction_std = self.friction_prior * np.stack(
            [limit, limit / self.robot.limits.velocity[order], limit], axis=1
        ).reshape(-1)
        nominal = base.matrix @ dynamics.inertial_parameters()
        body_std = _PRIOR_SHARE * np.abs(nominal) + _PRIOR_FLOOR
        self._p0 = np.diag(np.concatenate([friction_std, body_std]) ** 2)
        #: How far the estimate may go (3n + p,), and the error scale (n,).
        self.estimate_limit = ESTIMATE_PRIOR_STDS * np.concatenate([friction_std, body_std])
        self.error_scale_limit = limit
        self.covariance = self._p0.copy()
        self.estimate = np.zeros(3 * n + base.count)
        self.forgetting = 1.0 - self.period_s / self.time_constant_s
        self.limit = self.bound_share * limit
        self.error_scale = 0.02 * limit

    def regressor(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """(n, 3n + p) columns of one sample: friction blocks, then the base regressor."""
        n = len(v)
        out = np.zeros((n, 3 * n + len(self.names)))
        rows = np.arange(n)
        out[rows, 3 * rows] = coulomb(v, self.smoothing_velocity)
        out[rows, 3 * rows + 1] = v
        out[rows, 3 * rows + 2] = 1.0
        order = self._order
        robot = [_in_robot_order(x, order) for x in (q, v, a)]
        out[:, 3 * n :] = self._base(*robot)[order]
        return out

    @property
    def friction(self) -> np.ndarray:
        """(n, 3) the friction terms: Coulomb [N*m], viscous [N*m*s/rad], offset [N*m]."""
        return self.estimate[: 3 * len(self._order)].reshape(-1, 3)

    @property
    def change(self) -> np.ndarray:
        """(p,) the change of each base parameter (SI units)."""
        return self.estimate[3 * len(self._order) :]

    def correction(self, regressor: np.ndarray) -> np.ndarray:
        """(n,) tau_u to add for a sample's columns (n, 3n + p), clipped per joint [N*m]."""
        return np.clip(regressor @ self.estimate, -self.limit, self.limit)

    def update(self, regressor: np.ndarray, residual: np.ndarray, *, stale: bool = False) -> bool:
        """Learn from one sample: the measured tau_u less the model's (n,); whether it learnt.

        Nothing is learnt from stale or non-finite input, or when a joint's error is beyond the
        gate (the error scale still learns, clipped to the gate).
        """
        if stale or not np.isfinite(residual.sum() + regressor.sum()):
            return False
        lam = self.forgetting
        error = residual - regressor @ self.estimate
        limit = self.gate_sigmas * self.error_scale
        clipped = np.minimum(np.abs(error), limit)
        self.error_scale = np.minimum(
            np.sqrt(lam * self.error_scale**2 + (1 - lam) * clipped**2), self.error_scale_limit
        )
        if not (np.abs(error) <= limit).all():  # a NaN error is gated too
            self.gated += 1
            return False
        p_yt = self.covariance @ regressor.T  # (m, n)
        innovation = lam * np.diag(self.error_scale**2) + regressor @ p_yt
        gain = np.linalg.solve(innovation, p_yt.T).T  # P Y^T S^-1, S symmetric
        estimate = np.clip(self.estimate + gain @ error, -self.estimate_limit, self.estimate_limit)
        if not np.isfinite(estimate).all():  # never carry a broken estimate into a torque
            self.resets += 1
            self.estimate, self.covariance = np.zeros_like(estimate), self._p0.copy()
            return False
        self.estimate = estimate
        covariance = (self.covariance - gain @ p_yt.T) / lam
        stable, resets = stabilised(covariance[None], self._p0[None], self.max_variance)
        self.covariance = stable[0]
        self.resets += resets
        self.updates += 1
        return True

    def restore(self, estimate: np.ndarray, error_scale: np.ndarray) -> None:
        """Continue from a stored estimate (3n + p,) and error scale (n,); the prior covariance."""
        self.estimate = np.array(estimate, dtype=float)
        self.error_scale = np.array(error_scale, dtype=float)

    def state(self) -> dict[str, Any]:
        """The estimated friction terms and base-parameter changes, JSON-ready."""
        return {
            'theta': self.friction.tolist(),
            'error_scale_nm': self.error_scale.tolist(),
            'base_parameters': list(self.names),
            'change': self.change.tolist(),
            'updates': self.updates,
            'gated_samples': self.gated,
            'covariance_resets': self.resets,
        }


def stabilised(
    covariance: np.ndarray, prior: np.ndarray, max_variance: float = 1.0
) -> tuple[np.ndarray, int]:
    """RLS covariances (k, m, m) made safe to carry on, and how many had to start afresh.

    Rounding makes the update drift from symmetry, and forgetting amplifies it until the
    covariance is indefinite and the estimate diverges (after ~10^5 updates): each is made
    symmetric, and one that still lost definiteness starts again from its ``prior``. Forgetting
    without excitation (a joint at rest, a parameter the path does not reach) winds a variance
    up: each is capped at ``max_variance`` times its prior one, by scaling its row and column,
    so that the excited directions keep forgetting (a cap on the trace would take their share).
    """
    covariance = 0.5 * (covariance + np.swapaxes(covariance, 1, 2))
    diagonal = np.einsum('jii->ji', covariance)
    if not (np.isfinite(covariance.sum()) and (diagonal > 0).all()):
        broken = ~np.isfinite(covariance).all(axis=(1, 2)) | (diagonal <= 0).any(axis=1)
        covariance[broken] = prior[broken]
        resets = int(np.count_nonzero(broken))
        diagonal = np.einsum('jii->ji', covariance)
    else:
        resets = 0
    limit = max_variance * np.einsum('jii->ji', prior)
    shrink = np.sqrt(np.minimum(1.0, limit / diagonal))
    covariance *= shrink[:, :, None] * shrink[:, None, :]
    return covariance, resets


def _in_robot_order(x: np.ndarray, order: list[int]) -> np.ndarray:
    out = np.empty(len(order))
    out[order] = x
    return out
