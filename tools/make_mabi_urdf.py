"""Generate ``urdf/mabi_max100.urdf``, a 6-axis heavy industrial arm of the MABI MAX 100 class.

The model is our own approximation (about 1250 kg incl. base, 100 kg rated payload, Sinumerik
CNC): offset shoulder, long upper arm and a spherical wrist (axes 4, 5 and 6 meet at the origin
of ``joint_5``). Every link's inertia is computed from solid boxes and cylinders, combined with
the parallel-axis theorem, so masses, centres of mass and inertia tensors are consistent.

Usage:
    python tools/make_mabi_urdf.py [--output PATH]

The output is deterministic: floats are written with a fixed number of significant digits.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

ROBOT_NAME = 'mabi_max100'
DEFAULT_OUTPUT = Path(__file__).resolve().parent.parent / 'urdf' / f'{ROBOT_NAME}.urdf'
SIG_DIGITS = 8
TOTAL_MASS = 1250.0  # kg, all links with an inertial (base_link takes up the rest)
HALF_PI = math.pi / 2.0


@dataclass(frozen=True)
class Box:
    """Solid box with edge lengths ``size`` (x, y, z) centred at ``center`` (link frame)."""

    mass: float
    center: Vec3
    size: Vec3


@dataclass(frozen=True)
class Cylinder:
    """Solid cylinder of ``radius`` and ``length`` along link ``axis`` ('x', 'y' or 'z')."""

    mass: float
    center: Vec3
    radius: float
    length: float
    axis: str


Shape = Box | Cylinder


@dataclass(frozen=True)
class Joint:
    """Revolute joint: origin in the parent frame (rpy zero), axis and limits (rad, rad/s, Nm)."""

    name: str
    parent: str
    child: str
    xyz: Vec3
    axis: Vec3
    lower: float
    upper: float
    velocity: float
    effort: float


# --- Link shapes (link frame = frame of the joint that moves the link) -------------------------
# flange: mounting plate on link_6, attached by the fixed joint flange_joint (tiny mass).
FLANGE_MASS = 0.1
FLANGE_SHAPES: tuple[Shape, ...] = (
    Cylinder(FLANGE_MASS, (0.005, 0.0, 0.0), radius=0.05, length=0.01, axis='x'),
)
# link_6: flange disc of axis 6, rotating about x.
LINK_6_SHAPES: tuple[Shape, ...] = (
    Cylinder(8.0, (0.03, 0.0, 0.0), radius=0.10, length=0.06, axis='x'),
)
# link_5: wrist, a pitch hub about y on the axis-5 origin plus a nose towards the flange.
LINK_5_SHAPES: tuple[Shape, ...] = (
    Cylinder(12.0, (0.0, 0.0, 0.0), radius=0.10, length=0.22, axis='y'),
    Cylinder(13.0, (0.12, 0.0, 0.0), radius=0.09, length=0.12, axis='x'),
)
# link_4: forearm tube along +x (axis 4) up to the wrist.
LINK_4_SHAPES: tuple[Shape, ...] = (
    Cylinder(70.0, (0.45, 0.0, 0.0), radius=0.13, length=0.90, axis='x'),
)
# link_3: elbow housing, an elbow hub about y plus the box carrying the motors of axes 4-6.
LINK_3_SHAPES: tuple[Shape, ...] = (
    Cylinder(40.0, (0.0, 0.0, 0.0), radius=0.20, length=0.42, axis='y'),
    Box(110.0, (0.14, 0.0, 0.245), size=(0.56, 0.36, 0.34)),
)
# link_2: long upper arm along +z, a shoulder hub about y plus the arm beam (0.32 x 0.38 m).
LINK_2_SHAPES: tuple[Shape, ...] = (
    Cylinder(23.0, (0.0, 0.0, 0.0), radius=0.22, length=0.45, axis='y'),
    Box(217.0, (0.0, 0.0, 0.575), size=(0.32, 0.38, 1.15)),
)
# link_1: rotating column (carousel), a turntable about z plus the offset shoulder housing.
LINK_1_SHAPES: tuple[Shape, ...] = (
    Cylinder(100.0, (0.0, 0.0, 0.10), radius=0.45, length=0.20, axis='z'),
    Box(220.0, (0.175, 0.0, 0.39), size=(0.65, 0.80, 0.50)),
)
_MOVING_SHAPES = (
    LINK_1_SHAPES + LINK_2_SHAPES + LINK_3_SHAPES + LINK_4_SHAPES + LINK_5_SHAPES + LINK_6_SHAPES
)
_MOVING_MASS = sum(s.mass for s in _MOVING_SHAPES + FLANGE_SHAPES)
# base_link: fixed pedestal, a floor plate plus a column up to axis 1; it takes up the rest of
# TOTAL_MASS (about 437 kg).
BASE_PLATE_MASS = 120.0
BASE_SHAPES: tuple[Shape, ...] = (
    Box(BASE_PLATE_MASS, (0.0, 0.0, 0.04), size=(1.10, 1.10, 0.08)),
    Cylinder(
        TOTAL_MASS - _MOVING_MASS - BASE_PLATE_MASS,
        (0.0, 0.0, 0.365),
        radius=0.36,
        length=0.57,
        axis='z',
    ),
)

LINKS: tuple[tuple[str, tuple[Shape, ...]], ...] = (
    ('base_link', BASE_SHAPES),
    ('link_1', LINK_1_SHAPES),
    ('link_2', LINK_2_SHAPES),
    ('link_3', LINK_3_SHAPES),
    ('link_4', LINK_4_SHAPES),
    ('link_5', LINK_5_SHAPES),
    ('link_6', LINK_6_SHAPES),
    ('flange', FLANGE_SHAPES),
)

# --- Kinematics and limits ---------------------------------------------------------------------
X_AXIS: Vec3 = (1.0, 0.0, 0.0)
Y_AXIS: Vec3 = (0.0, 1.0, 0.0)
Z_AXIS: Vec3 = (0.0, 0.0, 1.0)
JOINTS: tuple[Joint, ...] = (
    Joint('joint_1', 'base_link', 'link_1', (0.0, 0.0, 0.65), Z_AXIS, -3.05, 3.05, 1.75, 9000.0),
    Joint('joint_2', 'link_1', 'link_2', (0.35, 0.0, 0.45), Y_AXIS, -1.40, 1.50, 1.45, 15000.0),
    Joint('joint_3', 'link_2', 'link_3', (0.0, 0.0, 1.15), Y_AXIS, -2.60, 1.30, 1.50, 7500.0),
    Joint('joint_4', 'link_3', 'link_4', (0.30, 0.0, 0.22), X_AXIS, -5.2, 5.2, 2.4, 1600.0),
    Joint('joint_5', 'link_4', 'link_5', (0.95, 0.0, 0.0), Y_AXIS, -2.1, 2.1, 2.3, 1300.0),
    Joint('joint_6', 'link_5', 'link_6', (0.18, 0.0, 0.0), X_AXIS, -6.0, 6.0, 3.5, 650.0),
)
FLANGE_XYZ: Vec3 = (0.06, 0.0, 0.0)  # flange face on link_6
TOOL0_RPY: Vec3 = (0.0, HALF_PI, 0.0)  # REP-199 tool0: z out of the flange


def fmt(x: float) -> str:
    """Format a float with SIG_DIGITS significant digits, without '-0' or round-off dust."""
    if abs(x) < 1e-12:
        x = 0.0
    return f'{x + 0.0:.{SIG_DIGITS}g}'


def fmt3(v: Vec3) -> str:
    """Format a 3-vector as a space-separated URDF attribute."""
    return ' '.join(fmt(c) for c in v)


def shape_inertia(shape: Shape) -> Vec3:
    """Principal moments (Ixx, Iyy, Izz) of a solid shape about its own centre, link axes."""
    if isinstance(shape, Box):
        sx, sy, sz = shape.size
        k = shape.mass / 12.0
        return (k * (sy * sy + sz * sz), k * (sx * sx + sz * sz), k * (sx * sx + sy * sy))
    r, h = shape.radius, shape.length
    axial = shape.mass * r * r / 2.0
    radial = shape.mass * (3.0 * r * r + h * h) / 12.0
    return tuple(axial if a == shape.axis else radial for a in 'xyz')  # type: ignore[return-value]


def combine(shapes: tuple[Shape, ...]) -> tuple[float, Vec3, Mat3]:
    """Mass, centre of mass and inertia tensor about the COM of rigidly joined solid shapes."""
    mass = sum(s.mass for s in shapes)
    com = tuple(sum(s.mass * s.center[i] for s in shapes) / mass for i in range(3))
    inertia = [[0.0] * 3 for _ in range(3)]
    for s in shapes:
        d = [s.center[i] - com[i] for i in range(3)]
        d2 = sum(c * c for c in d)
        own = shape_inertia(s)
        for i in range(3):
            for j in range(3):
                steiner = s.mass * ((d2 if i == j else 0.0) - d[i] * d[j])
                inertia[i][j] += (own[i] if i == j else 0.0) + steiner
    return mass, com, tuple(tuple(row) for row in inertia)  # type: ignore[return-value]


def shape_origin_rpy(shape: Shape) -> Vec3:
    """Rotation taking the URDF cylinder axis (z) onto the shape's axis."""
    if isinstance(shape, Cylinder) and shape.axis == 'x':
        return (0.0, HALF_PI, 0.0)
    if isinstance(shape, Cylinder) and shape.axis == 'y':
        return (-HALF_PI, 0.0, 0.0)
    return (0.0, 0.0, 0.0)


def link_xml(name: str, shapes: tuple[Shape, ...]) -> list[str]:
    """URDF lines of one link: inertial from the shapes, one visual per shape."""
    mass, com, inertia = combine(shapes)
    (ixx, ixy, ixz), (_, iyy, iyz), (_, _, izz) = inertia
    lines = [
        f'  <link name="{name}">',
        '    <inertial>',
        f'      <origin xyz="{fmt3(com)}" rpy="0 0 0"/>',
        f'      <mass value="{fmt(mass)}"/>',
        f'      <inertia ixx="{fmt(ixx)}" ixy="{fmt(ixy)}" ixz="{fmt(ixz)}"'
        f' iyy="{fmt(iyy)}" iyz="{fmt(iyz)}" izz="{fmt(izz)}"/>',
        '    </inertial>',
    ]
    for s in shapes:
        if isinstance(s, Box):
            geometry = f'<box size="{fmt3(s.size)}"/>'
        else:
            geometry = f'<cylinder radius="{fmt(s.radius)}" length="{fmt(s.length)}"/>'
        lines += [
            '    <visual>',
            f'      <origin xyz="{fmt3(s.center)}" rpy="{fmt3(shape_origin_rpy(s))}"/>',
            f'      <geometry>{geometry}</geometry>',
            '    </visual>',
        ]
    lines.append('  </link>')
    return lines


def joint_xml(j: Joint) -> list[str]:
    """URDF lines of one revolute joint."""
    return [
        f'  <joint name="{j.name}" type="revolute">',
        f'    <parent link="{j.parent}"/>',
        f'    <child link="{j.child}"/>',
        f'    <origin xyz="{fmt3(j.xyz)}" rpy="0 0 0"/>',
        f'    <axis xyz="{fmt3(j.axis)}"/>',
        f'    <limit lower="{fmt(j.lower)}" upper="{fmt(j.upper)}"'
        f' velocity="{fmt(j.velocity)}" effort="{fmt(j.effort)}"/>',
        '    <dynamics damping="0" friction="0"/>',
        '  </joint>',
    ]


def fixed_joint_xml(name: str, parent: str, child: str, xyz: Vec3, rpy: Vec3) -> list[str]:
    """URDF lines of one fixed joint."""
    return [
        f'  <joint name="{name}" type="fixed">',
        f'    <parent link="{parent}"/>',
        f'    <child link="{child}"/>',
        f'    <origin xyz="{fmt3(xyz)}" rpy="{fmt3(rpy)}"/>',
        '  </joint>',
    ]


def build_urdf() -> str:
    """Return the complete URDF document as a string."""
    lines = [
        '<?xml version="1.0"?>',
        '<!-- Generated by tools/make_mabi_urdf.py: do not edit by hand, rerun the script.',
        '     MABI MAX 100 class 6-axis arm (approximate model, ~1250 kg, 100 kg payload).',
        '     Units SI: m, rad, kg, kg m^2, N m, rad/s. Inertias from solid boxes/cylinders. -->',
        f'<robot name="{ROBOT_NAME}">',
    ]
    for name, shapes in LINKS:
        lines += link_xml(name, shapes)
    lines += ['  <link name="tool0"/>']
    for j in JOINTS:
        lines += joint_xml(j)
    lines += fixed_joint_xml('flange_joint', 'link_6', 'flange', FLANGE_XYZ, (0.0, 0.0, 0.0))
    lines += fixed_joint_xml('tool0_joint', 'flange', 'tool0', (0.0, 0.0, 0.0), TOOL0_RPY)
    lines.append('</robot>')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Write the URDF (default ``urdf/mabi_max100.urdf``) and print a short summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--output', type=Path, default=DEFAULT_OUTPUT, help='URDF file to write')
    args = parser.parse_args(argv)
    text = build_urdf()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text, encoding='utf-8', newline='\n')
    total = sum(combine(shapes)[0] for _, shapes in LINKS)
    print(f'wrote {args.output} ({len(LINKS)} links with inertial, total mass {total:.6g} kg)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
