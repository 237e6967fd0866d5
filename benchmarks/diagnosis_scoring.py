"""Score the diagnosis on twin recordings whose hidden effects it is not told.

Scenarios (each over --seeds seeds; magnitudes are multiples of the post-filter noise level of
the affected joint, measured on the twin's ground truth):

- nothing: no effect hidden; target: nothing named in >= 95 % of the runs;
- single:<effect>: one effect at --magnitude times the noise; target: right name and joint
  (exactly that one named) in >= 95 %, its parameter within 10 %, >= 90 % of the held-out gap to
  the true model closed (true model: the twin's noise-free tau_u filtered like the label);
- pair: two effects at once; target: the exact set in >= 80 %;
- aliased:<case>: effects this excitation cannot tell apart; target: an alias set holding the
  truth, no confident wrong name;
- untestable:cogging: cogging far above the filter cut-off; target: reported untestable, nothing
  named;
- outside: a torque outside the library (a slow drift in time); target: an unexplained remainder
  on its joint and no confident wrong name.

    python benchmarks/diagnosis_scoring.py [--seeds 10] [--duration 200] [--magnitude 3]
        [--jobs 2] [--scenarios nothing,single,large,pair,aliased,untestable,outside]
        [--effects payload_mass,rotor_inertia]
        [--out out/benchmarks/diagnosis_scoring.json]

Prints per-scenario rates and timing, and writes the JSON document (per-run details included) to
``--out``; writes docs/results/diagnosis_scoring.json and .md, the rates against the targets (not
with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import os

# One BLAS thread per process: on a small shared machine threaded LAPACK only waits on itself.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import argparse
import json
import math
import platform
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import (  # noqa: E402
    add_results_options,
    publish_results,
    settings_lines,
)

from id_learning.dataset.preprocess import lowpass  # noqa: E402
from id_learning.diagnosis import (  # noqa: E402
    DiagnosisResult,
    column_motion,
    evaluation_rows,
    filtered_prediction,
    run_diagnosis,
)
from id_learning.physics import NominalModel, effect_columns  # noqa: E402
from id_learning.robot.drives import current_from_motor_torque  # noqa: E402
from id_learning.twin import TwinConfig, load_twin_config, simulate  # noqa: E402

TWIN = REPO / 'config' / 'twin_default.yaml'
JOINTS = ('joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_5', 'joint_6')

#: single-effect scenarios: effect -> joints it goes on (rotated over seeds; None: robot-wide).
#: The gravity spring sits where gravity sweeps a real torque.
SINGLE: dict[str, tuple[str, ...] | None] = {
    'viscous_friction': JOINTS,
    'coulomb_friction': JOINTS,
    'stribeck_friction': JOINTS,
    'load_dependent_friction': ('joint_2', 'joint_3', 'joint_4', 'joint_5'),
    'rotor_inertia': JOINTS,
    'gravity_spring': ('joint_2', 'joint_3'),
    'payload_mass': None,
    # On joint_6 the nominal torque is almost only the rotor's: three noise levels there would
    # need a torque constant off by a factor 2.7, where the rotor inertia is the plausible name.
    'torque_constant_scale': JOINTS[:5],
    'signal_delay': None,
    'torque_offset': JOINTS,
    'inertial_parameter_error': None,
}
#: effects also run at ten times the magnitude (scenario large:<effect>).
#: (Not the rotor inertia or the inertial error: ten times the noise makes them several times
#: their datasheet values, which the plausibility rules rightly refuse.)
LARGE = ('gravity_spring', 'payload_mass')
#: pairs placed together (rotated over seeds).
PAIRS = (
    (('viscous_friction', 'joint_2'), ('torque_offset', 'joint_4')),
    (('coulomb_friction', 'joint_1'), ('rotor_inertia', 'joint_3')),
    (('torque_constant_scale', 'joint_5'), ('viscous_friction', 'joint_6')),
    (('signal_delay', None), ('torque_offset', 'joint_1')),
    (('load_dependent_friction', 'joint_3'), ('coulomb_friction', 'joint_2')),
    (('stribeck_friction', 'joint_2'), ('torque_offset', 'joint_5')),
)


# -- effects at a chosen size ---------------------------------------------------------------------
def effect_section(name: str, joint: str | None, size: float, seed: int) -> dict[str, Any]:
    """The twin's effects entry for one effect; ``size`` scales its reference strength.

    Every reference value is linear (or very nearly) in ``size``, so one calibration run gives
    the size for a target magnitude.
    """
    j = JOINTS.index(joint) if joint else None

    def on_joint(value: float, neutral: float = 0.0) -> list[float]:
        out = [neutral] * len(JOINTS)
        assert j is not None
        out[j] = value
        return out

    if name == 'viscous_friction':
        return {'enabled': True, 'coefficient': on_joint(10.0 * size)}
    if name == 'coulomb_friction':
        return {'enabled': True, 'level': on_joint(5.0 * size)}
    if name == 'stribeck_friction':
        return {
            'enabled': True,
            'level': on_joint(10.0 * size),
            'velocity': [0.03] * len(JOINTS),
        }
    if name == 'load_dependent_friction':
        return {'enabled': True, 'coefficient': on_joint(0.01 * size)}
    if name == 'rotor_inertia':
        return {'enabled': True, 'scale': on_joint(1.0 + 0.2 * size, 1.0)}
    if name == 'gravity_spring':
        return {
            'enabled': True,
            'joint': joint,
            'preload_n': 30.0 * size,
            'stiffness_n_per_m': 250.0 * size,
        }
    if name == 'payload_mass':
        return {
            'enabled': True,
            'mass_kg': 1.0 * size,
            'com_m': [0.1, 0.0, 0.03],
            'inertia_kgm2': [0.0, 0.0, 0.0],
        }
    if name == 'joint_offset':
        return {'enabled': True, 'offset': on_joint(0.001 * size)}
    if name == 'torque_constant_scale':
        # tau_u from currents is tau / s: the column gain c = 1 / s - 1 is what scales.
        return {'enabled': True, 'scale': on_joint(1.0 / (1.0 + 0.02 * size), 1.0)}
    if name == 'signal_delay':
        return {'enabled': True, 'delay_s': 0.002 * size}
    if name == 'torque_offset':
        return {'enabled': True, 'offset': on_joint(2.0 * size)}
    if name == 'cogging':
        return {'enabled': True, 'amplitude': on_joint(2.0 * size)}
    if name == 'inertial_parameter_error':
        return {'enabled': True, 'mass_rel_std': 0.01 * size, 'com_std_m': 0.003 * size}
    raise ValueError(name)


def true_parameter(name: str, section: dict[str, Any], joint: str | None) -> float | None:
    """The value the diagnosis' coefficient should recover (None: judged by its torque)."""
    j = JOINTS.index(joint) if joint else None
    if name in ('viscous_friction', 'load_dependent_friction'):
        return section['coefficient'][j]
    if name in ('coulomb_friction', 'stribeck_friction'):
        return section['level'][j]
    if name == 'rotor_inertia':
        return None  # compared as the change of inertia, below
    if name == 'payload_mass':
        return section['mass_kg']
    if name in ('joint_offset', 'torque_offset'):
        return section['offset'][j]
    if name == 'torque_constant_scale':
        return 1.0 / section['scale'][j] - 1.0
    if name == 'signal_delay':
        return section['delay_s']
    return None


# -- running one scenario -------------------------------------------------------------------------
def twin(seed: int, duration_s: float, effects: dict[str, Any], **excitation: Any) -> TwinConfig:
    config = load_twin_config(TWIN, {'effects': effects, 'seed': seed})
    return replace(
        config, excitation=replace(config.excitation, duration_s=duration_s, **excitation)
    )


def filtered(x: np.ndarray, dataset: Any) -> np.ndarray:
    return lowpass(x, dataset.cutoff_hz, dataset.period_s, dataset.filter_order)


def named_set(result: DiagnosisResult) -> set[tuple[str, str | None]]:
    return {(e.name, e.spec.joint_name or None) for e in result.named_effects()}


def alias_members(result: DiagnosisResult) -> list[set[tuple[str, str | None]]]:
    sets = []
    for alias in result.to_dict()['alias_sets']:
        sets.append({(m['name'], m['joint']) for m in alias['members']})
    return sets


def gap_closed(result: DiagnosisResult, dataset: Any, clean: np.ndarray) -> dict[str, float]:
    """Share of the held-out gap between the nominal and the true model that the refit closes.

    On the rows the diagnosis scored (held-out part, filter edges trimmed); the models' filtered
    torques are the label minus the residuals the diagnosis reports (``filtered_prediction``
    gives the same along a whole recording).
    """
    series = result.series
    test = series['is_test']
    rows = np.round(series['time_s'][test] / dataset.period_s).astype(int)
    truth = filtered(clean, dataset)[rows]
    nominal = (series['label'] - series['residual_before'])[test]
    model = (series['label'] - series['residual_after'])[test]
    weight = 1.0 / result.noise.filtered_std_nm
    before = float(np.sqrt(np.sum(((nominal - truth) * weight) ** 2)))
    after = float(np.sqrt(np.sum(((model - truth) * weight) ** 2)))
    return {
        'gap_before_weighted': before,
        'gap_after_weighted': after,
        'gap_closed': 1.0 - after / before if before > 0 else math.nan,
    }


def torque_error(
    result: DiagnosisResult, recording: Any, name: str, true_torque: np.ndarray
) -> float | None:
    """Relative RMS error of one found effect's torque against the true one (filtered, test)."""
    effects = [e for e in result.effects if e.name == name]
    if not effects:
        return None
    dataset, _ = filtered_prediction(result, recording, with_effects=False)
    q, v, a, jerk = column_motion(dataset)
    quantities = result.nominal_model.evaluate(q, v, a, jerk, derivatives=True, regressor=True)
    fitted = sum(
        effect_columns(e.spec, quantities, result.nominal_model) @ e.coefficients for e in effects
    )
    rows = evaluation_rows(dataset, result.settings)['test']
    truth = filtered(true_torque, dataset)[rows]
    fitted = filtered(np.asarray(fitted), dataset)[rows]
    return float(np.linalg.norm(fitted - truth) / np.linalg.norm(truth))


def parameter_error(
    result: DiagnosisResult,
    name: str,
    joint: str | None,
    section: dict[str, Any],
    robot_rotor: np.ndarray,
) -> float | None:
    """Relative error of the effect's coefficient, for effects with one physical parameter."""
    match = [e for e in result.effects if e.name == name and (e.spec.joint_name or None) == joint]
    if not match:
        return None
    effect = match[0]
    if name == 'rotor_inertia':
        j = JOINTS.index(joint or '')
        truth = (section['scale'][j] - 1.0) * robot_rotor[j]
    else:
        truth = true_parameter(name, section, joint)
    if truth is None:
        return None
    return float(abs(effect.coefficients[0] - truth) / abs(truth))


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    """One diagnosis on one twin recording; ``case`` says what is hidden."""
    start = time.perf_counter()
    seed, duration = case['seed'], case['duration_s']
    excitation = case.get('excitation', {})
    base_config = twin(seed, duration, {}, **excitation)
    base = simulate(base_config)
    hidden = case['hidden']  # list of (name, joint)
    sections: dict[str, dict[str, Any]] = {}
    from id_learning.dataset.preprocess import prepare_dataset

    dataset = prepare_dataset(base.recording, base_config.robot)
    rows = evaluation_rows(dataset)['test']
    noise = np.sqrt(
        np.mean(
            (dataset.tau - filtered(base.tau_u_clean, dataset))[rows] ** 2,
            axis=0,
        )
    )
    for name, joint in hidden:
        if 'raw_size' in case:  # a size fixed before the filter (cogging far above the cut-off)
            sections[name] = effect_section(name, joint, case['raw_size'], seed)
            continue
        # Calibrate: a reference run gives the effect's filtered held-out RMS per unit size.
        reference = effect_section(name, joint, 1.0, seed)
        if name == 'joint_offset':
            # The offset moves the measured q, not the torque: its apparent torque is the
            # nominal model's change between the true and the measured position.
            model = NominalModel(base_config.robot)
            offset = np.asarray(reference['offset'])
            apparent = (
                model.evaluate(base.q_true, base.v_true, base.a_true).tau_nominal
                - model.evaluate(base.q_true - offset, base.v_true, base.a_true).tau_nominal
            )
        else:
            ref = simulate(twin(seed, duration, {name: reference}, **excitation))
            apparent = ref.tau_u_clean - base.tau_u_clean
        effect = filtered(apparent, dataset)[rows]
        rms = np.sqrt(np.mean(effect**2, axis=0))
        j = JOINTS.index(joint) if joint else int(np.argmax(rms / noise))
        size = case['magnitude'] * noise[j] / rms[j]
        sections[name] = effect_section(name, joint, size, seed)
    config = twin(seed, duration, sections, **excitation) if sections else base_config
    result_twin = simulate(config) if sections else base
    recording = result_twin.recording
    if case.get('drift'):
        joint, amplitude_sigma, period = case['drift']
        j = JOINTS.index(joint)
        t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
        drift = np.zeros_like(recording.current)
        drift[:, j] = amplitude_sigma * noise[j] * math.sqrt(2) * np.sin(2 * np.pi * t / period)
        recording = replace(
            recording,
            current=recording.current + current_from_motor_torque(drift, config.robot.drives),
        )
    simulated = time.perf_counter()
    result = run_diagnosis(recording, config.robot)
    diagnosed = time.perf_counter()
    out: dict[str, Any] = {
        'scenario': case['scenario'],
        'seed': seed,
        'hidden': [list(h) for h in hidden],
        'hidden_parameters': sections,
        'named': sorted([list(x) for x in named_set(result)], key=str),
        'confidence': {e.label: e.confidence for e in result.named_effects()},
        'alias_sets': [sorted([list(m) for m in s], key=str) for s in alias_members(result)],
        'untestable': [list(x) for x in result.untestable_effects()],
        'structured_joints': result.structured_joints(),
        'noise_true_nm': noise.tolist(),
        'noise_estimated_nm': result.noise.filtered_std_nm.tolist(),
        'stop_reason': result.stop_reason,
        'simulate_s': simulated - start,
        'diagnose_s': diagnosed - simulated,
    }
    truth = {(name, joint) for name, joint in hidden}
    named = named_set(result)
    out['exact'] = named == truth
    out['truth_named'] = truth <= named
    # Named, or in an alias set, with nothing else named.
    covered = named | {m for s in alias_members(result) if s & truth for m in s}
    out['named_or_aliased'] = truth <= covered and named <= covered
    if case['scenario'].startswith(('single', 'large')) and hidden:
        name, joint = hidden[0]
        out.update(gap_closed(result, dataset, result_twin.tau_u_clean))
        change = filtered(result_twin.tau_u_clean - base.tau_u_clean, dataset)[rows]
        j = JOINTS.index(joint) if joint else None
        achieved = np.sqrt(np.mean(change**2, axis=0)) / noise
        out['magnitude_achieved'] = float(achieved[j] if j is not None else achieved.max())
        error = parameter_error(
            result, name, joint, sections[name], config.robot.drives.rotor_inertia
        )
        if error is None and name in ('gravity_spring', 'inertial_parameter_error'):
            true_torque = result_twin.tau_u_clean - base.tau_u_clean
            error = torque_error(result, recording, name, true_torque)
        out['parameter_error'] = error
        out['parameter_within_10pc'] = error is not None and error <= 0.10
    if case['scenario'].startswith('aliased'):
        sets = alias_members(result)
        out['in_alias_set'] = any(truth <= s for s in sets)
        out['wrong_confident'] = any(
            e.confidence == 'high' and (e.name, e.spec.joint_name or None) not in truth
            for e in result.named_effects()
        )
        out['success'] = out['in_alias_set'] and not out['wrong_confident']
    if case['scenario'].startswith('untestable'):
        out['success'] = truth <= set(result.untestable_effects()) and not named
    if case['scenario'] == 'outside':
        joint = case['drift'][0]
        out['remainder_flagged'] = joint in result.structured_joints()
        out['wrong_confident'] = any(e.confidence == 'high' for e in result.named_effects())
        out['success'] = out['remainder_flagged'] and not out['wrong_confident']
    if case['scenario'] == 'nothing':
        out['success'] = not named
    return out


# -- the plan and the summary ---------------------------------------------------------------------
def plan(args: argparse.Namespace) -> list[dict[str, Any]]:
    wanted = set(args.scenarios.split(','))
    cases: list[dict[str, Any]] = []
    common: dict[str, Any] = {'duration_s': args.duration, 'magnitude': args.magnitude}
    if args.base_frequency is not None:
        common['excitation'] = {'base_frequency_hz': args.base_frequency}
    for seed in range(args.seed0, args.seed0 + args.seeds):
        if 'nothing' in wanted:
            cases.append({**common, 'scenario': 'nothing', 'seed': seed, 'hidden': []})
        if 'single' in wanted:
            for name, joints in SINGLE.items():
                if args.effects and name not in args.effects:
                    continue
                joint = None if joints is None else joints[seed % len(joints)]
                cases.append(
                    {**common, 'scenario': f'single:{name}', 'seed': seed,
                     'hidden': [(name, joint)]}
                )  # fmt: skip
        if 'large' in wanted:
            # Effects nested in a plausible inertial parameter error at --magnitude: named once
            # they are larger than any plausible error of the link data.
            for name in LARGE:
                if args.effects and name not in args.effects:
                    continue
                joints = SINGLE[name]
                joint = None if joints is None else joints[seed % len(joints)]
                cases.append(
                    {**common, 'scenario': f'large:{name}', 'seed': seed,
                     'hidden': [(name, joint)], 'magnitude': 10.0 * args.magnitude}
                )  # fmt: skip
        if 'pair' in wanted:
            pair = PAIRS[seed % len(PAIRS)]
            cases.append({**common, 'scenario': 'pair', 'seed': seed, 'hidden': list(pair)})
        if 'aliased' in wanted:
            cases.append(
                {**common, 'scenario': 'aliased:joint_offset', 'seed': seed,
                 'hidden': [('joint_offset', ('joint_2', 'joint_3')[seed % 2])]}
            )  # fmt: skip
            cases.append(
                {**common, 'scenario': 'aliased:coulomb_small_motion', 'seed': seed,
                 'hidden': [('coulomb_friction', 'joint_3')],
                 'excitation': common.get('excitation', {}) | {'position_fraction': 0.03}}
            )  # fmt: skip
        if 'untestable' in wanted:
            # The twin's default cogging amplitudes (1.5 to 6 N*m at 0.5 to 6 % of the torque
            # noise before the filter): far above the cut-off whenever the joint moves.
            cases.append(
                {**common, 'scenario': 'untestable:cogging', 'seed': seed,
                 'hidden': [('cogging', JOINTS[seed % len(JOINTS)])], 'raw_size': 2.0}
            )  # fmt: skip
        if 'outside' in wanted:
            joint = ('joint_1', 'joint_2', 'joint_3', 'joint_4')[seed % 4]
            cases.append(
                {**common, 'scenario': 'outside', 'seed': seed, 'hidden': [],
                 'drift': (joint, args.magnitude, 37.0)}
            )  # fmt: skip
        if 'variant' in wanted:
            cases += variant_cases(args, seed, common)
    return cases


def variant_cases(args: argparse.Namespace, seed: int, common: dict[str, Any]) -> list[dict]:
    """Base friction of our own form, alone and with each variant effect (diagnosis_variants)."""
    from diagnosis_variants import selected_variants

    cases: list[dict[str, Any]] = [
        {**common, 'scenario': 'variant:nothing', 'seed': seed, 'hidden': []}
    ]
    for name, joints in selected_variants(args.effects).items():
        joint = None if joints is None else joints[seed % len(joints)]
        cases.append(
            {**common, 'scenario': f'variant:{name}', 'seed': seed, 'hidden': [(name, joint)]}
        )
    return cases


def run_any(case: dict[str, Any]) -> dict[str, Any]:
    """A twin-form case (``run_case``) or a variant-form one (``diagnosis_variants``)."""
    if case['scenario'].startswith('variant'):
        from diagnosis_variants import run_variant_case

        return run_variant_case(case)
    return run_case(case)


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    groups: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        groups.setdefault(run['scenario'], []).append(run)
    summary = {}
    for scenario, items in sorted(groups.items()):
        entry: dict[str, Any] = {'runs': len(items)}

        def rate(key: str, items: list[dict[str, Any]] = items) -> float:
            return float(np.mean([bool(run.get(key)) for run in items]))

        if scenario == 'nothing' or scenario.startswith(
            ('aliased', 'untestable', 'outside', 'variant')
        ):
            entry['success_rate'] = rate('success')
        if scenario.startswith('variant:') and scenario != 'variant:nothing':
            errors = [run['parameter_error'] for run in items if 'parameter_error' in run]
            entry['parameter_within_15pc_rate'] = (
                float(np.mean([e <= 0.15 for e in errors])) if errors else None
            )
        if scenario.startswith(('single', 'large')):
            entry['right_name_and_joint_rate'] = rate('exact')
            entry['truth_named_rate'] = rate('truth_named')
            entry['named_or_aliased_rate'] = rate('named_or_aliased')
            entry['parameter_within_10pc_rate'] = rate('parameter_within_10pc')
            closed = [run['gap_closed'] for run in items if 'gap_closed' in run]
            entry['gap_closed_median'] = float(np.median(closed)) if closed else None
            entry['gap_closed_min'] = float(np.min(closed)) if closed else None
            entry['gap_closed_ge_90pc_rate'] = float(np.mean([c >= 0.9 for c in closed]))
        if scenario == 'pair':
            entry['exact_set_rate'] = rate('exact')
        entry['diagnose_s_median'] = float(np.median([run['diagnose_s'] for run in items]))
        summary[scenario] = entry
    singles = [run for run in runs if run['scenario'].startswith('single')]
    if singles:
        summary['single:all'] = {
            'runs': len(singles),
            'right_name_and_joint_rate': float(np.mean([run['exact'] for run in singles])),
            'parameter_within_10pc_rate': float(
                np.mean([run['parameter_within_10pc'] for run in singles])
            ),
            'gap_closed_ge_90pc_rate': float(
                np.mean([run['gap_closed'] >= 0.9 for run in singles])
            ),
        }
    return summary


def machine() -> dict[str, Any]:
    try:
        commit = subprocess.run(
            ['git', 'rev-parse', 'HEAD'], cwd=REPO, capture_output=True, text=True, check=False
        ).stdout.strip()
    except OSError:
        commit = ''
    return {
        'python': platform.python_version(),
        'machine': platform.machine(),
        'processor': platform.processor(),
        'cpus': os.cpu_count(),
        'commit': commit,
    }


def build_parser(description: str, scenarios: bool = True) -> argparse.ArgumentParser:
    """The options; without ``scenarios`` no ``--scenarios`` (diagnosis_variants.py's parser)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument('--seeds', type=int, default=10)
    parser.add_argument('--seed0', type=int, default=0)
    parser.add_argument('--duration', type=float, default=200.0, help='recording length [s]')
    parser.add_argument(
        '--magnitude', type=float, default=3.0, help='effect size / post-filter noise level'
    )
    if scenarios:
        parser.add_argument(
            '--scenarios', default='nothing,single,large,pair,aliased,untestable,outside,variant'
        )
    parser.add_argument(
        '--base-frequency',
        type=float,
        default=None,
        help="the excitation's base frequency [Hz] (default: the twin config's; its harmonics "
        'reach 3 times it: 0.1 puts them at the 0.3 Hz cut-offs)',
    )
    parser.add_argument(
        '--effects',
        type=lambda text: text.split(','),
        default=None,
        help='comma-separated effects the single and large scenarios hide (default: all)',
    )
    parser.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument(
        '--out', type=Path, default=REPO / 'out' / 'benchmarks' / 'diagnosis_scoring.json'
    )
    add_results_options(parser)
    return parser


def run_plan(args: argparse.Namespace) -> tuple[list[dict[str, Any]], float]:
    """Every case of the plan, two processes at a time by default; the runs and the wall time."""
    cases = plan(args)
    start = time.perf_counter()
    runs: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for k, run in enumerate(pool.map(run_any, cases), start=1):
            runs.append(run)
            print(
                f'[{k}/{len(cases)}] {run["scenario"]} seed {run["seed"]}: named {run["named"]}'
                f' alias {run["alias_sets"]} ({run["diagnose_s"]:.1f} s)',
                file=sys.stderr,
                flush=True,
            )
    return runs, time.perf_counter() - start


def scored(name: str, args: argparse.Namespace) -> dict[str, Any]:
    """Run the plan of ``args`` and write its JSON document to ``--out``; the document."""
    runs, wall = run_plan(args)
    document = {
        'benchmark': name,
        'settings': vars(args) | {'out': str(args.out)},
        'machine': machine(),
        'wall_s': wall,
        'summary': summarise(runs),
        'runs': runs,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(document, indent=1, default=str) + '\n', encoding='utf-8')
    return document


def published(name: str, document: dict[str, Any], lines: list[str], args: Any) -> int:
    """The page on stderr and written (``publish_results``), the summary on stdout; 0."""
    print('\n'.join(lines), file=sys.stderr)
    publish_results(name, document, lines, args)
    summary = {'wall_s': round(document['wall_s'], 1), 'summary': document['summary']}
    print(json.dumps(summary, indent=1))
    return 0


def main() -> int:
    parser = build_parser(__doc__.split('\n')[0])
    args = parser.parse_args()
    from diagnosis_scoring_page import report

    document = scored('diagnosis_scoring', args)
    lines = report(document, settings_lines('diagnosis_scoring', parser, args))
    return published('diagnosis_scoring', document, lines, args)


if __name__ == '__main__':
    raise SystemExit(main())
