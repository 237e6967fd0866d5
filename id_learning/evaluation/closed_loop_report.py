"""The closed loop as the report shows it: a markdown section and its two figures.

``closed_loop.track`` runs the twin's loop; this module draws what a controls engineer reads from
it: per joint the tracking error with each model's feed-forward beside feedback alone and the
true inverse dynamics (a table from closed_loop.json, and the error over time), and the
feed-forward traces against the drives' torque limits with the saturated cycles marked. Models
that nearly coincide (an identified model and the true dynamics) are told apart by line style
and drawing order, and by a second column showing each feed-forward minus the true one.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.evaluation.closed_loop import FEEDBACK_ONLY, TRUE_DYNAMICS, Tracking
from id_learning.evaluation.findings import model_label
from id_learning.evaluation.report_figures import model_styles, pyplot, save_figure
from id_learning.evaluation.report_tables import markdown_table
from id_learning.outputs import write_text_atomic

__all__ = [
    'CLOSED_LOOP_HEADING',
    'RMS_WINDOW_S',
    'add_section',
    'closed_loop_section',
    'plot_feed_forward',
    'plot_tracking',
    'run_styles',
]

#: The heading of the closed-loop section, by which ``add_section`` finds an earlier one.
CLOSED_LOOP_HEADING = "## (h) Feed-forward in the twin's closed loop"
#: Window of the moving RMS the tracking figure draws [s].
RMS_WINDOW_S = 1.0
_FEEDBACK_STYLE = {'color': '0.6', 'ls': '-', 'lw': 2.4, 'zorder': 1}
_TRUE_STYLE = {'color': 'k', 'ls': (0, (2, 2)), 'lw': 1.6, 'zorder': 10}


def _name(run: str) -> str:
    """A run as the report names it: the model's label, or 'feedback only' / the truth."""
    return run if run in (FEEDBACK_ONLY, TRUE_DYNAMICS) else model_label(run)


def run_styles(names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Line styles per run: feedback alone wide and grey beneath, the truth dashed black on top.

    The models between take their report colours and cycled line styles, so that one drawn
    under the truth (an identified model) still shows through its dashes.
    """
    models = [n for n in names if n not in (FEEDBACK_ONLY, TRUE_DYNAMICS)]
    styles: dict[str, dict[str, Any]] = {
        kind: {**style, 'lw': 1.3, 'zorder': 2 + i}
        for i, (kind, style) in enumerate(model_styles(models).items())
    }
    styles[FEEDBACK_ONLY] = dict(_FEEDBACK_STYLE)
    styles[TRUE_DYNAMICS] = dict(_TRUE_STYLE)
    return {name: styles[name] for name in names}


def _moving_rms(x: np.ndarray, samples: int) -> np.ndarray:
    """Centred moving RMS of each column of x (N, n) over ``samples`` rows (fewer at the ends)."""
    sums = np.cumsum(np.concatenate([np.zeros((1, x.shape[1])), x**2]), axis=0)
    k = np.arange(len(x))
    lo = np.clip(k - samples // 2, 0, len(x))
    hi = np.clip(k + samples - samples // 2, 0, len(x))
    out: np.ndarray = np.sqrt((sums[hi] - sums[lo]) / (hi - lo)[:, None])
    return out


def _panels(n: int, cols: int, width: float, height: float) -> tuple[Any, Any]:
    """A figure of n rows by ``cols`` panels sharing the time axis."""
    figure_and_axes: tuple[Any, Any] = pyplot().subplots(
        n,
        cols,
        figsize=(width, height * n + 1.0),
        sharex=True,
        squeeze=False,
        constrained_layout=True,
    )
    return figure_and_axes


def _legend(fig: Any, ax: Any) -> None:
    """The runs' legend below the panels, taken from one panel."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc='outside lower center', ncol=min(len(labels), 6), fontsize=8)


def plot_tracking(
    runs: Mapping[str, Tracking], joints: Sequence[str], period_s: float, path: Path
) -> None:
    """Per joint, the moving RMS of each run's tracking error over time, on a log scale.

    A log scale keeps feedback alone (often ten times larger) and the feed-forwards on one
    panel; a diverged run is drawn up to the cycle it diverged at, marked with a cross.
    """
    from matplotlib import ticker

    styles = run_styles(list(runs))
    samples = max(1, round(RMS_WINDOW_S / period_s))
    fig, axes = _panels(len(joints), 1, 11.5, 1.7)
    for name, run in runs.items():
        stop = len(run.error) if run.diverged_at is None else run.diverged_at + 1
        t = np.arange(stop) * period_s
        level = 1e3 * _moving_rms(run.error[:stop], samples)
        for j, ax in enumerate(axes[:, 0]):
            ax.plot(t, level[:, j], label=_name(name), **styles[name])
            if run.diverged_at is not None:
                ax.plot(t[-1], level[-1, j], 'x', ms=8, color=styles[name]['color'])
    for j, ax in enumerate(axes[:, 0]):
        ax.set_yscale('log')
        # Ticks at 1, 2 and 5 per decade, written plainly: a decade or two stay readable.
        ax.yaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda y, _: f'{y:g}'))
        ax.yaxis.set_minor_formatter(ticker.NullFormatter())
        ax.set_ylabel(f'{joints[j]}\n[mrad]', fontsize=8)
        ax.grid(alpha=0.3, which='both')
    axes[-1, 0].set_xlabel('time along the reference [s]')
    _legend(fig, axes[0, 0])
    fig.suptitle(
        f"Tracking error in the twin's loop: moving RMS over {RMS_WINDOW_S:g} s of reference "
        'minus true position (log scale)'
    )
    save_figure(fig, path)


def _saturated(run: Tracking, j: int, limit: float) -> np.ndarray:
    """(N,) the cycles in which the run's command on joint j sat on its torque limit."""
    hit = np.abs(run.command[:, j]) >= limit * (1 - 1e-9)
    if run.diverged_at is not None:  # the command after it was never written
        hit[run.diverged_at + 1 :] = False
    out: np.ndarray = hit
    return out


def _limit_marks(
    ax: Any, t: np.ndarray, runs: Mapping[str, Tracking], j: int, *, limit: float, peak: float
) -> None:
    """The torque limit as red lines, and where each run's command sat on it, as ticks.

    A limit far beyond every trace (``peak`` below half of it) and never reached is only named.
    """
    styles = run_styles(list(runs))
    saturated = {name: _saturated(run, j, limit) for name, run in runs.items()}
    reached = any(hit.any() for hit in saturated.values())
    if reached or peak >= 0.5 * limit:
        note = f'torque limit ±{limit:g} N·m (red)'
        for sign in (1, -1):
            ax.axhline(sign * limit, color='tab:red', lw=1.2, zorder=0)
    else:
        note = f'torque limit ±{limit:g} N·m: off scale, never reached'
    for k, (name, hit) in enumerate(saturated.items()):
        if hit.any():  # each run's ticks a little further out, so that none hides another
            y = np.sign(runs[name].command[hit, j]) * limit * (1 + 0.03 * k)
            ax.plot(t[hit], y, '|', ms=6, color=styles[name]['color'])
    ax.text(
        1.0,
        1.0,
        note,
        transform=ax.transAxes,
        ha='right',
        va='bottom',
        fontsize=7,
        color='tab:red',
    )


def plot_feed_forward(
    feed_forwards: Mapping[str, np.ndarray],
    runs: Mapping[str, Tracking],
    *,
    limits: np.ndarray,
    joints: Sequence[str],
    period_s: float,
    path: Path,
) -> None:
    """Per joint, each feed-forward with the torque limits (left) and minus the true one (right).

    Args:
        feed_forwards: per run, (N, n) the feed-forward along the reference [N*m]; holds
            ``TRUE_DYNAMICS``.
        runs: the closed-loop runs, for the commands that hit the limit.
        limits: (n,) the drives' torque limits [N*m].
        joints: the joint names.
        period_s: the IPO period [s].
        path: the PNG to write.
    """
    styles = run_styles(list(feed_forwards))
    truth = feed_forwards[TRUE_DYNAMICS]
    t = np.arange(len(truth)) * period_s
    fig, axes = _panels(len(joints), 2, 14.0, 1.9)
    for j in range(len(joints)):
        left, right = axes[j]
        for name, ff in feed_forwards.items():
            left.plot(t, ff[:, j], label=_name(name), **styles[name])
            if name != TRUE_DYNAMICS:
                right.plot(t, ff[:, j] - truth[:, j], **styles[name])
        right.axhline(0.0, **{**_TRUE_STYLE, 'zorder': 0})
        peak = float(max(np.max(np.abs(ff[:, j])) for ff in feed_forwards.values()))
        _limit_marks(left, t, runs, j, limit=float(limits[j]), peak=peak)
        left.set_ylabel(f'{joints[j]}\n[N·m]', fontsize=8)
        for ax in (left, right):
            ax.grid(alpha=0.3)
    axes[0, 0].set_title('feed-forward tau_u along the reference', fontsize=9)
    axes[0, 1].set_title('feed-forward minus the true inverse dynamics', fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel('time along the reference [s]')
    _legend(fig, axes[0, 0])
    fig.suptitle('Feed-forward per joint, against the torque limits (saturated cycles ticked)')
    save_figure(fig, path)


def _tracking_table(document: Mapping[str, Any], key: str) -> str:
    """One row per run: per joint its error [mrad] (``key``: rms_rad or max_rad), and more.

    The RMS table also counts the cycles each run's command sat on a torque limit.
    """
    joints, runs = list(document['joints']), document['runs']
    base = np.asarray(runs[FEEDBACK_ONLY][key], dtype=float)
    rms = key == 'rms_rad'
    rows = []
    for name, run in runs.items():
        if run[key] is None:
            cells = [f'diverged at cycle {run["diverged_at_cycle"]}', *[''] * len(joints)]
        else:
            values = np.asarray(run[key], dtype=float)
            ratio = np.mean(values / np.where(base > 0, base, np.nan))
            cells = [*(f'{1e3 * x:.3g}' for x in values), f'{ratio:.3g}']
        saturated = [str(int(np.sum(run['saturated_cycles'])))] if rms else []
        rows.append([_name(name), *cells, *saturated])
    head = ['run', *joints, 'mean ratio to feedback only']
    return markdown_table(head + (['saturated cycles'] if rms else []), rows)


def closed_loop_section(
    document: Mapping[str, Any], figures: Sequence[tuple[str, str, str]]
) -> list[str]:
    """The report's closed-loop section from closed_loop.json's ``document``.

    Args:
        document: closed_loop.json's content (``training.closed_loop_run``).
        figures: (link relative to the report, caption, sentence) of each figure to show.
    """
    reference = document['reference']
    controller = document['controller']
    runs = document['runs']
    models = [name for name in runs if name not in (FEEDBACK_ONLY, TRUE_DYNAMICS)]
    best = document['best_model']
    factors = ', '.join(f'{x:.3g}' for x in document['improvement_best'])
    lines = [
        CLOSED_LOOP_HEADING,
        '',
        f'{reference["duration_s"]:.0f} s of {reference["part"]} of `{reference["bag"]}` '
        f'(rows {reference["rows"][0]}-{reference["rows"][1]}) tracked on the twin robot the '
        f'data came from, by a cascaded loop ({controller["structure"]}: '
        f'{1e3 * controller["period_s"]:g} ms): '
        f'with feedback alone, with each model ({", ".join(_name(m) for m in models)}) as '
        "feed-forward along the reference, and with the twin's true inverse dynamics, the best "
        'a feed-forward can do. Every run sees the same sensor noise. The tracking error is the '
        'reference minus the true position.',
        '',
        '### RMS tracking error per joint [mrad]',
        '',
        _tracking_table(document, 'rms_rad'),
        '',
        '### Largest tracking error per joint [mrad]',
        '',
        _tracking_table(document, 'max_rad'),
        '',
        f"Best model as feed-forward: **{_name(best)}**; feedback alone's RMS error divided by "
        f"its, per joint: {factors}. Saturated cycles count the IPO cycles in which a joint's "
        'command sat on its torque limit (summed over joints).',
        '',
    ]
    for link, caption, sentence in figures:
        lines += [f'### {caption}', '', sentence, '', f'![{caption}]({link})', '']
    return lines


def add_section(report: Path, lines: Sequence[str], out: Path) -> None:
    """Put the closed-loop section into ``report`` (report.md), replacing an earlier one.

    The section goes at the end; its figure links, relative to ``out`` in ``lines``, are made
    relative to the report's folder. The file is rewritten whole or not at all.

    Raises:
        OSError: reading or writing the report failed.
    """
    report = Path(report)
    prefix = Path(os.path.relpath(out, report.parent)).as_posix()
    text = report.read_text(encoding='utf-8')
    start = text.find(CLOSED_LOOP_HEADING)
    if start >= 0:  # an earlier section: up to the next section of the report, or the end
        end = text.find('\n## ', start + len(CLOSED_LOOP_HEADING))
        text = text[:start] + (text[end + 1 :] if end >= 0 else '')
    section = [
        line.replace('](', f']({prefix}/', 1) if line.startswith('![') else line for line in lines
    ]
    write_text_atomic(report, text.rstrip('\n') + '\n\n' + '\n'.join(section))
