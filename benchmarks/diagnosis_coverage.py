"""Are the diagnosis' parameters right and its intervals honest on twin recordings, all effects on?

Fresh twin recordings (seeds no test uses) with every effect of ``config/twin_default.yaml`` on:
for each friction, torque-constant scale, delay, payload-mass and rotor-inertia parameter in
the refit model (named, or kept for an alias set), whether it lies within 15 % of the twin's
true value and whether its 95 % interval holds that value. A torque-constant error is judged
as the scale s (true k_t / datasheet k_t), the number the report gives; a rotor inertia as the
motor-side J_m; the rest as the twin states them, in the twin's (joint-side, true) units. A
viscous law the diagnosis found curved (with an exponent) has no coefficient to compare with
the twin's linear one: it is counted apart.

    python benchmarks/diagnosis_coverage.py [--seeds 7,8,9] [--duration 300] [--jobs 2]
        [--out out/benchmarks/diagnosis_coverage.json]

Prints the rates per effect and overall, and writes the per-parameter details to ``--out``;
writes docs/results/diagnosis_coverage.json and .md (not with ``--no-results``;
``--results-folder`` elsewhere).
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import (  # noqa: E402
    add_results_options,
    markdown_table,
    publish_results,
    settings_lines,
    share,
    verdict,
)

from id_learning.diagnosis import run_diagnosis  # noqa: E402
from id_learning.twin import load_twin_config, simulate  # noqa: E402

TWIN = REPO / 'config' / 'twin_default.yaml'
JUDGED = (
    'viscous_friction',
    'coulomb_friction',
    'stribeck_friction',
    'load_dependent_friction',
    'torque_constant_scale',
    'signal_delay',
    'payload_mass',
    'rotor_inertia',
)
#: The targets, as shares of the judged parameters: within 15 % of the truth, and the 95 %
#: intervals holding it as often as their level says.
TARGET_WITHIN = 0.95
TARGET_COVERED = 0.95


def truth_of(name: str, joint: int | None, effects: dict[str, Any], rotor: Any) -> float:
    """The twin's true value of the parameter the report gives first for an effect."""
    section = effects[name]
    if name in ('viscous_friction', 'load_dependent_friction'):
        return float(section['coefficient'][joint])
    if name in ('coulomb_friction', 'stribeck_friction'):
        return float(section['level'][joint])
    if name == 'torque_constant_scale':
        return float(section['scale'][joint])
    if name == 'signal_delay':
        return float(section['delay_s'])
    if name == 'payload_mass':
        return float(section['mass_kg'])
    return float(section['scale'][joint] * rotor[joint])  # the motor-side rotor inertia


def run_seed(seed: int, duration_s: float) -> list[dict[str, Any]]:
    config = load_twin_config(TWIN, {'seed': seed})
    effects = yaml.safe_load(TWIN.read_text(encoding='utf-8'))['effects']
    config = replace(config, excitation=replace(config.excitation, duration_s=duration_s))
    result = run_diagnosis(simulate(config).recording, config.robot)
    rotor = config.robot.drives.rotor_inertia
    rows = []
    for effect in result.effects:
        if effect.name not in JUDGED:
            continue
        if effect.name == 'viscous_friction' and effect.spec.settings.get('exponent', 1.0) != 1:
            # A curved law's coefficients are not the twin's linear one: counted, not judged.
            rows.append({'seed': seed, 'effect': effect.label, 'name': effect.name,
                         'judged': False})  # fmt: skip
            continue
        first = effect.parameters[0]
        truth = truth_of(effect.name, effect.spec.joint, effects, rotor)
        low, high = first['ci']
        rows.append(
            {
                'seed': seed,
                'effect': effect.label,
                'judged': True,
                'status': effect.status,
                'name': effect.name,
                'parameter': first['name'],
                'value': first['value'],
                'interval': [low, high],
                'truth': truth,
                'within_15pc': abs(first['value'] - truth) <= 0.15 * abs(truth),
                'covered': min(low, high) <= truth <= max(low, high),
                'interval_inflation': effect.selection.get('interval_inflation'),
            }
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seeds', default='7,8,9')
    parser.add_argument('--duration', type=float, default=300.0)
    parser.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument(
        '--out', type=Path, default=REPO / 'out' / 'benchmarks' / 'diagnosis_coverage.json'
    )
    add_results_options(parser)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(',')]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = [row for part in pool.map(run_seed, seeds, [args.duration] * len(seeds))
                for row in part]  # fmt: skip
    summary: dict[str, dict[str, Any]] = {}
    for name in (*JUDGED, 'all'):
        items = [r for r in rows if r['judged'] and name in ('all', r['name'])]
        if items:
            summary[name] = {
                'parameters': len(items),
                'within_15pc': sum(r['within_15pc'] for r in items),
                'covered': sum(r['covered'] for r in items),
            }
    document = {
        'benchmark': 'diagnosis_coverage',
        'settings': {'seeds': seeds, 'duration_s': args.duration},
        'wall_s': time.perf_counter() - start,
        'summary': summary,
        'rows': rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(document, indent=1) + '\n', encoding='utf-8')
    for name, entry in summary.items():
        n = entry['parameters']
        print(
            f'{name:26s} {n:3d} named: within 15 % {entry["within_15pc"]:3d} '
            f'({100 * entry["within_15pc"] / n:.0f} %), 95 % interval holds the truth '
            f'{entry["covered"]:3d} ({100 * entry["covered"] / n:.0f} %)'
        )
    curved = sum(not r['judged'] for r in rows)
    print(f'{curved} curved viscous laws not judged (no linear coefficient to compare)')
    lines = report(document, curved, settings_lines('diagnosis_coverage', parser, args))
    publish_results('diagnosis_coverage', document, lines, args)
    return 0


def report(document: dict[str, Any], curved: int, settings: list[str]) -> list[str]:
    """The results page's body: per effect the shares within 15 % and covered, then overall."""
    rows = []
    for name, entry in document['summary'].items():
        n = entry['parameters']
        within, covered = entry['within_15pc'] / n, entry['covered'] / n
        judged = name == 'all'
        rows.append(
            [
                '**all**' if judged else name,
                n,
                f'{entry["within_15pc"]} ({share(within)})',
                f'{entry["covered"]} ({share(covered)})',
                verdict(within >= TARGET_WITHIN) if judged else '',
                verdict(covered >= TARGET_COVERED) if judged else '',
            ]
        )
    settings_used = document['settings']
    return [
        "The diagnosis' parameters and their 95 % intervals on fresh twin recordings with every "
        f'effect of config/twin_default.yaml on: seed(s) '
        f'{", ".join(str(seed) for seed in settings_used["seeds"])}, '
        f'{settings_used["duration_s"]:g} s each. Each friction, torque-constant scale, delay, '
        'payload-mass and rotor-inertia parameter of the refit model (named, or kept for an '
        "alias set) against the twin's true value (torque constant as the scale s, rotor "
        'inertia motor-side). Wall time '
        f'{document["wall_s"] / 60:.1f} min.',
        '',
        *settings,
        f'Target: every parameter within 15 % of the truth and a 95 % interval that holds it, '
        f'judged over all parameters at >= {share(TARGET_WITHIN)} within 15 % and '
        f">= {share(TARGET_COVERED)} covered (the intervals' level).",
        '',
        *markdown_table(
            [
                'effect',
                'parameters',
                'within 15 %',
                '95 % interval holds the truth',
                'within 15 %: target',
                'covered: target',
            ],
            rows,
            'lrrrll',
        ),
        '',
        f'{curved} curved viscous law(s) not judged (no linear coefficient to compare with the '
        "twin's).",
    ]


if __name__ == '__main__':
    raise SystemExit(main())
