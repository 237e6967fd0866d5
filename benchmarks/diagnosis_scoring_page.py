"""The results page of ``diagnosis_scoring.py``: its rates per scenario against the targets."""

from __future__ import annotations

from typing import Any

from common import markdown_table, number, share, verdict

__all__ = ['SHARE_DEFAULT', 'SHARE_NEEDED', 'SUCCESS_MEANS', 'report']

#: Share of the runs a target needs; where the target names none, that of nothing hidden (95 %).
SHARE_NEEDED = {'pair': 0.80}
SHARE_DEFAULT = 0.95
#: Per scenario family: what success means there.
SUCCESS_MEANS = {
    'nothing': 'nothing named',
    'aliased': 'an alias set holds the truth, no confident wrong name',
    'untestable': 'reported untestable, nothing named',
    'outside': 'an unexplained remainder on its joint, no confident name',
}


def single_rows(summary: dict[str, Any]) -> list[list[str]]:
    """One row per single or large effect: its three rates against >= 95 % each."""
    rows = []
    for scenario, entry in summary.items():
        if not scenario.startswith(('single', 'large')):
            continue
        rates = {
            'name': entry['right_name_and_joint_rate'],
            'parameter': entry['parameter_within_10pc_rate'],
            'gap': entry['gap_closed_ge_90pc_rate'],
        }
        failed = [key for key, rate in rates.items() if rate < SHARE_DEFAULT]
        rows.append(
            [
                f'**{scenario}**' if scenario == 'single:all' else scenario,
                entry['runs'],
                share(rates['name']),
                share(rates['parameter']),
                share(rates['gap']),
                share(entry.get('gap_closed_median')),
                number(entry.get('diagnose_s_median'), '.1f'),
                verdict(not failed) + (f' ({", ".join(failed)})' if failed else ''),
            ]
        )
    return rows


def other_rows(summary: dict[str, Any]) -> list[list[str]]:
    """One row per scenario judged by one rate: nothing, pair, aliased, untestable, outside."""
    rows = []
    for scenario, entry in summary.items():
        family = scenario.split(':')[0]
        if family == 'pair':
            rate, means = entry['exact_set_rate'], 'the exact set named'
        elif family in SUCCESS_MEANS:
            rate, means = entry['success_rate'], SUCCESS_MEANS[family]
        else:
            continue
        needed = SHARE_NEEDED.get(family, SHARE_DEFAULT)
        rows.append(
            [
                scenario,
                entry['runs'],
                means,
                share(rate),
                f'>= {share(needed)}',
                verdict(rate >= needed),
                number(entry.get('diagnose_s_median'), '.1f'),
            ]
        )
    return rows


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: the settings, then the rates per scenario against the targets."""
    from diagnosis_variants import variant_report

    options = document['settings']
    summary = document['summary']
    base = options.get('base_frequency')
    lines = [
        'The diagnosis on twin recordings whose hidden effects it is not told: '
        f'{options["seeds"]} seed(s) from {options["seed0"]} per scenario, '
        f'{options["duration"]:g} s recordings, each effect at {options["magnitude"]:g} times '
        'the post-filter noise level of its joint (large: ten times that), excitation base '
        + (f'frequency {base:g} Hz' if base is not None else "frequency the twin config's")
        + f'; scenarios {options["scenarios"]}'
        + (f', effects {",".join(options["effects"])}' if options.get('effects') else '')
        + '. The gap is the held-out error between the nominal and the true model, both through '
        f'the label filter. Wall time {document["wall_s"] / 60:.1f} min.',
        '',
        *settings,
    ]
    singles = single_rows(summary)
    if singles:
        lines += [
            'One effect hidden (single; large: ten times the magnitude). Target: the right name '
            'and joint (exactly that one named), its parameter within 10 % and >= 90 % of the gap '
            'closed, each in >= 95 % of the runs.',
            '',
            *markdown_table(
                [
                    'scenario',
                    'runs',
                    'right name and joint',
                    'parameter within 10 %',
                    'gap >= 90 % closed',
                    'gap closed (median)',
                    'diagnosis median [s]',
                    'target',
                ],
                singles,
                'lrrrrrrl',
            ),
            '',
        ]
    others = other_rows(summary)
    if others:
        lines += [
            'The other scenarios, each judged by one share of its runs (where the target names '
            'no share, the 95 % of nothing hidden).',
            '',
            *markdown_table(
                [
                    'scenario',
                    'runs',
                    'success means',
                    'measured',
                    'target',
                    'verdict',
                    'diagnosis median [s]',
                ],
                others,
                'lrlrllr',
            ),
            '',
        ]
    if any(scenario.startswith('variant') for scenario in summary):
        lines += variant_report(summary, document['runs'])
    return lines
