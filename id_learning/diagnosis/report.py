"""The diagnosis report: DIR/report.md with figures, DIR/effects.json; ``diagnose`` writes both."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.recording import Recording
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.locate import LOCATION_VARIABLES
from id_learning.diagnosis.pipeline import DiagnosisResult, run_diagnosis
from id_learning.diagnosis.result import FoundEffect
from id_learning.diagnosis.separation import describe
from id_learning.physics.augmented import EFFECTS_JSON
from id_learning.physics.effects import REGISTRY
from id_learning.robot.config import RobotConfig

__all__ = ['EFFECTS_JSON', 'REPORT_MD', 'diagnose', 'render_summary', 'write_report']

_LOG = logging.getLogger(__name__)
REPORT_MD = 'report.md'


def write_report(result: DiagnosisResult, out: Path) -> Path:
    """Write report.md, effects.json and the PNG figures into ``out``; return report.md's path."""
    out.mkdir(parents=True, exist_ok=True)
    (out / EFFECTS_JSON).write_text(result.to_json(), encoding='utf-8')
    figures = _plot(result, out)
    path = out / REPORT_MD
    path.write_text(render_markdown(result, figures), encoding='utf-8')
    _LOG.info('diagnosis: wrote %s and %s', path, out / EFFECTS_JSON)
    return path


def _row(cells: list[str]) -> str:
    return '| ' + ' | '.join(cells) + ' |'


def _table(head: list[str], rows: list[list[str]], align: str = '---') -> list[str]:
    return [_row(head), _row([align] * len(head)), *[_row(r) for r in rows]]


def _parameter_text(parameter: dict[str, Any]) -> str:
    value = parameter['value']
    if parameter['ci'] is None:
        return f'{parameter["name"]} = {value} {parameter["unit"]}'
    low, high = parameter['ci']
    return f'{parameter["name"]} = {value:.4g} [{low:.4g}, {high:.4g}] {parameter["unit"]}'


def render_markdown(result: DiagnosisResult, figures: list[str]) -> str:
    """The report's Markdown text."""
    lines = [
        f'# Diagnosis: {", ".join(result.sources)}',
        '',
        f'Robot {result.robot.name}, {result.duration_s:.1f} s recorded, target '
        f'{"tau_u from motor currents" if result.target == "motor" else "joint torque"}. '
        'Nominal model: URDF rigid-body dynamics (RNEA)'
        + (' plus the datasheet rotor inertia. ' if result.target == 'motor' else '. ')
        + 'Every torque below is joint side [N·m], filtered like the label; RMSEs are on the '
        'held-out (last 30 %, contiguous) part.',
        '',
        *_verdict(result),
        *_effects(result),
        *_untestable(result),
        *_remainder(result),
        '## Figures',
        '',
        *[f'![{name}]({name})' for name in figures],
        '',
    ]
    return '\n'.join(lines)


def _verdict(result: DiagnosisResult) -> list[str]:
    """What was found, in words, and the held-out RMSE as each effect enters."""
    lines = ['## Verdict', '']
    named = result.named_effects()
    if named:
        for effect in named:
            where = f' on {effect.spec.joint_name}' if effect.spec.joint_name else ''
            lines.append(
                f'- **{effect.name}**{where}: '
                + '; '.join(_parameter_text(p) for p in effect.parameters)
                + f' (explains {_share(effect.variance_explained_total)} of the '
                f'disagreement; {_held_out(effect)}; confidence {effect.confidence})'
            )
    else:
        lines.append('- No named effect is needed to explain the data.')
    for alias in result.alias_sets:
        lines.append(
            '- **Alias set** (this excitation cannot tell them apart): '
            + alias.summary()
            + f'; the model keeps {alias.representative}.'
        )
    lines += [f'- **Refused**: {text}' for text in refused_texts(result)]
    structured = result.structured_joints()
    if structured:
        lines.append(
            '- **Unexplained remainder** on '
            + ', '.join(structured)
            + ': structure no candidate explains (see the remainder table).'
        )
    return [
        *lines,
        f'- Selection stopped: {result.stop_reason}.',
        '',
        '## Held-out RMSE before and after [N·m]',
        '',
        *_table(
            ['model', *result.joints],
            [
                ['nominal', *[f'{x:.3g}' for x in result.rmse_before_nm]],
                *[[f'+ {label}', *[f'{x:.3g}' for x in rmse]] for label, rmse in result.waterfall],
                ['RNEA+effects (as saved)', *[f'{x:.3g}' for x in result.rmse_after_nm]],
                ['noise level (estimate)', *[f'{x:.3g}' for x in result.noise.filtered_std_nm]],
            ],
        ),
        '',
        *_fallback_lines(result),
        'The held-out part took part in the choice (an effect must lower its error there, and '
        'it decides the fallback): `train` and `evaluate` score on data the diagnosis never saw.',
        '',
    ]


def _fallback_lines(result: DiagnosisResult) -> list[str]:
    """Which joints the saved model leaves to the nominal model, and why."""
    if not result.nominal_joints:
        return []
    return [
        f'The effects do not improve {", ".join(result.nominal_joints)} on the held-out part '
        '(judged over blocks of time): the saved model gives the nominal torque there.',
        '',
    ]


def _effects(result: DiagnosisResult) -> list[str]:
    """The refit model's effects with parameters and selection statistics; the alias sets."""
    lines: list[str] = []
    if result.effects:
        rows = [
            [
                effect.label,
                effect.status,
                effect.confidence,
                '<br>'.join(_parameter_text(p) for p in effect.parameters),
                ', '.join(_share(x).removesuffix(' %') for x in effect.variance_explained),
                f'F = {effect.selection["f_statistic"]:.1f}, '
                f'p = {effect.selection["p_value"]:.2g}, '
                f'ΔBIC = {effect.selection["delta_bic"]:.1f}',
            ]
            for effect in result.effects
        ]
        head = [
            'effect',
            'status',
            'confidence',
            'parameters [95 % interval]',
            'variance explained per joint [%]',
            'selection',
        ]
        lines += ['## Effects in the refit model', '', *_table(head, rows), '']
        lines += _marginalised(result)
    if result.alias_sets:
        lines += [
            '## Alias sets',
            '',
            "Alternatives ranked by what they leave of the kept effect's torque, or for one that "
            'fits as well in its place, by the fit it loses there (in residual variances per '
            'effective sample: 0 reproduces it exactly or fits as well).',
            '',
        ]
        for alias in result.alias_sets:
            detail = ', '.join(
                f'{m} ({alias.unexplained.get(m, float("nan")):.2g}; canonical correlation '
                f'{alias.canonical_correlation.get(m, 1.0):.3f}'
                + (f'; to tell apart: {describe(alias.separation[m])}' if m in alias.separation
                   else '')
                + ')'
                for m in alias.alternatives()
            )  # fmt: skip
            further = f'; {alias.further} more mimic it less closely' if alias.further else ''
            lines.append(f'- {alias.representative} ≈ {detail}{further}')
        lines.append('')
    return lines


def _marginalised(result: DiagnosisResult) -> list[str]:
    """Which datasheet values the parameters were estimated with, and which stood in."""
    if not result.marginalised:
        return []
    kinds = [item.tolerance_text() for item in REGISTRY.values() if item.datasheet_value
             and any(label.startswith(item.name) for label in result.marginalised)]  # fmt: skip
    lines = [
        'Parameters are estimated with these datasheet values free within their tolerances ('
        + ', '.join(kinds)
        + '), as no effect names them: '
        + ', '.join(result.marginalised)
        + '.',
        '',
    ]
    if result.stand_ins:
        lines += [
            '**Fitted far outside their tolerances**, standing in for an effect the model lacks: '
            + ', '.join(result.stand_ins)
            + ". The values above are the refit model's; the intervals carry the tolerances.",
            '',
        ]
    return lines


def _untestable(result: DiagnosisResult) -> list[str]:
    """Candidates this recording cannot test, and why."""
    lines = ['## Untestable on this recording', '']
    if not result.untestable:
        return [*lines, 'Every candidate is testable.', '']
    rows = [
        [u['name'], u['joint'] or '-', 'yes' if u['all_variants'] else 'some', u['reason']]
        for u in result.untestable
    ]
    return [*lines, *_table(['effect', 'joint', 'all variants', 'reason'], rows), '']


def _remainder(result: DiagnosisResult) -> list[str]:
    """The remainder after the refit against the noise, and where the nominal residual lives."""
    noise = result.noise
    rows = [
        [
            r.joint,
            f'{r.rms_nm:.3g}',
            f'{r.noise_nm:.3g}',
            f'{r.ratio:.2f}',
            f'{r.p_value:.2g}',
            f'{r.correlation_ratio:.1f}',
            'yes' if r.structured else 'no',
        ]
        for r in result.remainder
    ]
    head = ['joint', 'RMS [N·m]', 'noise [N·m]', 'ratio', 'p (variance)', 'corr. time ratio']
    return [
        '## Remainder after the refit',
        '',
        *_table([*head, 'structured'], rows),
        '',
        f'Noise: raw label {", ".join(f"{x:.3g}" for x in noise.raw_std_nm)} N·m white level '
        f'({_band(noise.band_hz)}); after the filter '
        f'{", ".join(f"{x:.3g}" for x in noise.filtered_std_nm)} N·m with correlation times '
        f'{", ".join(f"{x:.0f}" for x in noise.correlation_samples)} samples; effective '
        f'samples train {", ".join(f"{x:.0f}" for x in result.effective_samples["train"])}, '
        f'test {", ".join(f"{x:.0f}" for x in result.effective_samples["test"])}.',
        '',
        *_noise_warning(result),
        '## Where the nominal residual lives (share of its variance organised by each variable)',
        '',
        *_table(
            ['joint', 'RMS [N·m]', *[LOCATION_VARIABLES[k][0] for k in LOCATION_VARIABLES]],
            [
                [
                    loc.joint,
                    f'{loc.rms_nm:.3g}',
                    *[f'{100 * loc.explained_share[k]:.0f} %' for k in LOCATION_VARIABLES],
                ]
                for loc in result.location
            ],
        ),
        '',
    ]


def _plot(result: DiagnosisResult, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    files = []
    joints = list(result.joints)
    n = len(joints)

    # Waterfall: held-out RMSE per joint after each added effect.
    steps = ['nominal', *[label for label, _ in result.waterfall]]
    values = np.vstack([result.rmse_before_nm, *[rmse for _, rmse in result.waterfall]])
    cols = min(n, 3)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.2 * cols, 2.8 * rows + 0.6 * len(steps) / 3), squeeze=False,
        constrained_layout=True,
    )  # fmt: skip
    colours = plt.get_cmap('viridis')(np.linspace(0.1, 0.9, len(steps)))
    for j in range(rows * cols):
        ax = axes[j // cols][j % cols]
        if j >= n:
            ax.axis('off')
            continue
        ax.bar(range(len(steps)), values[:, j], color=colours)
        ax.axhline(result.noise.filtered_std_nm[j], color='k', ls='--', lw=0.8, label='noise')
        ax.set_title(joints[j], fontsize=9)
        ax.set_ylabel('held-out RMSE [N·m]', fontsize=8)
        if values[:, j].min() > 0 and values[:, j].max() > 20 * values[:, j].min():
            ax.set_yscale('log')  # many effects of very different sizes
        every = max(1, len(steps) // 12)
        ax.set_xticks(range(0, len(steps), every))
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3, axis='y')
    legend = '\n'.join(f'{k}: {s}' for k, s in enumerate(steps))
    fig.suptitle('Waterfall: held-out RMSE after each added effect (dashed: noise level)')
    # The key goes below the panels (bbox_inches='tight' keeps it in the file).
    fig.text(0.01, -0.01, legend, fontsize=7, va='top', family='monospace')
    fig.savefig(out / 'waterfall.png', dpi=110, bbox_inches='tight')
    plt.close(fig)
    files.append('waterfall.png')

    # Location: binned residual against each variable, per joint.
    keys = list(LOCATION_VARIABLES)
    fig, axes = plt.subplots(
        n, len(keys), figsize=(2.3 * len(keys), 1.7 * n), squeeze=False, constrained_layout=True
    )
    for j, loc in enumerate(result.location):
        for c, key in enumerate(keys):
            ax = axes[j][c]
            centres, means, stds = loc.bins[key]
            if centres:
                centre = np.asarray(centres)
                mean, std = np.asarray(means), np.asarray(stds)
                ax.fill_between(centre, mean - std, mean + std, color='C0', alpha=0.2, lw=0)
                ax.plot(centre, mean, 'o-', ms=2, lw=1, color='C0')
            ax.axhline(0, color='k', lw=0.5)
            ax.tick_params(labelsize=6)
            if j == 0:
                label, unit = LOCATION_VARIABLES[key]
                ax.set_title(f'{label} [{unit}]', fontsize=7)
            if c == 0:
                ax.set_ylabel(f'{loc.joint}\nresidual [N·m]', fontsize=7)
            ax.text(
                0.02, 0.9, f'{100 * loc.explained_share[key]:.0f} %', transform=ax.transAxes,
                fontsize=6,
            )  # fmt: skip
    fig.suptitle(
        'Nominal residual (measured minus nominal) against each variable: binned mean ± std'
    )
    fig.savefig(out / 'residual_location.png', dpi=100)
    plt.close(fig)
    files.append('residual_location.png')

    if result.series:
        t = result.series['time_s']
        before, after = result.series['residual_before'], result.series['residual_after']
        fig, axes = plt.subplots(n, 1, figsize=(11, 1.7 * n), sharex=True, squeeze=False,
                                 constrained_layout=True)  # fmt: skip
        for j in range(n):
            ax = axes[j][0]
            ax.plot(t, before[:, j], '.', ms=1, color='0.6', label='nominal')
            ax.plot(t, after[:, j], '.', ms=1, color='C3', label='refit model')
            ax.set_ylabel(f'{joints[j]}\n[N·m]', fontsize=7)
            ax.grid(alpha=0.3)
        axes[0][0].legend(loc='upper right', fontsize=7, markerscale=6)
        axes[-1][0].set_xlabel('time in the recording [s] (train and held-out parts)')
        fig.suptitle('Residual torque before and after the refit')
        fig.savefig(out / 'residual_time.png', dpi=100)
        plt.close(fig)
        files.append('residual_time.png')
    return files


def refused_texts(result: DiagnosisResult) -> list[str]:
    """One sentence per joint a refused candidate closed: what fitted, and the rule it fails."""
    return [
        f'{r["label"]} explains the residual on {r["joint"]} best (fitted '
        f'{", ".join(f"{x:.3g}" for x in r["fitted"])}) but fails its plausibility rule: '
        f'{r["reason"]}; no other effect is named there, its remainder stays unexplained'
        for r in result.refused
    ]


def render_summary(result: DiagnosisResult) -> str:
    """A terminal summary: the verdict in one line per finding, then the waterfall as a table."""
    joints = list(result.joints)
    lines = ['effects found:' if result.named_effects() else 'no named effect is needed']
    for effect in result.named_effects():
        where = f' on {effect.spec.joint_name}' if effect.spec.joint_name else ''
        lines.append(
            f'  {effect.name}{where}: '
            + '; '.join(_parameter_text(p) for p in effect.parameters)
            + f' ({effect.confidence} confidence)'
        )
    for alias in result.alias_sets:
        lines.append(f'  alias set (cannot be told apart here): {alias.summary()}')
    untestable = result.untestable_effects()
    if untestable:
        lines.append(
            '  untestable on this excitation: '
            + ', '.join(f'{name}[{joint}]' if joint else name for name, joint in untestable)
        )
    lines += [f'  refused: {text}' for text in refused_texts(result)]
    structured = result.structured_joints()
    if structured:
        lines.append(f'  unexplained structured remainder on: {", ".join(structured)}')
    width = max([24, *(len(label) + 2 for label, _ in result.waterfall)])
    column = max([10, *(len(joint) + 2 for joint in joints)])  # names never run together
    head = f'{"held-out RMSE [N*m]":<{width}}' + ''.join(f'{j:>{column}}' for j in joints)
    rows = [('nominal', result.rmse_before_nm)]
    rows += [(f'+ {label}', rmse) for label, rmse in result.waterfall]
    rows.append(('noise level (estimate)', result.noise.filtered_std_nm))
    lines += ['waterfall:', head]
    lines += [
        f'{name:<{width}}' + ''.join(f'{x:>{column}.3g}' for x in rmse) for name, rmse in rows
    ]
    return '\n'.join(lines)


def diagnose(
    data: Recording | Dataset | Sequence[Recording | Dataset],
    robot: RobotConfig,
    config: DiagnosisConfig | None = None,
    out_dir: Path | str | None = None,
) -> DiagnosisResult:
    """Diagnose recordings against the nominal model; write the report when ``out_dir`` is given.

    Args:
        data: recordings (preprocessed here) or datasets (from ``prepare_dataset``), one robot.
        robot: the robot config the recordings were made with.
        config: diagnosis settings; defaults if None.
        out_dir: folder for report.md, effects.json and the figures; nothing is written if None.

    Raises:
        DatasetError: the recordings do not match the robot, or are too short to diagnose.
        ConfigError: an invalid setting.
    """
    result = run_diagnosis(data, robot, config)
    if out_dir is not None:
        write_report(result, Path(out_dir))
    return result


def _share(x: float) -> str:
    """A share of the disagreement for readers: '<1 %' when tiny, 'none' when not positive."""
    if not x > 0:
        return 'none'
    return '<1 %' if x < 0.01 else f'{100 * x:.0f} %'


def _held_out(effect: FoundEffect) -> str:
    """The held-out block test of an effect, in words."""
    test = effect.selection.get('held_out_blocks')
    if not test:
        return 'held-out gain not judged'
    blocks = f'{test["n_blocks"]} blocks of {test["block_s"]:.2g} s'
    if test['p_value_holm'] is None:  # too few blocks
        return f'held-out part too short to judge ({blocks})'
    return f'held-out gain over {blocks}: p = {test["p_value_holm"]:.2g}'


def _band(band_hz: tuple[float, float] | np.ndarray) -> str:
    """The band the white noise level was read in, or where it was read when no band fits."""
    low, high = float(band_hz[0]), float(band_hz[1])
    if low < high:
        return f'median spectrum {low:.3g}–{high:.3g} Hz'
    return 'read at the top of the spectrum: the label filter leaves no noise-only band'


#: A remainder this many times the noise on every joint: the noise level was misread.
_NOISE_UNDERESTIMATE_RATIO = 5.0


def _noise_warning(result: DiagnosisResult) -> list[str]:
    """A warning when the remainder dwarfs the noise estimate on every joint."""
    if (
        not result.remainder
        or min(r.ratio for r in result.remainder) <= _NOISE_UNDERESTIMATE_RATIO
    ):
        return []
    return [
        f'**The noise level is probably underestimated**: the remainder is over '
        f'{_NOISE_UNDERESTIMATE_RATIO:g} times it on every joint. Real drives often have little '
        'noise above the band the models learn and much structure inside it; read the '
        'selection statistics (which use this level) as optimistic, and the held-out block '
        'tests as the verdict.',
        '',
    ]
