"""The URDF's link inertias, checked where a robot config names the URDF.

A link with mass is a rigid body of finite size: its rotational inertia about the centre of
mass is positive semi-definite and its principal moments obey the triangle inequality
(I1 + I2 >= I3). An all-zero inertia under a mass of many kilograms is a URDF written without
inertias: the twin, the identification and every physics prior would run on a wrong model
without a word. A massless link (a frame) carries no inertia.

Real URDFs bend these rules where it does not matter: a 0.1 mg gripper frame with a zero inertia
(Baxter), a 1 mg base with a tiny negative moment (ANYmal, TIAGo), hand links a little against
the triangle inequality (Allegro, PR2): of the 69 URDFs of example-robot-data, 29 do. So only a
link that carries weight, at least ``SIGNIFICANT_KG`` or ``SIGNIFICANT_SHARE`` of the robot's
mass, is refused for an all-zero or indefinite inertia (3 of the 69: iCub's 1.3 kg head without
inertia, Romeo's 5 kg body with a negative moment); everything else is said once, as a warning
naming the links, and the robot is loaded.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from id_learning.errors import RobotModelError

__all__ = ['SIGNIFICANT_KG', 'SIGNIFICANT_SHARE', 'check_urdf_inertials']

_LOG = logging.getLogger(__name__)
#: A link this heavy, or this share of the robot's mass, carries weight: its inertia must be one.
SIGNIFICANT_KG = 1.0
SIGNIFICANT_SHARE = 0.02

_KEYS = ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz')
#: Relative tolerance of the checks on principal moments (rounding of the eigenvalues).
_TOLERANCE = 1e-9
#: Principal moments below this are zero [kg*m^2] (a hand-written URDF's rounding).
_ZERO = 1e-12


def _link_inertial(link: ElementTree.Element, urdf: Path) -> tuple[float, np.ndarray] | None:
    """The link's mass [kg] and inertia matrix [kg*m^2], or None when it has no <inertial>."""
    inertial = link.find('inertial')
    if inertial is None:
        return None
    mass_element, tensor = inertial.find('mass'), inertial.find('inertia')
    try:
        mass = float(mass_element.get('value', 'nan')) if mass_element is not None else 0.0
        values = [float(tensor.get(k, 0.0)) if tensor is not None else 0.0 for k in _KEYS]
    except ValueError as err:
        raise RobotModelError(
            f'{urdf}: link {link.get("name", "?")}: unreadable <inertial>: {err}'
        ) from err
    ixx, ixy, ixz, iyy, iyz, izz = values
    return mass, np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def check_urdf_inertials(urdf: Path | str) -> list[str]:
    """Refuse a link no rigid body can be that carries weight; what else is off, as warnings.

    Returns:
        One line per link whose inertia is off but does not matter (also logged as a warning).

    Raises:
        RobotModelError: the URDF is unreadable; a mass that is not finite and >= 0; a link of
            significant mass whose inertia is all zero or has a negative principal moment.
    """
    urdf = Path(urdf)
    try:
        root = ElementTree.parse(urdf).getroot()
    except (OSError, ElementTree.ParseError) as err:
        raise RobotModelError(f'{urdf}: cannot read the URDF: {err}') from err
    links = []
    for link in root.iter('link'):
        found = _link_inertial(link, urdf)
        if found is None:
            continue
        name, (mass, inertia) = link.get('name', '?'), found
        if not (math.isfinite(mass) and mass >= 0 and np.isfinite(inertia).all()):
            raise RobotModelError(
                f'{urdf}: link {name}: mass {mass:g} kg and inertia must be finite, the mass >= 0'
            )
        links.append((name, mass, inertia))
    total = sum(mass for _, mass, _ in links)
    warnings = []
    for name, mass, inertia in links:
        problem = _problem(mass, inertia)
        if problem is None:
            continue
        significant = mass >= min(SIGNIFICANT_KG, SIGNIFICANT_SHARE * total) and problem[0]
        text = f'{urdf}: link {name}: {problem[1]}'
        if significant:
            raise RobotModelError(text)
        warnings.append(text)
    if warnings:
        _LOG.warning('%d URDF link(s) whose inertia bends the rigid-body rules where it cannot '
                     'mislead (too light, a thin rod, the triangle inequality): %s',
                     len(warnings), '; '.join(warnings))  # fmt: skip
    return warnings


def _problem(mass: float, inertia: np.ndarray) -> tuple[bool, str] | None:
    """(whether it is refused when the link carries weight, what is off), or None."""
    moments = np.linalg.eigvalsh(inertia)
    largest = float(np.abs(moments).max())
    shown = np.round(moments, 9).tolist()
    if mass == 0:
        if largest > 0:
            return False, f'a massless link with inertia {shown} kg*m^2 (a frame has none)'
        return None
    if largest <= _ZERO:
        return True, (
            f'mass {mass:g} kg with principal moments {shown} kg*m^2 (all zero); a body with '
            'mass has positive moments: give its inertia about the centre of mass, or mass 0 '
            'for a frame'
        )
    if moments[0] < -_TOLERANCE * largest - _ZERO:
        return True, (
            f'mass {mass:g} kg with principal moments {shown} kg*m^2 (not positive '
            'semi-definite); give its inertia about the centre of mass'
        )
    if moments[0] <= _TOLERANCE * largest:
        return False, f'mass {mass:g} kg with principal moments {shown} kg*m^2 (a thin rod)'
    if moments[0] + moments[1] < moments[2] * (1 - _TOLERANCE):
        return False, (
            f'principal moments {shown} kg*m^2 break the triangle inequality I1 + I2 >= I3 of '
            'a rigid body'
        )
    return None
