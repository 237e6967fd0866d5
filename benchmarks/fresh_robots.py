"""Robots the package has never seen: rnea_id's feed-forward on fresh twin robots, in the loop.

    python benchmarks/fresh_robots.py [--robots 4242:777,5151:888,6363:999] [--duration 600]
        [--closed-loop-seconds 60] [--work DIR [--reuse]]

Issue 39 asks of the identified physics, on the demo bag and on a fresh twin robot: in the
closed loop a tracking error within 1.25 x that of the true inverse dynamics on every joint, and
an error against the torque the drive needs within 2 x the label-noise floor on every joint.
``generalisation.py`` checks the demo bag's robot on unseen motion; this checks robots drawn
afresh. Per ``SEED:ROBOT_SEED`` of ``--robots``, through the ``id-learning`` CLI, each step a
subprocess whose wall time is recorded:

1. ``simulate --config config/twin_default.yaml --seed SEED --robot-seed ROBOT_SEED``: a new
   hidden robot (link masses and centres of mass drawn anew) on a new excitation,
   ``--duration`` seconds long;
2. ``train --models rnea_id`` on it (its training part, the default split);
3. ``closed-loop`` on its test part (``--closed-loop-seconds``) on its own twin.

Per robot and joint: the test part's RMSE through the label filter and against the needed
torque, each over the label-noise floor (the run's metrics.json), and the tracking RMS with
``rnea_id`` over that with the true inverse dynamics (closed_loop.json); then the two checks,
pass or fail with their figures. Prints the page on stderr and the JSON document on stdout;
writes docs/results/fresh_robots.json and .md (not with ``--no-results``; ``--results-folder``
elsewhere).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import (
    DEFAULT_ROBOT,
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    repo_path,
    settings_lines,
    verdict,
)
from generalisation import (
    LOOP_TO_TRUE,
    NEEDED_LIMIT,
    TRUE_DYNAMICS,
    cli,
    loop_figures,
    read_json,
    run_step,
)

NAME = 'fresh_robots'
DEFAULT_TWIN = REPO / 'config' / 'twin_default.yaml'
KIND = 'rnea_id'


def robot_pairs(text: str) -> list[tuple[int, int]]:
    """``SEED:ROBOT_SEED,...`` as pairs of integers.

    Raises:
        ValueError: an item is not two integers joined by a colon, or a robot seed repeats.
    """
    pairs = []
    for item in (part.strip() for part in text.split(',') if part.strip()):
        seed, _, robot_seed = item.partition(':')
        pairs.append((int(seed), int(robot_seed)))
    robot_seeds = [r for _, r in pairs]
    if not pairs or len(set(robot_seeds)) != len(robot_seeds):
        raise ValueError(f'expected SEED:ROBOT_SEED pairs of distinct robot seeds, got {text!r}')
    return pairs


def measure(seed: int, robot_seed: int, args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """Simulate, train and track one fresh robot; its figures and steps."""
    folder = work / f'robot_{robot_seed}'
    folder.mkdir(parents=True, exist_ok=True)
    bag, run, loop = folder / 'bag', folder / 'run', folder / 'closed_loop'
    reuse = args.reuse
    steps = {
        'simulate': run_step(
            f'{robot_seed}: simulate',
            cli(
                'simulate',
                '--config',
                args.twin,
                '--out',
                bag,
                '--seed',
                seed,
                '--robot-seed',
                robot_seed,
                '--duration',
                args.duration,
                '--quiet',
                '--force',
            ),
            folder / 'simulate.log',
            bag / 'metadata.yaml' if reuse else None,
        ),
    }
    entry: dict[str, Any] = {'seed': seed, 'robot_seed': robot_seed, 'steps': steps}
    if steps['simulate']['returncode'] == 0:
        steps['train'] = run_step(
            f'{robot_seed}: train',
            cli(
                'train',
                '--bag',
                bag,
                '--out',
                run,
                '--robot',
                args.robot,
                '--models',
                KIND,
                '--quiet',
                '--force',
            ),
            folder / 'train.log',
            run / 'metrics.json' if reuse else None,
        )
    if steps.get('train', {}).get('returncode') == 0:
        steps['closed-loop'] = run_step(
            f'{robot_seed}: closed-loop',
            cli(
                'closed-loop',
                '--run',
                run,
                '--out',
                loop,
                '--duration',
                args.closed_loop_seconds,
                '--quiet',
                '--force',
            ),
            folder / 'closed_loop.log',
            loop / 'closed_loop.json' if reuse else None,
        )
    metrics = read_json(run / 'metrics.json')
    model = (metrics or {}).get('models', {}).get(KIND, {})
    entry['through_filter_over_floor'] = model.get('rmse_through_filter_over_floor')
    entry['needed_over_floor'] = model.get('rmse_needed_over_floor')
    closed_loop = read_json(loop / 'closed_loop.json')
    figures = loop_figures(closed_loop) if closed_loop else {}
    entry['loop_over_true'] = figures.get(KIND, {}).get('over_true')
    entry['loop_rms_rad'] = {
        name: figures.get(name, {}).get('rms_rad') for name in (KIND, TRUE_DYNAMICS)
    }
    entry['checks'] = [
        check(
            f'{KIND} in the loop within {LOOP_TO_TRUE:g} x the true inverse dynamics',
            entry['loop_over_true'],
            LOOP_TO_TRUE,
        ),
        check(
            f'{KIND} against the needed torque within {NEEDED_LIMIT:g} x the floor',
            entry['needed_over_floor'],
            NEEDED_LIMIT,
        ),
    ]
    return entry


def check(name: str, figures: list[float | None] | None, limit: float) -> dict[str, Any]:
    """Every joint's figure at most ``limit``; None (no figure) fails."""
    worst = None if not figures or None in figures else max(figures)  # type: ignore[type-var]  # None excluded above
    return {
        'check': name,
        'worst': worst,
        'limit': limit,
        'passed': worst is not None and worst <= limit,
    }


def page(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page: per robot the figures per joint, then the checks."""
    joints = document['joints']
    lines = [
        f'Fresh twin robots (`{document["twin"]}`, each drawn from its robot seed: link masses '
        'and centres of mass, with every hidden effect of the default twin), each recorded for '
        f'{document["duration_s"]:g} s on an excitation of its own seed; `{KIND}` trained on '
        'its training part and judged on its test part: the RMSE through the label filter and '
        'against the torque the drive needs (the planned reference, unfiltered), each over the '
        'label-noise floor, and the tracking RMS in the closed loop '
        f'({document["closed_loop_seconds"]:g} s of the test part) over that of the true '
        f'inverse dynamics. Wall time {document["wall_s"] / 60:.1f} min.',
        '',
        *settings,
    ]
    rows = []
    for entry in document['robots']:
        label = f'{entry["robot_seed"]} (seed {entry["seed"]})'
        for key, name in (
            ('through_filter_over_floor', 'through the filter / floor'),
            ('needed_over_floor', 'needed torque / floor'),
            ('loop_over_true', 'closed loop / true ID'),
        ):
            values = entry[key] or [None] * len(joints)
            rows.append([label, name, *(number(v, '.3g') for v in values)])
    lines += markdown_table(['robot', 'figure', *joints], rows, 'll' + 'r' * len(joints))
    lines += [
        '',
        *markdown_table(
            ['robot', 'check', 'worst joint', 'limit', 'verdict'],
            [
                [
                    entry['robot_seed'],
                    c['check'],
                    number(c['worst'], '.3g'),
                    f'{c["limit"]:g}',
                    verdict(c['passed']),
                ]
                for entry in document['robots']
                for c in entry['checks']
            ],
            'lllrl',
        ),
    ]
    checks = [c for entry in document['robots'] for c in entry['checks']]
    lines += ['', f'{sum(c["passed"] for c in checks)} of {len(checks)} checks pass.']
    failed = {
        f'{entry["robot_seed"]}: {name}': step['error']
        for entry in document['robots']
        for name, step in entry['steps'].items()
        if step.get('returncode')
    }
    for where, error in failed.items():
        lines += ['', f'Step failed, {where}:', '', '```', error, '```']
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--robots',
        default='4242:777,5151:888,6363:999',
        help='SEED:ROBOT_SEED pairs, comma-separated',
    )
    parser.add_argument('--duration', type=float, default=600.0, help='each recording [s]')
    parser.add_argument(
        '--closed-loop-seconds', type=float, default=60.0, help='test part tracked [s]'
    )
    parser.add_argument('--twin', type=Path, default=DEFAULT_TWIN, help='twin config')
    parser.add_argument('--robot', type=Path, default=DEFAULT_ROBOT, help='robot config')
    parser.add_argument('--work', type=Path, help='keep bags, runs and logs here')
    parser.add_argument('--reuse', action='store_true', help="reuse --work's complete steps")
    add_results_options(parser)
    args = parser.parse_args()
    try:
        pairs = robot_pairs(args.robots)
    except ValueError as err:
        parser.error(f'--robots: {err}')
    if args.reuse and args.work is None:
        parser.error('--reuse needs --work')
    began = time.perf_counter()
    work = args.work or Path(tempfile.mkdtemp(prefix='fresh_robots_'))
    robots = [measure(seed, robot_seed, args, work) for seed, robot_seed in pairs]
    from id_learning.robot import load_robot_config

    document = {
        'benchmark': NAME,
        'twin': repo_path(args.twin),
        'kind': KIND,
        'joints': list(load_robot_config(args.robot).joints),
        'duration_s': args.duration,
        'closed_loop_seconds': args.closed_loop_seconds,
        'robots': robots,
        'wall_s': time.perf_counter() - began,
    }
    complete = all(not s.get('returncode') for r in robots for s in r['steps'].values())
    if args.work is None and complete:
        shutil.rmtree(work, ignore_errors=True)
    elif not complete:
        print(f'work kept in {work}', file=sys.stderr)
    finish(NAME, document, page(document, settings_lines(NAME, parser, args)), args)
    return 0 if complete and all(c['passed'] for r in robots for c in r['checks']) else 1


if __name__ == '__main__':
    sys.exit(main())
