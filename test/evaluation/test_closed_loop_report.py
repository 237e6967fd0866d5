"""The closed loop in the report: a section with every run's row, figures that tell runs apart."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import FAST_HYPER, twin_config

from id_learning.evaluation.closed_loop import FEEDBACK_ONLY, TRUE_DYNAMICS, Tracking
from id_learning.evaluation.closed_loop_report import (
    CLOSED_LOOP_HEADING,
    add_section,
    closed_loop_section,
    plot_feed_forward,
    plot_tracking,
    run_styles,
)
from id_learning.training import train_run
from id_learning.training.closed_loop_run import closed_loop_run
from id_learning.twin import simulate, write_twin_output

PNG = b'\x89PNG\r\n\x1a\n'
JOINTS = ('j1', 'j2')


def _document(runs: dict[str, list[float] | None]) -> dict:
    """A closed_loop.json document with the given per-joint RMS errors [rad] (None: diverged)."""
    return {
        'reference': {
            'bag': 'bags/x',
            'rows': [700, 1200],
            'duration_s': 4.0,
            'part': 'the test part',
        },
        'joints': list(JOINTS),
        'controller': {'structure': 'position P, velocity PI, torque limit', 'period_s': 0.008},
        'runs': {
            name: {
                'rms_rad': rms,
                'max_rad': None if rms is None else [3 * x for x in rms],
                'saturated_cycles': [0, 5] if name == FEEDBACK_ONLY else [0, 0],
                'diverged_at_cycle': 42 if rms is None else None,
            }
            for name, rms in runs.items()
        },
        'best_model': 'rnea_id',
        'improvement_best': [10.0, 20.0],
    }


DOCUMENT = _document({
    FEEDBACK_ONLY: [1e-3, 2e-3],
    'rnea_id': [1e-4, 1e-4],
    'mlp': [5e-4, 1e-3],
    'lstm': None,
    TRUE_DYNAMICS: [1e-4, 9e-5],
})  # fmt: skip


def test_the_section_has_a_row_per_run_in_both_tables_with_ratios_and_saturation():
    lines = closed_loop_section(DOCUMENT, [('closed_loop.png', 'Tracking', 'What it shows.')])
    text = '\n'.join(lines)
    assert lines[0] == CLOSED_LOOP_HEADING
    rms, largest = text.split('### RMS tracking error per joint [mrad]')[1].split(
        '### Largest tracking error per joint [mrad]'
    )
    for table in (rms, largest):
        for row in ('| feedback only |', '| rnea_id |', '| MLP |', '| LSTM |'):
            assert row in table
        assert '| true inverse dynamics |' in table
        assert '| LSTM | diverged at cycle 42 |' in table
    # Per joint in mrad, the mean ratio to feedback alone, the saturated cycles (RMS table).
    assert '| feedback only | 1 | 2 | 1 | 5 |' in rms
    assert '| MLP | 0.5 | 1 | 0.5 | 0 |' in rms
    assert '| MLP | 1.5 | 3 | 0.5 |' in largest
    assert 'Best model as feed-forward: **rnea_id**' in text
    assert '10, 20' in text
    assert 'What it shows.\n\n![Tracking](closed_loop.png)' in text


def test_the_section_replaces_an_earlier_one_and_links_from_the_reports_folder(tmp_path):
    report = tmp_path / 'run' / 'report.md'
    report.parent.mkdir()
    report.write_text('# Run\n\n## Figures\n\nfigures\n\n## Fits cut short\n\n- mlp\n')
    lines = closed_loop_section(DOCUMENT, [('closed_loop.png', 'Tracking', 'What it shows.')])
    add_section(report, lines, tmp_path / 'closed_loop')
    add_section(report, lines, tmp_path / 'closed_loop')  # again: replaced, not repeated
    text = report.read_text()
    assert text.count(CLOSED_LOOP_HEADING) == 1
    assert text.startswith('# Run\n\n## Figures\n\nfigures\n\n## Fits cut short\n\n- mlp\n\n')
    assert '![Tracking](../closed_loop/closed_loop.png)' in text
    # A section followed by another keeps the other.
    report.write_text(text + '\n## Later\n\nkept\n')
    add_section(report, lines, tmp_path / 'closed_loop')
    text = report.read_text()
    assert text.count(CLOSED_LOOP_HEADING) == 1
    assert '## Later\n\nkept' in text
    assert text.index('## Later') < text.index(CLOSED_LOOP_HEADING)


def test_runs_that_coincide_are_drawn_apart_and_limits_and_saturation_are_marked(tmp_path):
    styles = run_styles([FEEDBACK_ONLY, 'rnea_id', 'mlp', TRUE_DYNAMICS])
    # The truth dashed and on top of a model drawn solid beneath it; every model its own look.
    assert styles[TRUE_DYNAMICS]['zorder'] > styles['rnea_id']['zorder']
    assert styles[TRUE_DYNAMICS]['ls'] != styles['rnea_id']['ls']
    assert styles['rnea_id']['ls'] != styles['mlp']['ls']
    assert styles['rnea_id']['color'] != styles['mlp']['color']
    assert styles[FEEDBACK_ONLY]['lw'] > styles['mlp']['lw']
    n, period = 600, 0.008
    t = np.arange(n) * period
    truth = np.column_stack([80 * np.sin(t), 5 * np.cos(t)])
    feed_forwards = {'rnea_id': truth + 0.1, 'mlp': 0.8 * truth, TRUE_DYNAMICS: truth}
    limits = np.array([75.0, 500.0])  # j1's command sits on its limit near the sine's peaks
    runs = {}
    for k, name in enumerate([FEEDBACK_ONLY, *feed_forwards]):
        command = np.clip(truth * (1.2 - 0.1 * k), -limits, limits)
        error = 1e-3 * (k + 1) * np.column_stack([np.sin(3 * t), np.cos(2 * t)])
        runs[name] = Tracking(error, command, (np.abs(command) >= limits).sum(axis=0))
    runs['mlp'] = Tracking(runs['mlp'].error, runs['mlp'].command, runs['mlp'].saturated, 400)
    plot_tracking(runs, JOINTS, period, tmp_path / 'tracking.png')
    plot_feed_forward(feed_forwards, runs, limits=limits, joints=JOINTS, period_s=period,
                      path=tmp_path / 'ff.png')  # fmt: skip
    for name in ('tracking.png', 'ff.png'):
        assert (tmp_path / name).read_bytes()[:8] == PNG


@pytest.fixture(scope='module')
def twin_run(mabi, tmp_path_factory):
    """A short training run (RNEA+LQ, MLP) on one 60 s twin bag."""
    folder = tmp_path_factory.mktemp('closed_loop')
    config = twin_config(60.0, seed=21)
    bag = write_twin_output(simulate(config), config, folder / 'bag')
    return train_run([bag], mabi, 'motor', ['rnea_lq', 'mlp'], folder / 'run', hyper=FAST_HYPER,
                     progress=False, device='cpu')  # fmt: skip


def test_a_closed_loop_run_writes_its_section_and_adds_it_to_the_runs_report(
    twin_run, mabi, tmp_path
):
    report = twin_run.out / 'report.md'
    before = report.read_text()
    result = closed_loop_run(
        twin_run.out, mabi, tmp_path / 'loop', duration_s=4.0, progress=False, report=report
    )
    document = json.loads(result.json_path.read_text())
    for path in (result.plot_path, result.feed_forward_plot_path):
        assert path.read_bytes()[:8] == PNG
    own, added = result.report_path.read_text(), report.read_text()
    assert added.startswith(before.rstrip('\n'))
    for text in (own, added):
        section = text.split(CLOSED_LOOP_HEADING)[1]
        for row in ('| feedback only |', '| RNEA+LQ |', '| MLP |', '| true inverse dynamics |'):
            assert section.count(row) == 2  # in the RMS and in the largest-error table
        assert f'| MLP | {1e3 * document["runs"]["mlp"]["rms_rad"][0]:.3g} |' in section
    assert '![Tracking error over time per joint](closed_loop.png)' in own
    links = [
        line for line in added.splitlines() if line.startswith('![') and 'closed_loop' in line
    ]
    assert len(links) == 2
    for link in links:
        target = link[link.index('](') + 2 : -1]
        assert (report.parent / target).resolve() in (
            result.plot_path.resolve(),
            result.feed_forward_plot_path.resolve(),
        )
