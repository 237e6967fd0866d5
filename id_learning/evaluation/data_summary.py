"""Data summary of a preprocessed recording: ranges, noise, torque shares, and plots."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset, lowpass
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_inertia_torque

__all__ = ['DataSummary', 'nominal_components', 'summarise', 'write_summary']

SHARE_NAMES = ('gravity', 'inertia', 'coriolis', 'rotor_inertia', 'remainder')


def nominal_components(dataset: Dataset, robot: RobotConfig) -> dict[str, np.ndarray]:
    """Split the target torque with the nominal model; each (N, n) [N*m].

    The nominal model is evaluated on the motion filtered like the labels (``dataset.study``),
    so that every part is as smooth as the filtered target. ``remainder`` is the target minus
    the nominal model: friction, balancer, payload and every other effect the URDF and datasheet
    do not know.
    """
    q, v, a = dataset.study.q, dataset.study.v, dataset.study.a
    dynamics = RigidBodyDynamics.from_config(robot)
    gravity = dynamics.gravity(q)
    inertia = np.einsum('bij,bj->bi', dynamics.mass_matrix(q), a)
    coriolis = dynamics.coriolis(q, v)
    rotor = rotor_inertia_torque(a, robot.drives.rotor_inertia, robot.drives.gear_ratio)
    remainder = dataset.tau - gravity - inertia - coriolis - rotor
    return {
        'gravity': gravity,
        'inertia': inertia,
        'coriolis': coriolis,
        'rotor_inertia': rotor,
        'remainder': remainder,
    }


def rms(x: np.ndarray) -> np.ndarray:
    """Root mean square per column."""
    out: np.ndarray = np.sqrt(np.mean(np.square(x), axis=0))
    return out


def shares(components: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each component's RMS divided by the sum of the components' RMS, per joint."""
    values = {name: rms(value) for name, value in components.items()}
    total = np.sum(list(values.values()), axis=0)
    return {name: value / np.where(total > 0, total, 1.0) for name, value in values.items()}


@dataclass(frozen=True, eq=False)
class DataSummary:
    """Figures a user checks before training."""

    joints: tuple[str, ...]
    n_samples: int
    duration_s: float
    n_train: int
    ranges: dict[str, dict[str, list[float]]]
    rms_nm: dict[str, list[float]]
    shares: dict[str, list[float]]
    true_shares: dict[str, list[float]] | None
    noise_after_filter_nm: list[float] | None
    regularise: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return dict(self.__dict__)


def _true_shares(ground_truth: dict[str, Any]) -> dict[str, list[float]]:
    """Shares from the twin's noise-free components, grouped like the nominal split."""
    groups = {
        'gravity': ('gravity',),
        'inertia': ('inertia',),
        'coriolis': ('coriolis',),
        'rotor_inertia': ('rotor_inertia',),
        'friction': (
            'viscous_friction',
            'coulomb_friction',
            'stribeck_friction',
            'load_dependent_friction',
        ),
        'other': ('gravity_spring', 'cogging', 'torque_offset'),
    }
    rms_by_name = {k: np.asarray(v) for k, v in ground_truth['component_rms_nm'].items()}
    n = len(ground_truth['joints'])
    grouped = {
        g: sum((rms_by_name.get(name, np.zeros(n)) for name in names), np.zeros(n))
        for g, names in groups.items()
    }
    total = np.sum(list(grouped.values()), axis=0)
    return {g: (value / total).tolist() for g, value in grouped.items()}


def summarise(
    dataset: Dataset,
    robot: RobotConfig,
    ground_truth: dict[str, Any] | None = None,
    tau_clean: np.ndarray | None = None,
) -> tuple[DataSummary, dict[str, np.ndarray]]:
    """Compute the data summary and the nominal torque components."""
    components = nominal_components(dataset, robot)
    ranges = {
        name: {'min': np.min(x, axis=0).tolist(), 'max': np.max(x, axis=0).tolist()}
        for name, x in (
            ('q_rad', dataset.controller.q),
            ('v_rad_s', dataset.controller.v),
            ('a_rad_s2', dataset.controller.a),
            ('tau_nm', dataset.tau),
        )
    }
    noise = None
    if tau_clean is not None and len(tau_clean) == len(dataset.tau):
        clean = lowpass(tau_clean, dataset.cutoff_hz, dataset.period_s, dataset.filter_order)
        noise = rms(dataset.tau - clean).tolist()
    summary = DataSummary(
        joints=dataset.joints,
        n_samples=len(dataset.q),
        duration_s=float((len(dataset.q) - 1) * dataset.period_s),
        n_train=dataset.n_train,
        ranges=ranges,
        rms_nm={
            name: rms(value).tolist()
            for name, value in {**components, 'target': dataset.tau}.items()
        },
        shares={name: value.tolist() for name, value in shares(components).items()},
        true_shares=_true_shares(ground_truth) if ground_truth else None,
        noise_after_filter_nm=noise,
        regularise=dataset.regularise_report.summary() if dataset.regularise_report else '',
    )
    return summary, components


def _table(title: str, joints: tuple[str, ...], rows: dict[str, list[float]], fmt: str) -> str:
    head = f'| {title} | ' + ' | '.join(joints) + ' |'
    rule = '|---|' + '---:|' * len(joints)
    body = [
        f'| {name} | ' + ' | '.join(format(x, fmt) for x in values) + ' |'
        for name, values in rows.items()
    ]
    return '\n'.join([head, rule, *body])


def _plot(
    dataset: Dataset, components: dict[str, np.ndarray], summary: DataSummary, out: Path
) -> list[str]:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    files = []
    n = len(dataset.joints)
    t = (dataset.stamps_ns - dataset.stamps_ns[0]) * 1e-9
    window = t <= min(60.0, t[-1])
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.9 * n), sharex=True, constrained_layout=True)
    for j, ax in enumerate(np.atleast_1d(axes)):
        ax.plot(t[window], dataset.tau_raw[window, j], color='0.7', lw=0.6, label='raw')
        ax.plot(
            t[window],
            dataset.tau[window, j],
            color='C0',
            lw=1.2,
            label=f'filtered ({dataset.cutoff_hz[j]:g} Hz)',
        )
        ax.plot(
            t[window],
            dataset.tau[window, j] - components['remainder'][window, j],
            color='C3',
            lw=1.0,
            ls='--',
            label='nominal model',
        )
        ax.set_ylabel(f'{dataset.joints[j]}\n[N·m]')
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend(loc='upper right', ncol=3, fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel('time [s]')
    fig.suptitle(
        f'{"tau_u from currents" if dataset.target == "motor" else "joint torque"}: first 60 s'
    )
    fig.savefig(out / 'torque_timeseries.png', dpi=110)
    plt.close(fig)
    files.append('torque_timeseries.png')

    fig, ax = plt.subplots(figsize=(9, 4), constrained_layout=True)
    bottom = np.zeros(n)
    for name in SHARE_NAMES:
        values = np.asarray(summary.shares[name]) * 100
        ax.bar(dataset.joints, values, bottom=bottom, label=name.replace('_', ' '))
        bottom += values
    ax.set_ylabel('share of RMS torque [%]')
    ax.set_title('Where the torque comes from (nominal model split; remainder = unmodelled)')
    ax.legend(loc='upper left', bbox_to_anchor=(1.0, 1.0), fontsize=8)
    fig.savefig(out / 'torque_shares.png', dpi=110)
    plt.close(fig)
    files.append('torque_shares.png')

    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True, constrained_layout=True)
    for ax, (label, x) in zip(
        axes,
        (('q [rad]', dataset.q), ('v [rad/s]', dataset.v), ('a [rad/s²]', dataset.a)),
        strict=True,
    ):
        step = max(1, len(t) // 5000)
        ax.plot(t[::step], x[::step], lw=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(dataset.joints, ncol=len(dataset.joints), fontsize=8, loc='upper right')
    axes[-1].set_xlabel('time [s]')
    if dataset.is_shuffled:
        axes[0].set_title('Excitation after filtering (train and test samples drawn at random)')
    else:
        axes[-1].axvline(t[dataset.n_train], color='k', ls=':', lw=1)
        axes[0].set_title('Excitation after filtering (dotted line: train | test split)')
    fig.savefig(out / 'excitation.png', dpi=110)
    plt.close(fig)
    files.append('excitation.png')
    return files


def write_summary(
    dataset: Dataset,
    robot: RobotConfig,
    out: Path,
    *,
    ground_truth: dict[str, Any] | None = None,
    tau_clean: np.ndarray | None = None,
) -> DataSummary:
    """Write ``summary.md``, ``summary.json`` and PNG figures into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    summary, components = summarise(dataset, robot, ground_truth, tau_clean)
    figures = _plot(dataset, components, summary, out)
    (out / 'summary.json').write_text(
        json.dumps(summary.to_dict(), indent=1) + '\n', encoding='utf-8'
    )
    pct = {name: [100 * x for x in values] for name, values in summary.shares.items()}
    target = 'tau_u from motor currents' if dataset.target == 'motor' else 'measured joint torque'
    lines = [
        f'# Data summary: {dataset.source}',
        '',
        f'{summary.n_samples} samples '
        f'({summary.duration_s:.1f} s at {dataset.period_s * 1e3:g} ms), '
        f'target: {target}, '
        f'{_split_text(dataset, summary.n_train)}. {summary.regularise}.',
        '',
        '## Ranges after filtering',
        '',
        _table(
            'quantity',
            dataset.joints,
            {f'{k} min': v['min'] for k, v in summary.ranges.items()}
            | {f'{k} max': v['max'] for k, v in summary.ranges.items()},
            '.3g',
        ),
        '',
        '## Share of the torque per joint [% of summed RMS], nominal model split',
        '',
        _table('component', dataset.joints, pct, '.1f'),
        '',
        'remainder = target minus the nominal model (URDF rigid body + datasheet rotor inertia): '
        'friction and every effect the nominal model lacks.',
    ]
    if summary.true_shares:
        lines += [
            '',
            '## Share of tau_u per joint [%], twin ground truth',
            '',
            _table(
                'component',
                dataset.joints,
                {k: [100 * x for x in v] for k, v in summary.true_shares.items()},
                '.1f',
            ),
        ]
    if summary.noise_after_filter_nm:
        lines += [
            '',
            '## Label noise after filtering (measured minus noise-free, twin ground truth)',
            '',
            _table('', dataset.joints, {'RMS [N·m]': summary.noise_after_filter_nm}, '.3g'),
        ]
    lines += ['', '## Figures', ''] + [f'![{name}]({name})' for name in figures]
    (out / 'summary.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return summary


def _split_text(dataset: Dataset, n_train: int) -> str:
    if dataset.is_shuffled:
        return f'train/test split: {n_train} training samples drawn at random (shuffled)'
    return f'train/test split at sample {n_train} (contiguous)'
