"""The report's account of identified physics: what the data changed against the URDF.

For a fitted model that carries ``physics.identified.IdentifiedPhysics`` (rnea_id and the
networks on it: rnea_id_mlp, delan_id, lnn_mlp_id): each body's mass and centre of mass, the
payload, the drives against their datasheet, the motor cogging found on the full band, and the
base parameters with their 95 % intervals, marked identified by the data or held at the CAD prior.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from id_learning.physics.effects import friction_law
from id_learning.physics.identification import PRIOR_DOMINATED
from id_learning.physics.identified import IdentifiedPhysics
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS, RigidBodyDynamics
from id_learning.robot.config import RobotConfig

__all__ = ['identified_physics_section']


def identified_physics_section(models: dict[str, Any], robot: RobotConfig) -> list[str]:
    """Markdown lines for the first model with identified physics; [] when there is none."""
    for kind, model in models.items():
        physics = getattr(model, 'physics_', None)
        if isinstance(physics, IdentifiedPhysics):
            return _section(kind, physics, robot)
    return []


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return [
        '| ' + ' | '.join(head) + ' |',
        '|' + '---|' * len(head),
        *('| ' + ' | '.join(row) + ' |' for row in rows),
        '',
    ]


def _g(x: float, digits: int = 4) -> str:
    return f'{x:.{digits}g}'


def _pm(value: float, std: float | None, digits: int = 4) -> str:
    return _g(value, digits) if std is None else f'{_g(value, digits)} ± {_g(1.96 * std, 2)}'


def _scale(gain: float, std: float | None) -> str:
    """The torque-constant scale s = 1 / (1 + g) of a label gain g, with its interval."""
    scale = 1.0 / (1.0 + gain)
    return _pm(scale, None if std is None else std * scale**2, 3)


def _mass_and_com(theta: np.ndarray) -> tuple[float, np.ndarray]:
    mass = float(theta[0])
    return mass, theta[1:4] / mass if mass > 0 else np.zeros(3)


def _section(kind: str, physics: IdentifiedPhysics, robot: RobotConfig) -> list[str]:
    report = physics.report
    base = report.get('base_parameters', [])
    identified = sum(1 for b in base if b['identified'])
    seconds = float(report.get('seconds', float('nan')))
    condition = float(report.get('condition_number', float('nan')))
    lines = [
        f'## Identified physics ({kind}) against the URDF',
        '',
        f'Identified from {report.get("samples", "?")} rows (every '
        f'{report.get("row_step", 1)}. sample of the training part) in '
        f'{_g(seconds, 3)} s. Condition number of the base regressor on this recording: '
        f'{_g(condition, 3)}. {identified} of {len(base)} base parameters are identified by the '
        f'data (posterior std below {PRIOR_DOMINATED:g} of the prior std); the others stay near '
        'the URDF, held by the CAD prior. '
        'Every body is physically consistent (pseudo-inertia positive semidefinite; solver '
        f'status {report.get("solver_status", "optimal")}). Intervals are 95 %.',
        '',
        '### Bodies (payload included in its carrying body)',
        '',
    ]
    urdf = RigidBodyDynamics.from_config(robot).inertial_parameters()
    rows = []
    for b in range(len(urdf) // N_INERTIAL_PARAMETERS):
        block = slice(N_INERTIAL_PARAMETERS * b, N_INERTIAL_PARAMETERS * (b + 1))
        m0, c0 = _mass_and_com(urdf[block])
        m1, c1 = _mass_and_com(physics.theta[block])
        rows.append(
            [
                f'body {b + 1} ({robot.joints[b] if b < robot.n_joints else "fixed"})',
                _g(m0),
                _g(m1),
                ', '.join(f'{x:.3f}' for x in c0),
                ', '.join(f'{x:.3f}' for x in c1),
            ]
        )
    lines += _table(
        ['body', 'mass URDF [kg]', 'mass identified [kg]', 'COM URDF [m]', 'COM identified [m]'],
        rows,
    )
    payload = report.get('payload')
    if payload and payload.get('value'):
        value, std = np.asarray(payload['value']), np.asarray(payload['std'])
        mass, com = _mass_and_com(value)
        lines += [
            f'Payload at `{payload["frame"]}` (the URDF has none): mass {_pm(mass, std[0])} kg, '
            f'centre of mass ({", ".join(f"{x:.3f}" for x in com)}) m.',
            '',
        ]
    lines += _drives(physics, robot)
    lines += _cogging(physics)
    lines += [
        '### Base parameters',
        '',
        *_table(
            ['base parameter', 'unit', 'URDF', 'identified', '95 % interval', 'by'],
            [
                [
                    b['name'],
                    b['unit'],
                    _g(b['urdf']),
                    _g(b['value']),
                    f'[{_g(b["ci95"][0])}, {_g(b["ci95"][1])}]',
                    'data' if b['identified'] else 'prior',
                ]
                for b in base
            ],
        ),
    ]
    return lines


def _drives(physics: IdentifiedPhysics, robot: RobotConfig) -> list[str]:
    """Per joint: rotor inertia against the datasheet, label gain, offset, friction, balancer."""
    drive = physics.report.get('drive', {})

    def std(name: str, j: int) -> float | None:
        entry = drive.get(name)
        return None if entry is None else float(np.asarray(entry['std']).reshape(-1)[j])

    head = ['joint']
    if physics.target == 'motor':
        head += ['rotor inertia datasheet [kg·m²]', 'identified [kg·m²]', 'torque-constant scale']
    head += ['offset [N·m]', *[f'{law} friction' for law in physics.laws], 'balancer (r, phase)']
    rows = []
    for j, joint in enumerate(robot.joints):
        row = [joint]
        if physics.target == 'motor':
            row += [
                _g(float(robot.drives.rotor_inertia[j])),
                _pm(float(physics.rotor[j]), std('rotor', j)),
                _scale(float(physics.gain[j]), std('gain', j)),
            ]
        row.append(_pm(float(physics.offset[j]), std('offset', j), 3))
        for law in physics.laws:
            text = _pm(float(physics.friction[law][j]), std(law, j), 3)
            if friction_law(law).hump:
                text += f' (v_s {_g(float(physics.stribeck_velocity[j]), 3)} rad/s)'
            row.append(text)
        has_balancer = bool(np.any(physics.balancer[j] != 0))
        row.append(
            f'{physics.balancer_ratio[j]:.3f}, {physics.balancer_phase[j]:.3f} rad'
            if has_balancer
            else '–'
        )
        rows.append(row)
    units = 'friction coefficients in N·m·s/rad (viscous), N·m (Coulomb, Stribeck), 1 (load)'
    return [
        '### Drives',
        '',
        f'Signal delay of the labels behind the positions: {physics.delay_s * 1e3:.2f} ms. '
        'Torque-constant scale s: the true torque constant over the datasheet one; the labels '
        f'are 1 / s times the rigid-body and rotor torque ({units}).',
        '',
        *_table(head, rows),
    ]


def _cogging(physics: IdentifiedPhysics) -> list[str]:
    """Per joint: the cogging ripple kept (period, amplitude, interval), or why none."""
    found = physics.report.get('cogging')
    lines = ['### Cogging', '']
    if not found:
        return [*lines, 'Not sought (identified before the full-band cogging stage).', '']
    if found.get('skipped'):
        return [*lines, f'Not sought: {found["skipped"]}.', '']
    tried = ', '.join(str(p) for p in found.get('periods_tried', []))
    lines += [
        'A torque ripple s sin(p N q) + c cos(p N q) per joint (p periods per motor turn, N the '
        "gear ratio, q at the labels' time), far above the label filter's band: fitted on the "
        "training part's unfiltered labels less the identified torque, both sides high-passed "
        f'at {_g(float(found.get("high_pass_hz", float("nan"))), 3)} Hz, for p in {{{tried}}}, '
        'and kept where its amplitude reaches '
        f'{_g(float(found.get("z_threshold", float("nan"))), 3)} standard errors (from blocks '
        "of time; with few blocks the same tail probability under Student's t) and lowers that "
        'residual on the held-out tail of the training part; the most significant '
        'per joint, then fitted on the whole training part.',
        '',
    ]
    rows = []
    for entry in found.get('joints', []):
        if entry.get('period'):
            low, high = entry['amplitude_ci95_nm']
            rows.append(
                [
                    entry['joint'],
                    str(entry['period']),
                    _g(entry['amplitude_nm'], 3),
                    f'[{_g(low, 3)}, {_g(high, 3)}]',
                    f'{entry["phase_rad"]:.3f}',
                    _g(entry['z'], 3),
                    _g(entry['held_out_gain'], 2),
                ]
            )
            continue
        strongest = entry.get('strongest') or {}
        why = entry.get('why_none', 'none significant')
        if strongest:
            why += (
                f' (strongest: p = {strongest["period"]}, '
                f'{_g(strongest["amplitude_nm"], 2)} N·m, {_g(strongest["z"], 2)} SE)'
            )
        rows.append([entry['joint'], '–', f'none: {why}', '', '', '', ''])
    head = [
        'joint',
        'periods per motor turn',
        'amplitude [N·m]',
        '95 % interval',
        'phase [rad]',
        'standard errors',
        'held-out gain',
    ]
    return [*lines, *_table(head, rows)]
