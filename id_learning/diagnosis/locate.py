"""Where the residual lives: per joint, against v, its sign, speed, q, a, load torque and time.

For each variable the residual's conditional mean over quantile bins is computed; the share of the
residual variance that the binned mean explains says how much of the disagreement that variable
organises (friction lives in velocity and its sign, a balancer in position, an inertia error in
acceleration, drift in time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['LOCATION_VARIABLES', 'JointLocation', 'locate_residual']

#: variable key -> (label, unit)
LOCATION_VARIABLES: dict[str, tuple[str, str]] = {
    'velocity': ('velocity', 'rad/s'),
    'velocity_sign': ('sign of velocity', '1'),
    'speed': ('speed |v|', 'rad/s'),
    'position': ('position', 'rad'),
    'acceleration': ('acceleration', 'rad/s^2'),
    'load_torque': ('nominal rigid-body torque', 'N*m'),
    'time': ('time', 's'),
}


@dataclass(frozen=True)
class JointLocation:
    """The residual of one joint against each variable.

    Attributes:
        joint: joint name.
        rms_nm: residual RMS [N*m].
        explained_share: variable -> share of the residual variance its binned mean explains.
        bins: variable -> (bin centres, binned mean residual [N*m], binned std [N*m]).
    """

    joint: str
    rms_nm: float
    explained_share: dict[str, float]
    bins: dict[str, tuple[list[float], list[float], list[float]]]

    def dominant(self) -> str:
        """The variable that organises most of the residual."""
        return max(self.explained_share, key=lambda key: self.explained_share[key])


#: A residual's mean against a variable: bin centres, means and standard deviations.
BinnedCurve = tuple[list[float], list[float], list[float]]


def _binned(x: np.ndarray, r: np.ndarray, n_bins: int) -> tuple[float, BinnedCurve]:
    total = float(np.sum((r - r.mean()) ** 2))
    if x.size < 2 * n_bins or np.ptp(x) == 0 or total == 0:  # nothing to organise
        return 0.0, ([], [], [])
    levels = np.unique(x)
    if levels.size <= 3:  # a discrete variable (the sign of v): one bin per value
        which = np.searchsorted(levels, x)
        edges = np.arange(levels.size + 1)
    else:
        edges = np.unique(np.quantile(x, np.linspace(0, 1, n_bins + 1)))
        which = np.clip(np.searchsorted(edges, x, side='right') - 1, 0, len(edges) - 2)
    centres: list[float] = []
    means: list[float] = []
    stds: list[float] = []
    fitted = np.empty_like(r)
    for b in range(len(edges) - 1):
        inside = which == b
        if not inside.any():
            continue
        fitted[inside] = r[inside].mean()
        centres.append(float(np.median(x[inside])))
        means.append(float(r[inside].mean()))
        stds.append(float(r[inside].std()))
    explained = 1.0 - float(np.sum((r - fitted) ** 2)) / total
    # Many bins explain a little even of pure noise; the expected share there is (bins-1)/N_eff,
    # so small shares are not shown as structure.
    return max(explained, 0.0), (centres, means, stds)


def locate_residual(
    residual: np.ndarray,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    *,
    load: np.ndarray,
    t: np.ndarray,
    joints: tuple[str, ...],
    n_bins: int = 24,
) -> list[JointLocation]:
    """Bin each joint's residual against the variables of ``LOCATION_VARIABLES``.

    Args:
        residual: (N, n) measured minus nominal torque [N*m] (filtered).
        q, v, a: (N, n) filtered motion [rad, rad/s, rad/s^2].
        load: (N, n) nominal rigid-body torque [N*m].
        t: (N,) time [s].
        joints: joint names.
        n_bins: quantile bins per variable.
    """
    out = []
    for j, joint in enumerate(joints):
        r = residual[:, j]
        variables = {
            'velocity': v[:, j],
            'velocity_sign': np.sign(v[:, j]),
            'speed': np.abs(v[:, j]),
            'position': q[:, j],
            'acceleration': a[:, j],
            'load_torque': load[:, j],
            'time': t,
        }
        shares, bins = {}, {}
        for key, x in variables.items():
            share, curve = _binned(x, r, 2 if key == 'velocity_sign' else n_bins)
            shares[key] = share
            bins[key] = curve
        out.append(JointLocation(joint, float(np.sqrt(np.mean(r**2))), shares, bins))
    return out
