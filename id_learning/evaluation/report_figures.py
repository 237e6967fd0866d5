"""The report's PNG figures (a)-(d), the numbers only they show, and what all figures share.

Plotting is kept apart from the markdown (``report_tables``) and the findings (``findings``)
because it alone needs matplotlib (imported on first use, headless) and reads the models'
torque components; ``evaluation.report`` calls these functions and links the files. The other
figure modules (``report_signals``, ``closed_loop_report``) draw with the same helpers, so that
a model has one colour in every figure.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.signals import lowpass
from id_learning.evaluation.data_summary import shares
from id_learning.evaluation.findings import model_label
from id_learning.evaluation.study import MODEL_LABELS
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.data import nominal_rnea
from id_learning.robot.config import RobotConfig

__all__ = [
    'TRAJECTORY_SECONDS',
    'dissipative_figure',
    'model_colours',
    'model_styles',
    'plot_boxes',
    'plot_dissipative',
    'plot_rmse',
    'plot_shares',
    'pyplot',
    'rnea_lq_split',
    'save_figure',
    'torque_splits',
]

#: Stretch of the test part shown in the dissipative-torque figure [s].
TRAJECTORY_SECONDS = 60.0


def pyplot() -> Any:
    """Matplotlib's pyplot on the headless Agg back end (imported on first use)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path) -> None:
    """Save and close ``fig``; a write that fails (disk full) leaves no partial PNG at ``path``.

    Raises:
        OSError: the write failed (the OS's reason).
    """
    try:
        fig.savefig(path, dpi=110)
    except OSError:
        Path(path).unlink(missing_ok=True)
        raise
    finally:
        pyplot().close(fig)


#: Colours of the kinds beyond the study's seven (which take tab10's first seven): none grey,
#: which the figures keep for labels and feedback alone.
_EXTRA_COLOURS = {
    'rnea_id': 'tab:cyan',
    'rnea_effects': 'tab:olive',
    'rnea_id_mlp': '#1f3f8f',
    'rnea_effects_mlp': '#8b6914',
    'delan_id': '#6a3d9a',
    'lnn_mlp_id': '#b03060',
}
_SPARE_COLOURS = ('#2f4f4f', '#daa520', '#800000')
#: Line styles cycled over the models, so that lines of the same level stay told apart.
_LINE_STYLES: tuple[Any, ...] = ('-', (0, (5, 2)), (0, (3, 1, 1, 1)), (0, (1, 1)))


def model_colours(kinds: list[str]) -> dict[str, Any]:
    """A fixed colour per model kind, the same in every figure."""
    study = list(MODEL_LABELS)[:7]
    cmap = pyplot().get_cmap('tab10')
    colours: dict[str, Any] = {}
    spare = 0
    for kind in kinds:
        if kind in study:
            colours[kind] = cmap(study.index(kind))
        elif kind in _EXTRA_COLOURS:
            colours[kind] = _EXTRA_COLOURS[kind]
        else:
            colours[kind] = _SPARE_COLOURS[spare % len(_SPARE_COLOURS)]
            spare += 1
    return colours


def model_styles(kinds: list[str]) -> dict[str, dict[str, Any]]:
    """Per model, the colour and line style of its line: overlapping models stay visible."""
    colours = model_colours(kinds)
    return {
        kind: {'color': colours[kind], 'ls': _LINE_STYLES[i % len(_LINE_STYLES)]}
        for i, kind in enumerate(kinds)
    }


def plot_rmse(
    joints: tuple[str, ...],
    errors: dict[str, np.ndarray],
    path: Path,
    floor: np.ndarray | None = None,
    floor_label: str = 'label-noise floor',
) -> None:
    """Figure (a): bars of the per-joint normalised test RMSE, one per model.

    ``floor`` (n,), on the same normalised scale, is drawn as a line across each joint's bars:
    the error no model can go below, so that a bar near it has nothing left to learn.
    """
    plt = pyplot()
    kinds = list(errors)
    colours = model_colours(kinds)
    fig, ax = plt.subplots(figsize=(11, 4.2), constrained_layout=True)
    width = 0.8 / max(len(kinds), 1)
    x = np.arange(len(joints))
    for i, kind in enumerate(kinds):
        ax.bar(
            x + (i - (len(kinds) - 1) / 2) * width,
            errors[kind],
            width,
            label=model_label(kind),
            color=colours[kind],
        )
    values = [np.asarray(e, dtype=float) for e in errors.values()]
    if floor is not None:
        ax.hlines(
            floor,
            x - 0.45,
            x + 0.45,
            colors='k',
            linestyles='--',
            lw=1.6,
            zorder=3,
            label=floor_label,
        )
        values.append(np.asarray(floor, dtype=float))
    ax.set_xticks(x, joints)
    flat = np.concatenate(values) if values else np.zeros(0)
    positive = flat[flat > 0]
    if positive.size and positive.max() / positive.min() > 30:  # one bad model hides the rest
        ax.set_yscale('log')
    ax.set_ylabel('test RMSE, normalised [-1, 1] scale [-]')
    ax.set_title('Test RMSE per joint and model (lower is better)')
    ax.grid(axis='y', alpha=0.3)
    ax.legend(ncol=min(len(kinds) + (floor is not None), 5), fontsize=8, loc='upper left')
    save_figure(fig, path)


def plot_boxes(joints: tuple[str, ...], abs_errors: dict[str, np.ndarray], path: Path) -> None:
    """Figure (b): box plots of the absolute test errors, one panel per joint."""
    plt = pyplot()
    kinds = list(abs_errors)
    colours = model_colours(kinds)
    n = len(joints)
    cols = 3 if n > 3 else n
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False, constrained_layout=True
    )
    for j in range(rows * cols):
        ax = axes.flat[j]
        if j >= n:
            ax.set_visible(False)
            continue
        data = [abs_errors[k][:, j] for k in kinds]
        boxes = ax.boxplot(
            data, showfliers=False, whis=(5, 95), patch_artist=True, medianprops={'color': 'k'}
        )
        for patch, kind in zip(boxes['boxes'], kinds, strict=True):
            patch.set_facecolor(colours[kind])
            patch.set_alpha(0.8)
        ax.set_xticks(
            range(1, len(kinds) + 1),
            [model_label(k) for k in kinds],
            rotation=45,
            ha='right',
            fontsize=8,
        )
        ax.set_title(joints[j])
        ax.set_ylabel('|error| [N·m]')
        ax.grid(axis='y', alpha=0.3)
    fig.suptitle('Absolute test errors per joint and model (box: quartiles, whiskers: 5-95 %)')
    save_figure(fig, path)


def plot_dissipative(
    *,
    t: np.ndarray,
    measured: np.ndarray,
    estimates: dict[str, np.ndarray],
    frictions: dict[str, np.ndarray],
    joint: str,
    target: str,
    path: Path,
) -> None:
    """Figure (c): per model, its torque beyond the nominal RNEA against the measured one."""
    plt = pyplot()
    kinds = list(estimates)
    colours = model_colours(kinds)
    cols = 2
    rows = int(np.ceil(len(kinds) / cols))
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(12, 2.3 * rows + 0.8),
        sharex=True,
        sharey=True,
        squeeze=False,
        constrained_layout=True,
    )
    label = 'tau_u' if target == 'motor' else 'tau'
    for i in range(rows * cols):
        ax = axes.flat[i]
        if i >= len(kinds):
            ax.set_visible(False)
            continue
        kind = kinds[i]
        ax.plot(t, measured, color='0.55', lw=1.4, label=f'measured {label} - RNEA')
        ax.plot(
            t, estimates[kind], color=colours[kind], lw=1.1, label=f'{model_label(kind)} - RNEA'
        )
        if kind in frictions:
            ax.plot(
                t,
                frictions[kind],
                color=colours[kind],
                lw=1.0,
                ls='--',
                label=f'{model_label(kind)} friction part',
            )
        ax.set_title(model_label(kind), fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc='upper right')
        if i % cols == 0:
            ax.set_ylabel('[N·m]')
    for ax in axes[-1]:
        ax.set_xlabel('time in the test part [s]')
    fig.suptitle(
        f'{joint}: torque beyond the nominal rigid body (RNEA, URDF parameters) on a test '
        'stretch: measured vs each model'
    )
    save_figure(fig, path)


def plot_shares(
    joints: tuple[str, ...], splits: dict[str, dict[str, np.ndarray]], path: Path
) -> None:
    """Figure (d): stacked shares of the label torque per joint, one panel per split."""
    plt = pyplot()
    fig, axes = plt.subplots(
        1, len(splits), figsize=(6.5 * len(splits), 5.0), squeeze=False, constrained_layout=True
    )
    palette = {
        'inertia': 'C0',
        'gravity': 'C1',
        'coriolis': 'C2',
        'rotor inertia': 'C4',
        'friction': 'C3',
        'remainder (friction and unmodelled)': 'C3',
        'unexplained': '0.7',
    }
    for ax, (title, split) in zip(axes[0], splits.items(), strict=True):
        bottom = np.zeros(len(joints))
        for name, values in split.items():
            ax.bar(joints, 100 * values, bottom=bottom, label=name, color=palette.get(name))
            bottom += 100 * values
        ax.set_ylabel('share of summed RMS torque [%]')
        ax.set_ylim(0, 100)
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=8, loc='upper center', bbox_to_anchor=(0.5, -0.09), ncol=3)
    fig.suptitle('Where the label torque comes from, per joint')
    save_figure(fig, path)


def torque_splits(
    dataset: Dataset, components: dict[str, np.ndarray], models: dict[str, InverseDynamicsModel]
) -> dict[str, dict[str, np.ndarray]]:
    """The splits of figure (d): the nominal one, and RNEA+LQ's own when that model is there.

    Args:
        dataset: the preprocessed data.
        components: ``data_summary.nominal_components`` of ``dataset``.
        models: the report's models.
    """
    nominal = shares(components)
    splits = {
        'nominal split (URDF rigid body + datasheet rotor inertia)': {
            'inertia': nominal['inertia'],
            'gravity': nominal['gravity'],
            'coriolis': nominal['coriolis'],
            'rotor inertia': nominal['rotor_inertia'],
            'remainder (friction and unmodelled)': nominal['remainder'],
        }
    }
    lq_split = rnea_lq_split(models, dataset)
    if lq_split is not None:
        splits['RNEA+LQ split (fitted rotor inertia and friction)'] = lq_split
    return splits


def rnea_lq_split(
    models: dict[str, InverseDynamicsModel], dataset: Dataset
) -> dict[str, np.ndarray] | None:
    """The RNEA+LQ model's own split of the label, as shares; None without that model.

    Each part is the model's on a controller's inputs, filtered like the labels.
    """
    model = models.get('rnea_lq')
    if model is None:
        return None
    ds = dataset
    motion = ds.controller
    parts = model.components(motion.q, motion.v, motion.a)
    named = {
        'inertia': parts.inertial,
        'gravity': parts.gravity,
        'coriolis': parts.coriolis,
        'rotor inertia': parts.rotor_inertia,
        'friction': parts.friction,
    }
    present = {k: ds.filter_like_labels(v) for k, v in named.items() if v is not None}
    if not present:
        return None
    present['unexplained'] = ds.tau - ds.filter_like_labels(parts.total)
    return shares(present)


def dissipative_figure(
    *,
    robot: RobotConfig,
    dataset: Dataset,
    rows: list[tuple[int, int]],
    models: dict[str, InverseDynamicsModel],
    predictions: dict[str, np.ndarray],
    path: Path,
) -> None:
    """Plot axis 1 on the first evaluated stretch (at most TRAJECTORY_SECONDS), filtered.

    The stretch starts at ``rows[0]``, where the evaluated predictions begin: their head is
    reused. Everything is shown as the labels see it: through the label filter.
    """
    ds = dataset
    a, b = rows[0]
    b = min(b, a + round(TRAJECTORY_SECONDS / ds.period_s))
    motion = ds.controller
    rigid_body = nominal_rnea(robot, motion.q, motion.v, motion.a)
    baseline = ds.filter_like_labels(rigid_body)[a:b, 0]
    measured = ds.tau[a:b, 0] - baseline
    estimates, frictions = {}, {}
    stretch = motion.take(slice(a, b))
    for kind, model in models.items():
        estimates[kind] = predictions[kind][: b - a, 0] - baseline
        if not model.is_sequence_model:
            friction = model.components(stretch.q, stretch.v, stretch.a).friction
            if friction is not None:
                frictions[kind] = lowpass(friction, ds.cutoff_hz, ds.period_s, ds.filter_order)[
                    :, 0
                ]
    t = np.arange(b - a) * ds.period_s
    plot_dissipative(
        t=t,
        measured=measured,
        estimates=estimates,
        frictions=frictions,
        joint=ds.joints[0],
        target=ds.target,
        path=path,
    )
