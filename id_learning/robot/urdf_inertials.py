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
inertia, Romeo's 5 kg body with a negative moment); everything else is said, one warning line
per link saying what the model gets wrong, and the robot is loaded.

``urdf_checks.check_urdf`` adds what needs the robot config (which links move, which joints are
driven); this module looks at each link alone.
"""

from __future__ import annotations

import codecs
import logging
import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from id_learning.config_io import read_capped
from id_learning.errors import ConfigError, RobotModelError

__all__ = [
    'SIGNIFICANT_KG',
    'SIGNIFICANT_SHARE',
    'Inertial',
    'check_urdf_inertials',
    'inertia_problems',
    'link_inertials',
    'parse_urdf',
    'principal_moments_problem',
    'read_urdf',
]

_LOG = logging.getLogger(__name__)
#: A link this heavy, or this share of the robot's mass, carries weight: its inertia must be one.
SIGNIFICANT_KG = 1.0
SIGNIFICANT_SHARE = 0.02

_KEYS = ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz')
#: Relative tolerance of the checks on principal moments (rounding of the eigenvalues).
_TOLERANCE = 1e-9
#: Principal moments below this are zero [kg*m^2] (a hand-written URDF's rounding).
_ZERO = 1e-12

#: A link's mass [kg] and rotational inertia about its centre of mass [kg*m^2].
Inertial = tuple[float, np.ndarray]


def read_urdf(urdf: Path | str) -> bytes:
    """The URDF's bytes, read through the capped reader (``config_io.read_capped``).

    A regular file only: the URDF is read more than once (its checks, its hash, pinocchio), and
    a pipe gives its text once.

    Raises:
        RobotModelError: the file is missing, no regular file (a FIFO, a device), over
            ``MAX_CONFIG_BYTES``, or not UTF-8.
    """
    try:
        data = read_capped(urdf, 'URDF', regular=True)
    except ConfigError as err:
        raise RobotModelError(str(err)) from None
    # urdfdom (pinocchio's parser) reads UTF-8 only; XML in UTF-16 parses here but not there.
    wide = (codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE, codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)
    if data.startswith(wide) or b'\x00' in data[:256]:
        raise RobotModelError(
            f'{urdf}: the URDF is UTF-16 or UTF-32 text; URDF parsers read UTF-8: convert it '
            '(iconv -f UTF-16 -t UTF-8 and an encoding="UTF-8" declaration)'
        )
    try:
        data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise RobotModelError(
            f'{urdf}: the URDF is not UTF-8 text (byte {err.start} is {data[err.start]:#04x}); '
            'save it as UTF-8'
        ) from None
    return data


def parse_urdf(urdf: Path | str, text: bytes | None = None) -> ElementTree.Element:
    """The URDF's root element; ``text``: its bytes, when already read (``read_urdf``).

    Raises:
        RobotModelError: the file is missing, a device, over ``MAX_CONFIG_BYTES``, or no XML.
    """
    try:
        return ElementTree.fromstring(read_urdf(urdf) if text is None else text)
    except ElementTree.ParseError as err:
        raise RobotModelError(f'{urdf}: cannot read the URDF: {err}') from err


def _link_inertial(link: ElementTree.Element, urdf: Path | str) -> Inertial | None:
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


def link_inertials(root: ElementTree.Element, urdf: Path | str) -> dict[str, Inertial | None]:
    """Each link's mass and inertia (None: no <inertial>), by name, in the URDF's order.

    Raises:
        RobotModelError: an unreadable <inertial>; a mass that is not finite and >= 0 or an
            inertia that is not finite.
    """
    links: dict[str, Inertial | None] = {}
    for link in root.iter('link'):
        name, found = link.get('name', '?'), _link_inertial(link, urdf)
        if found is not None:
            mass, inertia = found
            if not (math.isfinite(mass) and mass >= 0 and np.isfinite(inertia).all()):
                raise RobotModelError(
                    f'{urdf}: link {name}: mass {mass:g} kg and inertia must be finite, '
                    'the mass >= 0'
                )
        links[name] = found
    return links


def inertia_problems(links: dict[str, Inertial | None], urdf: Path | str) -> list[tuple[str, str]]:
    """(link, message line) for each link whose inertia is off but is loaded anyway.

    Raises:
        RobotModelError: a link of significant mass whose inertia is all zero or has a negative
            principal moment.
    """
    total = sum(found[0] for found in links.values() if found is not None)
    threshold = min(SIGNIFICANT_KG, SIGNIFICANT_SHARE * total)
    problems = []
    for name, found in links.items():
        if found is None:
            continue
        mass, inertia = found
        problem = _problem(mass, inertia)
        if problem is None:
            continue
        refused, text = problem
        line = f'{urdf}: link {name}: {text}'
        if refused and mass >= threshold:
            raise RobotModelError(line)
        if refused:
            line += (
                f'; loaded, as a link this light (under {threshold:.3g} kg, the lesser of '
                f'{SIGNIFICANT_KG:g} kg and {SIGNIFICANT_SHARE:.0%} of the robot) barely moves '
                'the torques'
            )
        problems.append((name, line))
    return problems


def check_urdf_inertials(urdf: Path | str) -> list[str]:
    """Refuse a link no rigid body can be that carries weight; what else is off, as warnings.

    The URDF alone: ``urdf_checks.check_urdf`` is the full check of a robot config's URDF.

    Returns:
        One line per link whose inertia is off but is loaded (each also logged as a warning).

    Raises:
        RobotModelError: the URDF is unreadable; a mass that is not finite and >= 0; a link of
            significant mass whose inertia is all zero or has a negative principal moment.
    """
    lines = [line for _, line in inertia_problems(link_inertials(parse_urdf(urdf), urdf), urdf)]
    for line in lines:
        _LOG.warning('%s', line)
    return lines


def principal_moments_problem(moments: np.ndarray) -> str | None:
    """Why three principal moments of inertia about a centre of mass [kg*m^2] are no body's.

    A rigid body's are each >= 0 and obey the triangle inequality I1 + I2 >= I3 in every
    order: I_xx + I_yy = integral of (x^2 + y^2 + 2 z^2) dm >= integral of (x^2 + y^2) dm =
    I_zz. All zero is a point mass. None when they are realisable (within rounding).
    """
    values = np.sort(np.asarray(moments, dtype=float))
    shown = np.round(values, 9).tolist()
    if values[0] < -_ZERO:
        return f'principal moments {shown} kg*m^2: a negative moment (every one must be >= 0)'
    if values[0] + values[1] < values[2] * (1 - _TOLERANCE) - _ZERO:
        return (
            f'principal moments {shown} kg*m^2 break the triangle inequality I1 + I2 >= I3 '
            f'({values[0]:g} + {values[1]:g} < {values[2]:g}): no mass distribution has them'
        )
    return None


def _problem(mass: float, inertia: np.ndarray) -> tuple[bool, str] | None:
    """(whether it is refused when the link carries weight, what is off), or None."""
    moments = np.linalg.eigvalsh(inertia)
    largest = float(np.abs(moments).max())
    shown = np.round(moments, 9).tolist()
    if mass == 0:
        if largest > 0:
            return False, (
                f'mass 0 with principal moments {shown} kg*m^2: a mass typed as 0? A frame has '
                'neither; the model keeps the rotational inertia but not the weight nor the '
                "mass's share of the inertia"
            )
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
        return False, (
            f'mass {mass:g} kg with principal moments {shown} kg*m^2 (a thin rod: no '
            'inertia about one axis); loaded as it is'
        )
    if moments[0] + moments[1] < moments[2] * (1 - _TOLERANCE):
        return False, (
            f'principal moments {shown} kg*m^2 break the triangle inequality I1 + I2 >= I3: no '
            'mass distribution has this inertia, so the inertia torques the model predicts for '
            'this link are off; give its inertia about the centre of mass'
        )
    return None
