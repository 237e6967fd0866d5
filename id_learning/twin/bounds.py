"""How long a simulation may be, and how coarse its sensors and how far off its robot may be.

The twin keeps every sample in memory until the bag is written (the motion, each torque
component, the currents and the ground truth): about ``BYTES_PER_SAMPLE_JOINT`` bytes per
sample and joint, measured on the default twin (8 ms IPO period, 6 joints: 480 s peak at 209 MB,
60 s at 117 MB, so 300 B per sample and joint, with a margin on top). A duration is refused
above ``MAX_DURATION_S`` or where it would need more than ``MEMORY_SHARE`` of the memory
available, before any work starts, instead of swapping for hours or being killed.

The sensors must leave the signals measurable (``check_measurement``): a current quantisation
step or a noise of a large share of a joint's full scale is refused, naming the key. The
robot's drawn link masses must stay positive (``check_drawn_masses``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from id_learning.config_io import finite_number
from id_learning.errors import ConfigError
from id_learning.memory import available_memory_bytes
from id_learning.record.excitation import ExcitationConfig, check_bandwidth
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import amperes_per_newton_metre

__all__ = [
    'BYTES_PER_SAMPLE_JOINT',
    'MAX_DURATION_S',
    'MAX_NOISE_SHARE',
    'MAX_RESOLUTION_SHARE',
    'MEMORY_SHARE',
    'available_memory_bytes',
    'check_drawn_masses',
    'check_duration',
    'check_excitation',
    'check_measurement',
]

#: The longest excitation the twin simulates [s]: one day of recording.
MAX_DURATION_S = 86_400.0
#: Memory the twin holds per sample and joint until the bag is written [bytes].
BYTES_PER_SAMPLE_JOINT = 384
#: The share of the available memory one simulation may take.
MEMORY_SHARE = 0.5
#: The coarsest current quantisation step, as a share of each joint's full-scale current (the
#: current at its torque limit, tau_max / (N k_t)): 1 % leaves 200 steps across +-I_max, where a
#: drive's 12-bit current measurement has 4096. Coarser, the currents are recorded as a few
#: steps, or all 0 (a 50 A step on the MABI, whose full scale is 8 to 33 A).
MAX_RESOLUTION_SHARE = 0.01
#: The largest white noise (std) of a measured signal, as a share of its full scale (the current
#: or joint torque at the torque limit, the velocity limit): the friction, cogging and offsets
#: the twin exists to simulate are a few % of the torque limit, and a noise above 10 % of it
#: hides them in every sample (real drives: well under 1 %).
MAX_NOISE_SHARE = 0.1


def check_duration(
    duration_s: object, period_s: float, n_joints: int, where: str, available: int | None = None
) -> float:
    """``duration_s`` as a float when the twin can simulate it here.

    Args:
        duration_s: the excitation's length [s].
        period_s: the robot's IPO period [s].
        n_joints: the robot's joint count.
        where: the key or option named in errors (``excitation.duration_s``, ``--duration``).
        available: memory available [bytes]; None reads it from the system.

    Raises:
        ConfigError: not a finite number in (0, MAX_DURATION_S], or more samples than
            MEMORY_SHARE of the available memory holds (names the bound in seconds).
    """
    duration = finite_number(duration_s, where, low=0.0, high=MAX_DURATION_S, low_open=True)
    available = available_memory_bytes() if available is None else available
    if available is None:
        return duration
    per_second = n_joints * BYTES_PER_SAMPLE_JOINT / period_s
    need = (duration / period_s + 1) * n_joints * BYTES_PER_SAMPLE_JOINT
    budget = MEMORY_SHARE * available
    if need > budget:
        raise ConfigError(
            f'{where}: {duration:g} s at the {period_s * 1e3:g} ms IPO period would need about '
            f'{need / 2**30:.1f} GiB, more than {MEMORY_SHARE:.0%} of the '
            f'{available / 2**30:.1f} GiB of memory available: at most '
            f'{max(budget / per_second - period_s, 0.0):.0f} s fit on this machine; simulate '
            'shorter runs'
        )
    return duration


#: The excitation's numbers and their ranges: (low, high, low_open, integer).
_EXCITATION_RANGES: dict[str, tuple[float, float | None, bool, bool]] = {
    'base_frequency_hz': (0.0, None, True, False),
    'harmonics': (1, 10, False, True),
    'position_fraction': (0.0, 1.0, True, False),
    'velocity_fraction': (0.0, 1.0, True, False),
    'acceleration_fraction': (0.0, 1.0, True, False),
    'rest_s': (0.0, MAX_DURATION_S, False, False),
}


def check_excitation(
    data: dict[str, Any], period_s: float, n_joints: int, where: str
) -> dict[str, Any]:
    """The excitation section with each number checked finite and in range (home aside).

    Raises:
        ConfigError: names the key (``where.key``), the value and the allowed range; harmonics
            at or above the IPO period's Nyquist frequency (``check_bandwidth``); a duration
            beyond what ``check_duration`` allows.
    """
    checked = dict(data)
    for key, (low, high, low_open, integer) in _EXCITATION_RANGES.items():
        if key in data:
            checked[key] = finite_number(
                data[key], f'{where}.{key}', low=low, high=high, low_open=low_open, integer=integer
            )
    defaults = ExcitationConfig()
    check_bandwidth(
        checked.get('base_frequency_hz', defaults.base_frequency_hz),
        checked.get('harmonics', defaults.harmonics),
        period_s,
        where,
    )
    if 'duration_s' in data:
        checked['duration_s'] = check_duration(
            data['duration_s'], period_s, n_joints, f'{where}.duration_s'
        )
    return checked


def check_measurement(values: dict[str, np.ndarray], robot: RobotConfig, where: str) -> None:
    """Refuse sensors that leave a signal unmeasurable: too coarse or too noisy.

    Args:
        values: the measurement keys (``current_resolution_a``, ``current_noise_std_a``,
            ``joint_torque_noise_std``, ``velocity_noise_std``), (n,) each, in their units.
        robot: the robot whose limits and drives give each joint's full scale.
        where: the config file, named in errors.

    Raises:
        ConfigError: names the key, the joint, the value, the full scale and the most allowed.
    """
    current = robot.limits.torque * amperes_per_newton_metre(robot.drives)
    bounds = {  # key: (share, full scale (n,), unit, the full scale in words, what goes wrong)
        'current_resolution_a': (MAX_RESOLUTION_SHARE, current, 'A', 'its current at the '
                                 'torque limit', 'the currents would be recorded as a few '
                                 'steps, or all 0'),
        'current_noise_std_a': (MAX_NOISE_SHARE, current, 'A', 'its current at the torque limit',
                                'the noise would hide the effects in the currents'),
        'joint_torque_noise_std': (MAX_NOISE_SHARE, robot.limits.torque, 'N*m', 'its torque '
                                   'limit', 'the noise would hide the effects in the torques'),
        'velocity_noise_std': (MAX_NOISE_SHARE, robot.limits.velocity, 'rad/s', 'its velocity '
                               'limit', 'the noise would hide the motion'),
    }  # fmt: skip
    for key, (share, scale, unit, full, consequence) in bounds.items():
        over = np.flatnonzero(np.asarray(values[key]) > share * scale)
        if over.size:
            j = int(over[0])
            raise ConfigError(
                f'{where}: measurement.{key}: {values[key][j]:g} {unit} for {robot.joints[j]} is '
                f'more than {share:.0%} of {full} ({scale[j]:.4g} {unit}): {consequence}; give '
                f'at most {share * scale[j]:.3g} {unit}'
            )


def check_drawn_masses(
    urdf_masses: np.ndarray,
    drawn: np.ndarray,
    bodies: list[str],
    *,
    mass_rel_std: float,
    robot_seed: int,
    where: str,
) -> None:
    """Refuse a draw of the inertial parameter error that gives a body a mass <= 0.

    Args:
        urdf_masses: (bodies,) the URDF's masses [kg].
        drawn: (bodies,) the twin's masses [kg], drawn from them.
        bodies: the joint that moves each body.
        mass_rel_std: the relative standard deviation they were drawn with.
        robot_seed: the seed of the draw.
        where: the config file, named in errors.

    Raises:
        ConfigError: names the key, its value, the body, both masses and the seed.
    """
    bad = np.flatnonzero((urdf_masses > 0) & (drawn <= 0))
    if bad.size:
        k = int(bad[0])
        raise ConfigError(
            f'{where}: effects.inertial_parameter_error.mass_rel_std: {mass_rel_std:g} draws a '
            f'mass of {drawn[k]:.3g} kg for the body moved by {bodies[k]} ({urdf_masses[k]:.3g} '
            f'kg in the URDF) with robot_seed {robot_seed}: no body has one; lower '
            'mass_rel_std or choose another robot_seed'
        )
