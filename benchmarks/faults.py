"""Fault injection: bad input at the offline doors and the predictor core, outcomes classified.

    python benchmarks/faults.py [--out DIR] [--only SUBSTRING]

Builds a short twin recording, a fitted artifact and an import log, then breaks them one way at a
time (bad values, wrong types and units, truncated and corrupted bags and artifacts) and feeds
each to the door a user would: the ``id-learning`` commands (run in-process through the CLI's
``main``, exactly as the shell runs them), the replay's plan, ``bag recover`` and the predictor's
core. Each case is classified:

- ``clear_error``: refused (exit status != 0, or the documented exception) with a message that
  names what is wrong (the case's expected words);
- ``handled``: accepted on purpose and said so (a reordered joint list, a trimmed tail with a
  warning, a sample refused online while the stream goes on);
- ``silently_accepted``: exit 0 or a torque, with nothing said;
- ``traceback``: an exception the door did not turn into a message;
- ``data_lost``: a recovery that kept less than it should (less than 40 % of a bag cut at half).

Writes docs/results/faults.json and .md (per door and in all; not with --only). Prints one
JSON line with ``cases``, ``clear_error``, ``handled``,
``silently_accepted``, ``traceback``, ``data_lost`` and the cases that are not clear errors or
handled. Doors: train, evaluate, diagnose, sweep, import, inspect, simulate, bag recover, the
robot and twin configs and the URDF, the replay's plan, the predictor's core, and the nodes as
processes (bad settings and inputs, a SIGKILLed recorder and replay, a reference at 20x the IPO
rate) and the online check. ``test/test_faults.py`` runs every case in the test suite. The parts
live in ``fault_kit.py``, the cases in ``fault_cases_recordings.py``,
``fault_cases_settings.py`` and ``fault_cases_nodes.py``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections import Counter
from pathlib import Path

from common import write_results
from fault_cases_bags import bag_more_cases
from fault_cases_inputs import input_cases
from fault_cases_more_inputs import more_input_cases
from fault_cases_nodes import node_cases
from fault_cases_outputs import output_cases
from fault_cases_recordings import bag_cases, import_cases, replay_and_recover_cases
from fault_cases_settings import (
    artifact_cases,
    cli_cases,
    config_cases,
    other_door_cases,
    predictor_cases,
)
from fault_cases_streams import stream_cases
from fault_kit import KINDS, Case, Fixtures, Outcome, build_fixtures, cli, raises

__all__ = ['all_cases', 'build_fixtures', 'cli', 'raises', 'run_cases', 'summary']


# -- running --------------------------------------------------------------------------------------
def all_cases(fx: Fixtures) -> list[Case]:
    cases: list[Case] = []
    makers = (bag_cases, cli_cases, artifact_cases, predictor_cases, replay_and_recover_cases,
              import_cases, config_cases, other_door_cases, stream_cases, input_cases,
              more_input_cases, bag_more_cases, output_cases, node_cases)  # fmt: skip
    for make in makers:
        cases += list(make(fx))
    return cases


def run_cases(cases: list[Case]) -> list[tuple[Case, Outcome]]:
    results = []
    for case in cases:
        try:
            outcome = case.run()
        except Exception as error:
            outcome = Outcome('traceback', f'{type(error).__name__}: {error}')
        results.append((case, outcome))
        print(f'{outcome.kind:<18} {case.door:<12} {case.name}', file=sys.stderr, flush=True)
    return results


def summary(results: list[tuple[Case, Outcome]]) -> dict[str, object]:
    counts = Counter(outcome.kind for _, outcome in results)
    return {
        'cases': len(results),
        **{kind: counts.get(kind, 0) for kind in KINDS},
        'not_clear': [
            {'case': case.name, 'door': case.door, 'outcome': outcome.kind, 'said': outcome.said}
            for case, outcome in results
            if outcome.kind not in ('clear_error', 'handled')
        ],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path, help='keep the broken files here')
    parser.add_argument('--only', default='', help='run the cases whose name holds this')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        root = args.out or Path(scratch)
        root.mkdir(parents=True, exist_ok=True)
        print('building the fixtures (twin recording, rnea_lq run) ...', file=sys.stderr)
        fx = build_fixtures(root, train=True)
        cases = [c for c in all_cases(fx) if args.only in c.name]
        results = run_cases(cases)
    document = summary(results)
    print(json.dumps(document))
    if not args.only:  # the whole suite: its figures go to docs/results/faults.*
        write_results('faults', {**document, 'per_door': per_door(results)}, _table(results))
    return 0


def per_door(results: list[tuple[Case, Outcome]]) -> dict[str, dict[str, int]]:
    """Outcome counts per door."""
    counts: dict[str, Counter[str]] = {}
    for case, outcome in results:
        counts.setdefault(case.door, Counter())[outcome.kind] += 1
    return {door: {kind: c.get(kind, 0) for kind in KINDS} for door, c in sorted(counts.items())}


def _table(results: list[tuple[Case, Outcome]]) -> list[str]:
    lines = ['| door | cases | ' + ' | '.join(KINDS) + ' |', '|---|' + '---:|' * (len(KINDS) + 1)]
    doors = per_door(results)
    for door, counts in doors.items():
        lines.append(f'| {door} | {sum(counts.values())} | '
                     + ' | '.join(str(counts[k]) for k in KINDS) + ' |')  # fmt: skip
    total = Counter(outcome.kind for _, outcome in results)
    lines.append(f'| **all** | **{len(results)}** | '
                 + ' | '.join(f'**{total.get(k, 0)}**' for k in KINDS) + ' |')  # fmt: skip
    return lines


if __name__ == '__main__':
    sys.exit(main())
