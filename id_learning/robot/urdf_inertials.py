"""The URDF's link inertias, checked where a robot config names the URDF.

A link with mass is a rigid body of finite size: its rotational inertia about the centre of
mass is positive definite and its principal moments obey the triangle inequality
(I1 + I2 >= I3). An all-zero inertia under a mass of many kilograms is a URDF written without
inertias: the twin, the identification and every physics prior would run on a wrong model
without a word. A massless link (a frame) carries no inertia.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from id_learning.errors import RobotModelError

__all__ = ['check_urdf_inertials']

_KEYS = ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz')
#: Relative tolerance of the checks on principal moments (rounding of the eigenvalues).
_TOLERANCE = 1e-9


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


def check_urdf_inertials(urdf: Path | str) -> None:
    """Refuse a link no rigid body can be, naming the file and the link.

    Raises:
        RobotModelError: the URDF is unreadable; a mass that is not finite and >= 0; a massless
            link with inertia; a link with mass whose inertia is not positive definite (all
            zero, say) or breaks the triangle inequality.
    """
    urdf = Path(urdf)
    try:
        root = ElementTree.parse(urdf).getroot()
    except (OSError, ElementTree.ParseError) as err:
        raise RobotModelError(f'{urdf}: cannot read the URDF: {err}') from err
    for link in root.iter('link'):
        found = _link_inertial(link, urdf)
        if found is None:
            continue
        name, (mass, inertia) = link.get('name', '?'), found
        if not (math.isfinite(mass) and mass >= 0 and np.isfinite(inertia).all()):
            raise RobotModelError(
                f'{urdf}: link {name}: mass {mass:g} kg and inertia must be finite, the mass >= 0'
            )
        moments = np.linalg.eigvalsh(inertia)
        largest = float(np.abs(moments).max())
        if mass == 0:
            if largest > 0:
                raise RobotModelError(
                    f'{urdf}: link {name}: a massless link with inertia '
                    f'{np.round(moments, 9).tolist()} kg*m^2; give it its mass or no inertia'
                )
            continue
        if moments[0] <= _TOLERANCE * largest:
            what = 'all zero' if largest == 0 else 'not positive definite'
            raise RobotModelError(
                f'{urdf}: link {name}: mass {mass:g} kg with principal moments '
                f'{np.round(moments, 9).tolist()} kg*m^2 ({what}); a body with mass has three '
                'positive moments: give its inertia about the centre of mass, or mass 0 for a '
                'frame'
            )
        if moments[0] + moments[1] < moments[2] * (1 - _TOLERANCE):
            raise RobotModelError(
                f'{urdf}: link {name}: principal moments {np.round(moments, 9).tolist()} kg*m^2 '
                'break the triangle inequality I1 + I2 >= I3 of a rigid body'
            )
