"""A robot config's URDF as a whole: what no robot can be is refused, what misleads is said.

Every command reads its robot through ``load_robot_config`` and builds the dynamics through
``build_pinocchio_model``; both call ``check_urdf``, which adds to the per-link inertia checks
(``urdf_inertials``) what needs the config's joints:

* refused: a movable joint whose axis has no length (no direction to turn about); a driven
  joint that the URDF makes follow another (``<mimic>``: the package models no coupling, it
  would drive the joint on its own); a robot whose moving links carry no mass at all (a URDF for
  display: the model would predict no weight and no inertia);
* said, one warning line per link: a moving body (the link a driven joint moves, with what is
  fixed to it) without mass while the other links carry some: the model misses its weight and
  inertia, the torques of the joints that carry it lack its share. A massless hinge (one link
  of no length between joints through one point, as URDFs write wrists and hips) is no missing
  link; a link no driven joint moves (the base) enters no torque: neither is said.

Masses a drive could not hold (``1e30`` kg) need the kinematics: ``build_pinocchio_model`` weighs
gravity against the torque limits.

A URDF is checked once per process for one config (its bytes, joints and locked joints): the
warnings are logged once, not once per model built from it.
"""

from __future__ import annotations

import hashlib
import logging
import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from id_learning.errors import RobotModelError
from id_learning.robot.urdf_inertials import (
    Inertial,
    inertia_problems,
    link_inertials,
    parse_urdf,
    read_urdf,
)

__all__ = ['MIN_AXIS_LENGTH', 'check_urdf']

_LOG = logging.getLogger(__name__)
#: The joint types that move about or along their axis (floating and planar ones have none).
_AXIS_TYPES = ('revolute', 'continuous', 'prismatic')
#: An axis shorter than this is no direction [-]: URDF axes are unit vectors (``0 0 1``).
MIN_AXIS_LENGTH = 1e-6
#: Warnings of the URDFs checked so far, by (file, its SHA-256, joints, locked joints).
_CHECKED: dict[tuple[str, str, tuple[str, ...], tuple[str, ...]], tuple[str, ...]] = {}


@dataclass(frozen=True)
class _Joint:
    """One URDF joint: name, type, links, axis text, the joint it mimics, whether at no offset.

    ``at_parent_origin``: the joint's origin is its parent link's frame (``xyz`` all zero).
    """

    name: str
    kind: str
    parent: str
    child: str
    axis: str | None
    mimic: str | None
    at_parent_origin: bool


def _urdf_joints(root: ElementTree.Element) -> list[_Joint]:
    """The URDF's joints (those of the robot element, not of transmissions)."""
    joints = []
    for joint in root.findall('joint'):
        parent, child = joint.find('parent'), joint.find('child')
        axis, mimic, origin = joint.find('axis'), joint.find('mimic'), joint.find('origin')
        xyz = origin.get('xyz', '0 0 0') if origin is not None else '0 0 0'
        try:
            offset = [float(x) for x in xyz.split()]
        except ValueError:
            offset = [1.0]  # unreadable: pinocchio refuses it
        joints.append(
            _Joint(
                name=joint.get('name', '?'),
                kind=joint.get('type', ''),
                parent=parent.get('link', '') if parent is not None else '',
                child=child.get('link', '') if child is not None else '',
                axis=axis.get('xyz') if axis is not None else None,
                mimic=mimic.get('joint', '?') if mimic is not None else None,
                at_parent_origin=not any(offset),
            )
        )
    return joints


def check_urdf(
    urdf: Path | str,
    joints: Sequence[str],
    locked_joints: Collection[str] = (),
    source: Path | str | None = None,
) -> list[str]:
    """Refuse a URDF that cannot be the robot; say, once, what is off but loads.

    Args:
        urdf: the URDF file.
        joints: the config's driven joints.
        locked_joints: the config's locked joints (held still: fixed for the model).
        source: the robot config, named in messages.

    Returns:
        One line per link that is off but loaded (logged as a warning the first time).

    Raises:
        RobotModelError: the URDF is unreadable, over the size cap or a device; a link no rigid
            body can be (``urdf_inertials``); a movable joint's axis of zero length; a driven
            joint that mimics another; no moving link with mass. The message names the URDF and
            the joint or link.
    """
    text = read_urdf(urdf)
    key = (
        str(urdf),
        hashlib.sha256(text).hexdigest(),
        tuple(joints),
        tuple(sorted(locked_joints)),
    )
    if key in _CHECKED:
        return list(_CHECKED[key])
    root = parse_urdf(urdf, text)
    _check_unique_names(root, urdf)
    links = link_inertials(root, urdf)
    per_link = inertia_problems(links, urdf)
    urdf_joints = _urdf_joints(root)
    _check_axes(urdf_joints, urdf)
    _check_mimics(urdf_joints, joints, urdf, source)
    bodies = _moving_bodies(urdf_joints, joints, locked_joints)
    body_lines = _moving_mass(links, bodies, urdf)
    # A link no driven joint moves (the base) enters no torque: what is off in it cannot mislead.
    lines = [line for link, line in per_link if link in bodies.moving and link not in body_lines]
    lines += list(body_lines.values())
    for line in lines:
        _LOG.warning('%s', line)
    _CHECKED[key] = tuple(lines)
    return lines


def _check_unique_names(root: ElementTree.Element, urdf: Path | str) -> None:
    """Refuse two links or two joints of one name: the tree, and which is meant, is ambiguous."""
    for tag in ('link', 'joint'):
        names = [element.get('name', '') for element in root.findall(tag)]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise RobotModelError(
                f'{urdf}: {len(repeated)} {tag} name(s) given more than once: '
                f'{", ".join(repeated)}; each {tag} needs a name of its own (a copied '
                f'{tag} left unrenamed?)'
            )


def _check_axes(urdf_joints: list[_Joint], urdf: Path | str) -> None:
    """Refuse a revolute or prismatic joint whose axis is not three finite numbers of length."""
    for joint in urdf_joints:
        if joint.kind not in _AXIS_TYPES or joint.axis is None:
            continue  # no <axis>: the URDF's default, 1 0 0
        try:
            axis = np.array([float(value) for value in joint.axis.split()])
        except ValueError:
            axis = np.array([])
        if axis.shape != (3,) or not np.isfinite(axis).all():
            raise RobotModelError(
                f'{urdf}: joint {joint.name}: axis {joint.axis!r} is not three finite numbers '
                "(a direction such as '0 0 1')"
            )
        length = float(np.linalg.norm(axis))
        if length < MIN_AXIS_LENGTH:
            raise RobotModelError(
                f'{urdf}: joint {joint.name}: axis {joint.axis!r} has length {length:g}, no '
                f'direction for a {joint.kind} joint to move about or along; give its unit '
                "axis (such as '0 0 1')"
            )


def _check_mimics(
    urdf_joints: list[_Joint],
    joints: Sequence[str],
    urdf: Path | str,
    source: Path | str | None,
) -> None:
    """Refuse a driven joint that the URDF makes follow another (``<mimic>``)."""
    for joint in urdf_joints:
        if joint.name in joints and joint.mimic is not None:
            config = f'the robot config {source}' if source else 'the robot config'
            raise RobotModelError(
                f'{urdf}: joint {joint.name} mimics {joint.mimic} (<mimic joint='
                f'"{joint.mimic}">) but {config} lists it among the driven joints: a mimic '
                'joint follows another, without a drive of its own, and id_learning models '
                'no mimic coupling; remove the <mimic> if the joint has its own drive'
            )


@dataclass(frozen=True)
class _Bodies:
    """What the driven joints move.

    A driven joint's body is its child link with what is fixed to it (fixed and locked joints),
    up to the next joint that moves: what pinocchio makes one body of. A hinge is how a URDF
    writes two or three joints through one point (a wrist, a hip): a body of one link whose
    next joints all sit at its origin; a massless hinge is no link left out.

    Attributes:
        moving: every link a driven joint moves.
        bodies: each driven joint's body (its links, the child link first), by joint.
        hinges: the driven joints whose body is a hinge.
        carriers: the driven joints from the root down to each driven joint, itself included.
    """

    moving: set[str]
    bodies: dict[str, list[str]]
    hinges: set[str]
    carriers: dict[str, list[str]]


def _moving_bodies(
    urdf_joints: list[_Joint], joints: Sequence[str], locked_joints: Collection[str]
) -> _Bodies:
    """The bodies of the driven joints (``_Bodies``)."""
    below: dict[str, list[_Joint]] = {}
    for joint in urdf_joints:
        below.setdefault(joint.parent, []).append(joint)
    parent_joint = {joint.child: joint for joint in urdf_joints}

    def reach(link: str, rigid_only: bool) -> list[str]:
        found, stack = [], [link]
        while stack:
            current = stack.pop()
            if current in found:
                continue  # a loop in a broken tree: pinocchio refuses it
            found.append(current)
            for joint in below.get(current, []):
                if not rigid_only or joint.kind == 'fixed' or joint.name in locked_joints:
                    stack.append(joint.child)
        return found

    def carriers(start: _Joint) -> list[str]:
        chain: list[str] = []
        joint: _Joint | None = start
        seen: set[str] = set()
        while joint is not None and joint.name not in seen:
            seen.add(joint.name)
            if joint.name in joints:
                chain.append(joint.name)
            joint = parent_joint.get(joint.parent)
        return chain[::-1]

    driven = [j for j in urdf_joints if j.name in joints and j.kind in _AXIS_TYPES]
    bodies = {joint.name: reach(joint.child, rigid_only=True) for joint in driven}
    return _Bodies(
        moving={link for joint in driven for link in reach(joint.child, rigid_only=False)},
        bodies=bodies,
        hinges={
            name
            for name, body in bodies.items()
            if len(body) == 1
            and below.get(body[0])
            and all(joint.at_parent_origin for joint in below[body[0]])
        },
        carriers={joint.name: carriers(joint) for joint in driven},
    )


def _moving_mass(
    links: dict[str, Inertial | None], found: _Bodies, urdf: Path | str
) -> dict[str, str]:
    """Refuse a robot whose moving links carry no mass; a message line per massless body.

    Returns:
        A warning line by link: the child link of each driven joint whose body has no mass
        while others do, hinges aside.
    """

    def mass(link: str) -> float:
        inertial = links.get(link)
        return 0.0 if inertial is None else inertial[0]

    if not found.bodies:
        return {}  # no driven joint in the URDF: building the model names them
    moving = found.moving
    total = sum(mass(link) for link in moving)
    if not total > 0:
        top = [name for name, chain in found.carriers.items() if chain == [name]]
        bare = sum(1 for link in moving if links.get(link) is None)
        raise RobotModelError(
            f'{urdf}: none of the {len(moving)} links below joint(s) '
            f'{", ".join(top or found.bodies)} carries mass ({bare} without <inertial>, '
            f'{len(moving) - bare} of mass 0): a rigid-body model of it predicts no weight and '
            'no inertia, no torque at all; give each link its <inertial> (mass, centre of '
            'mass, inertia): a URDF for display is not the robot'
        )
    lines = {}
    for name, body in found.bodies.items():
        if name in found.hinges or any(mass(link) > 0 for link in body):
            continue
        link, inertial = body[0], links.get(body[0])
        if inertial is None:
            what = 'has no <inertial>'
        else:
            moments = np.round(np.linalg.eigvalsh(inertial[1]), 6).tolist()
            what = 'has mass 0' + (
                f' (with principal moments {moments} kg*m^2: a mass typed as 0?)'
                if max(abs(m) for m in moments) > 0
                else ''
            )
        fixed = ' (nor anything fixed to it)' if len(body) > 1 else ''
        lines[link] = (
            f'{urdf}: link {link} (moved by {name}) {what}{fixed} while the other moving links '
            f'carry {_kilograms(total)}: the model misses its weight and inertia, so the torques '
            f'it predicts for {", ".join(found.carriers[name])} lack its share, which a payload '
            'or residual model then takes up wrongly; give it its <inertial>'
        )
    return lines


def _kilograms(mass: float) -> str:
    """A mass for messages: '1250 kg', '0.35 kg', '1e+30 kg'."""
    return f'{mass:.4g} kg' if math.isfinite(mass) else f'{mass} kg'
