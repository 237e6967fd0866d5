"""Plot the JointState samples of an ``inspect_bag`` report (or of a recording) to an image.

Apart from the analysis so that matplotlib is needed, and imported, only when a plot is asked for.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from id_learning.dataset.inspect_report import FIELDS, BagReport
from id_learning.dataset.recording import Recording
from id_learning.errors import ConfigError
from id_learning.output_kinds import OutputError, make_parent, os_reason

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ['image_suffixes', 'plot_report']


def image_suffixes() -> tuple[str, ...]:
    """The file suffixes matplotlib's Agg canvas writes ('.png', '.pdf', '.svg', ...)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    return tuple(sorted(f'.{name}' for name in FigureCanvasAgg.get_supported_filetypes()))


def _envelope(t: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Decimate (N,) times and (N, n) values to at most max_points per line.

    Keeps each bucket's minimum and maximum, so that spikes survive, and NaN only where a whole
    bucket is NaN.
    """
    if len(t) <= max_points:
        return t, y
    buckets = max(max_points // 2, 1)
    starts = np.linspace(0, len(t), buckets, endpoint=False).astype(np.int64)
    low = np.fmin.reduceat(y, starts, axis=0)
    high = np.fmax.reduceat(y, starts, axis=0)
    values = np.empty((2 * buckets, y.shape[1]))
    values[0::2], values[1::2] = low, high
    return np.repeat(t[starts], 2), values


_Row = tuple[str, str, np.ndarray, np.ndarray, tuple[str, ...]]


def _rows_from_report(report: BagReport) -> list[_Row]:
    """(title, y label, stamps [ns], values (N, n), joint names) per quantity, contract first."""
    contract = report.contract
    labels = {
        (contract.joint_states, 'position'): ('joint position', 'position [rad]'),
        (contract.joint_states, 'velocity'): ('joint velocity', 'velocity [rad/s]'),
        (contract.motor_currents, 'effort'): ('motor current', 'current [A]'),
        (contract.joint_states, 'effort'): ('joint torque', 'torque [N*m]'),
    }
    units = {'position': '[rad or m]', 'velocity': '[rad/s or m/s]', 'effort': '[N*m or N]'}
    rows: list[_Row] = []
    keys = list(labels) + [
        (topic, key) for topic in report.series for key in FIELDS if (topic, key) not in labels
    ]
    for topic, key in keys:
        series = report.series.get(topic)
        values = None if series is None else getattr(series, key)
        if series is None or values is None or not len(values):
            continue
        title, ylabel = labels.get((topic, key), (key, f'{key} {units[key]}'))
        rows.append((f'{title} ({topic})', ylabel, series.stamps_ns, values, series.names))
    return rows


def _rows_from_recording(recording: Recording) -> list[_Row]:
    quantities = (
        ('joint position', 'position [rad]', recording.position),
        ('joint velocity', 'velocity [rad/s]', recording.velocity),
        ('motor current', 'current [A]', recording.current),
        ('joint torque', 'torque [N*m]', recording.joint_torque),
    )
    return [
        (title, ylabel, recording.stamps_ns, values, recording.joints)
        for title, ylabel, values in quantities
        if values is not None
    ]


def plot_report(
    report: BagReport,
    out_png: Path | str,
    *,
    recording: Recording | None = None,
    max_points: int = 5000,
) -> Path:
    """Plot each joint's position, velocity, motor current and torque over time to one PNG.

    One row per quantity, one line per joint. Lines are decimated to at most ``max_points``
    points (per-bucket minimum and maximum, so spikes stay visible). Uses matplotlib's Agg canvas
    directly: no GUI, no change to pyplot's global state.

    Args:
        report: from ``inspect_bag``; its JointState samples are plotted unless a recording is
            given.
        out_png: the image to write, in the format its suffix names (``image_suffixes``);
            parent folders are created.
        recording: plot these samples instead (e.g. a loaded and filtered recording).
        max_points: upper bound on points per line.

    Returns:
        out_png.

    Raises:
        ConfigError: max_points is below 2, or the suffix is not an image format.
        OutputError: the image cannot be written (the path and the OS's reason).
    """
    from matplotlib.figure import Figure

    if max_points < 2:
        raise ConfigError(f'max_points must be at least 2, got {max_points}')
    out_png = Path(out_png)
    if out_png.suffix.lower() not in image_suffixes():
        raise ConfigError(
            f'{out_png}: not an image suffix; use one of {", ".join(image_suffixes())}'
        )
    rows = _rows_from_recording(recording) if recording is not None else _rows_from_report(report)
    firsts = [int(stamps[0]) for _, _, stamps, _, _ in rows if len(stamps)]
    origin = min(firsts) if firsts else report.start_ns

    figure = Figure(figsize=(12, 2.8 * max(len(rows), 1)), layout='constrained')
    axes = figure.subplots(max(len(rows), 1), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (title, ylabel, stamps, values, joints) in zip(axes, rows, strict=False):
        t, y = _envelope((stamps - origin) * 1e-9, values, max_points)
        for column, joint in enumerate(joints):
            ax.plot(t, y[:, column], linewidth=0.8, label=joint)
        ax.set_title(title, loc='left', fontsize='medium')
        ax.set_ylabel(ylabel)
        ax.grid(visible=True, alpha=0.3)
        ax.legend(loc='upper left', bbox_to_anchor=(1.005, 1.0), fontsize='small', frameon=False)
    if not rows:
        axes[0].text(0.5, 0.5, 'no JointState samples', ha='center', va='center')
    axes[-1].set_xlabel('time since first sample [s]')
    robot = f', robot {report.robot_name}' if report.robot_name else ''
    figure.suptitle(f'{report.path}: {report.start_iso}, {report.duration_s:.1f} s{robot}')
    _save(figure, out_png)
    return out_png


def _save(figure: Figure, out: Path) -> None:
    """Write ``figure`` through a temporary sibling and a rename: the image is whole or absent.

    A full disk is one line, leaving no torn image (and, with --force, the old one as it was).

    Raises:
        OutputError: creating the folder or writing the image failed (the OS's reason).
    """
    make_parent(out)
    tmp = out.with_name(f'.{out.name}.tmp-{os.getpid()}')
    try:
        figure.savefig(tmp, dpi=100, format=out.suffix[1:].lower())
        tmp.replace(out)
    except OSError as err:
        raise OutputError(
            f'{out}: {os_reason(err)} (writing the plot); nothing was written'
        ) from err
    finally:
        tmp.unlink(missing_ok=True)
