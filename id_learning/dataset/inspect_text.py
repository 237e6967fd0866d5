"""Render an ``inspect_bag`` report as aligned plain text, one helper per report section."""

from __future__ import annotations

from collections.abc import Sequence

from id_learning.dataset.inspect_report import (
    FIELDS,
    MAX_LISTED,
    BagReport,
    FieldStats,
    TopicReport,
)

__all__ = ['render_report']


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str) -> list[str]:
    """Align columns, align[i] being 'l' (text) or 'r' (numbers) for column i."""
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        parts = [
            cell.ljust(width) if side == 'l' else cell.rjust(width)
            for cell, width, side in zip(cells, widths, align, strict=True)
        ]
        return ('  ' + '  '.join(parts)).rstrip()

    return [line(header), '  ' + '  '.join('-' * width for width in widths), *map(line, rows)]


def _number(value: float | None, digits: int = 3) -> str:
    return '-' if value is None else f'{value:.{digits}f}'


#: Said where no robot config was given: what is then not judged, and how to have it judged.
_NO_ROBOT = (
    '- (not given: limits, the IPO grid and whether samples follow from the ones before them are '
    'not checked; pass --robot CONFIG, as train reads the bag with its default robot)'
)


def _percent(fraction: float | None) -> str:
    return '-' if fraction is None else f'{100 * fraction:.2f} %'


def render_report(report: BagReport) -> str:
    """Format a report as aligned plain text for a terminal."""
    lines = [
        f'bag       {report.path}',
        f'storage   {report.storage}, {len(report.files)} file(s): {", ".join(report.files)}',
        f'start     {report.start_iso} ({report.start_ns} ns)',
        f'duration  {report.duration_s:.3f} s, {report.message_count} messages',
        f'robot     {report.robot_name or _NO_ROBOT}',
        '',
        'topics',
        *_timing_table(report),
    ]
    for topic in report.topics:
        lines += _gap_lines(topic) + _stamp_lines(topic) + _joint_lines(topic)
    lines += _verdict_lines(report)
    return '\n'.join(lines) + '\n'


def _timing_table(report: BagReport) -> list[str]:
    """One row per topic: type, count, time base, rate, period, jitter and stamp anomalies."""
    rows = []
    for topic in report.topics:
        timing = topic.timing
        jitter = (
            '-'
            if timing.jitter_std_ms is None
            else f'{timing.jitter_std_ms:.3f} / {_number(timing.jitter_p99_ms)}'
        )
        period = None if timing.median_period_s is None else timing.median_period_s * 1e3
        rows.append(
            [
                topic.name,
                topic.msgtype,
                str(topic.count),
                timing.time_base,
                _number(timing.rate_hz),
                _number(period),
                jitter,
                str(timing.gap_count),
                str(timing.repeated_count),
                str(timing.backward_count),
            ]
        )
    return _table(
        [
            'topic',
            'type',
            'count',
            'stamps',
            'rate [Hz]',
            'period [ms]',
            'jitter std / p99 [ms]',
            'gaps',
            'repeated',
            'backward',
        ],
        rows,
        'llrlrrrrrr',
    )


def _gap_lines(topic: TopicReport) -> list[str]:
    """The listed gaps of one topic, as a table; nothing without gaps."""
    timing = topic.timing
    if not timing.gap_count:
        return []
    nominal_ms = (timing.nominal_period_s or 0.0) * 1e3
    listed = f', first {MAX_LISTED} listed' if timing.gap_count > MAX_LISTED else ''
    return [
        '',
        f'gaps on {topic.name} ({timing.gap_count}, nominal period {nominal_ms:.3f} ms{listed})',
        *_table(
            ['before sample', 'stamp [ns]', 'periods'],
            [[str(g.sample), str(g.stamp_ns), f'{g.periods:.2f}'] for g in timing.gaps],
            'rrr',
        ),
    ]


def _stamp_lines(topic: TopicReport) -> list[str]:
    """The samples of one topic whose stamps repeat or go backwards."""
    timing = topic.timing
    lines: list[str] = []
    for label, count, samples in (
        ('repeated stamps', timing.repeated_count, timing.repeated),
        ('backward stamps', timing.backward_count, timing.backward),
    ):
        if count:
            listed = ', '.join(map(str, samples)) + (', ...' if count > len(samples) else '')
            lines += ['', f'{label} on {topic.name} ({count}) at samples {listed}']
    return lines


def _joint_lines(topic: TopicReport) -> list[str]:
    """Per joint and field: range, mean, non-finite count and share outside the limits."""
    if not topic.joints:
        return []
    rows = []
    for joint in topic.joints:
        for key in FIELDS:
            stats: FieldStats | None = getattr(joint, key)
            if stats is None:
                continue
            limit = {
                'position': joint.position_outside_limits,
                'velocity': joint.velocity_outside_limits,
                'effort': joint.effort_outside_limits,
            }.get(key)
            rows.append(
                [
                    joint.name,
                    key,
                    _number(stats.minimum, 4),
                    _number(stats.maximum, 4),
                    _number(stats.mean, 4),
                    str(stats.non_finite),
                    _percent(limit),
                ]
            )
    return [
        '',
        f'joints on {topic.name}',
        *_table(
            ['joint', 'field', 'min', 'max', 'mean', 'non-finite', 'outside limits'],
            rows,
            'llrrrrr',
        ),
    ]


def _verdict_lines(report: BagReport) -> list[str]:
    """The contract check and the list of problems."""
    contract = report.contract
    pair = f'{contract.joint_states} / {contract.motor_currents}'
    if contract.joint_torques_only:
        verdict = (
            f'joint torques in {contract.joint_states} effort, no {contract.motor_currents}: '
            'labels for --target joint (motor labels need the currents)'
        )
    elif contract.missing:
        found = dict(contract.wrong_types)
        verdict = 'missing ' + ', '.join(
            f'{name} (it has type {found[name]})' if name in found else name
            for name in contract.missing
        )
    elif contract.stamps_match:
        verdict = 'stamps match sample for sample'
    else:
        verdict = f'stamps differ from sample {contract.first_mismatch} on'
    if contract.names_match is False:
        verdict += '; joint names differ'
    for name in contract.several_types:
        verdict += f'; {name} holds several message types'
    for name, key in contract.empty_fields:
        verdict += f'; {name} carries no {key}'
    problems = report.problems
    return [
        '',
        f'contract  {pair}: {verdict}',
        '',
        f'problems  {len(problems) or "none"}',
        *(f'  - {problem}' for problem in problems),
    ]
