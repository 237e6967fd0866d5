"""Every model kind and the diagnosis on real and twin robots: held-out RMSE per joint, time.

    python benchmarks/real_robots.py [--robots panda_real,panda_twin,ur5_twin,mabi_twin]
        [--robot-dir DIR ...] [--max-seconds-per-model 60] [--duration 120] [--out DIR]

Robots:

- ``panda_real``: the Franka Panda of Gaz et al. (RA-L 2019), ``--panda-dir`` (default
  ../shared/data/panda_gaz2019; skipped, with the reason, when absent): 21 s of measured joint
  torques at about 1 kHz with jitter. Its robot config (the shared URDF, the URDF's position,
  velocity and torque limits; IPO period, label cut-offs, drives and acceleration limits from
  config/panda.yaml) and its import mapping (NPZ, ``resample: interpolate`` onto the 1 ms grid)
  are written into the working folder at run time; the data stay where they are. Imported with
  ``id-learning import``, trained with ``--target joint``. The published identified model (the
  shared URDF's RNEA, with the paper's gravity 9.80665 m/s^2, plus the paper's sigmoid friction,
  both from panda_gaz2019_params.json) is
  scored on the same preprocessed dataset and test part as the trained models, by the
  trainer's own scoring (``evaluation.scoring.score_model``: through the label filter, RMSE on
  the last 30 % in time).
- ``--robot-dir DIR`` (repeatable): DIR holds bag folders (rosbag2, each with metadata.yaml)
  and ``robot.yaml``; all bags train together. The target is ``motor`` when the bags carry the
  robot's motor-current topic, else ``joint``. An optional ``published.yaml`` gives a
  published model to score beside the trained ones::

      urdf: published.urdf        # optional, relative to DIR (default: robot.yaml's URDF)
      gravity: 9.80665            # optional [m/s^2] (default: pinocchio's 9.81)
      friction:                   # optional; one of:
        model: sigmoid            # Gaz et al.: p1/(1+exp(-p2 (v+p3))) - p1/(1+exp(-p2 p3))
        phi1: [...]
        phi2: [...]
        phi3: [...]
      # friction: {model: viscous_coulomb, viscous: [...], coulomb: [...]}  (coulomb * sign(v))

- ``panda_twin``, ``ur5_twin``: config/panda.yaml and config/ur5.yaml as digital twins with
  hidden effects of their own (``TWIN_EFFECTS``), ``mabi_twin``: config/twin_default.yaml as it
  is; simulated with ``id-learning simulate --duration`` (motor currents: ``--target motor``).

Per robot: ``train --models all --max-seconds-per-model S`` and ``diagnose``, each a
subprocess whose wall and CPU time (getrusage of the children) are measured. Prints per robot
the held-out RMSE per model and joint [N*m] (and the published model's), the effects the
diagnosis named, and the time of each step; writes docs/results/real_robots.md and .json (with
commit, machine and date; ``--no-results`` skips that) and ends with one JSON line.
Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from common import REPO, environment, write_results

BUILTIN = ('panda_real', 'panda_twin', 'ur5_twin', 'mabi_twin')
DEFAULT_PANDA_DIR = REPO.parent / 'shared' / 'data' / 'panda_gaz2019'
PANDA_NPZ = 'panda_exciting_traj1.npz'
PANDA_URDF = 'panda_gaz2019.urdf'
PANDA_PARAMS = 'panda_gaz2019_params.json'
#: The grid the Panda's jittery 1 kHz log is interpolated onto [s] (its IPO period).
PANDA_PERIOD_S = 0.001
#: A pause in the Panda log longer than this ends a segment [s] (its longest step: 8.8 ms).
PANDA_MAX_GAP_S = 0.02

#: Hidden effects of the Panda and UR5 twins (the MABI twin keeps config/twin_default.yaml's).
TWIN_EFFECTS: dict[str, dict[str, Any]] = {
    'panda_twin': {
        'viscous_friction': {'enabled': True, 'coefficient': [0.6, 0.6, 0.5, 0.5, 0.2, 0.2, 0.1]},
        'coulomb_friction': {'enabled': True, 'level': [0.8, 1.0, 0.8, 0.9, 0.4, 0.4, 0.3]},
        'payload_mass': {
            'enabled': True,
            'mass_kg': 1.5,
            'com_m': [0.0, 0.0, 0.06],
            'inertia_kgm2': [0.004, 0.004, 0.002],
        },
        'signal_delay': {'enabled': True, 'delay_s': 0.002},
    },
    'ur5_twin': {
        'viscous_friction': {'enabled': True, 'coefficient': [2.0, 2.0, 1.5, 0.5, 0.5, 0.4]},
        'coulomb_friction': {'enabled': True, 'level': [3.0, 3.5, 2.5, 0.8, 0.8, 0.6]},
        'rotor_inertia': {'enabled': True, 'scale': [1.3, 1.3, 1.3, 1.2, 1.2, 1.2]},
        'payload_mass': {
            'enabled': True,
            'mass_kg': 2.5,
            'com_m': [0.0, 0.0, 0.08],
            'inertia_kgm2': [0.008, 0.008, 0.004],
        },
        'torque_offset': {'enabled': True, 'offset': [0.0, 1.5, -1.0, 0.3, 0.0, 0.0]},
    },
}
#: Sensors of the Panda and UR5 twins: current noise of about 0.15 N*m joint side.
TWIN_MEASUREMENT = {
    'current_noise_std_a': 0.015,
    'current_resolution_a': 0.001,
    'encoder_counts_per_motor_turn': 1048576,
    'velocity_noise_std': 0.001,
}
TWIN_ROBOTS = {'panda_twin': 'panda.yaml', 'ur5_twin': 'ur5.yaml'}


@dataclass
class Job:
    """One robot to train and diagnose: its config, bags, target and published model."""

    name: str
    robot_yaml: Path
    bags: list[Path]
    target: str
    published: PublishedModel | None = None
    hidden_effects: list[str] | None = None
    steps: dict[str, dict[str, Any]] = field(default_factory=dict)


# -- timing of the steps ------------------------------------------------------------------------
def run_step(name: str, command: list[str], log: Path) -> dict[str, Any]:
    """Run one subprocess; its wall and CPU time (user + system of the children) and outcome.

    stdout and stderr go to ``log``; a failure's last stderr lines are returned as ``error``.
    """
    print(f'  {name}: {" ".join(command[2:])}', file=sys.stderr, flush=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with log.open('w', encoding='utf-8') as out:
        result = subprocess.run(
            command, cwd=REPO, stdout=out, stderr=subprocess.STDOUT, text=True, check=False
        )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    step: dict[str, Any] = {
        'wall_s': round(wall, 2),
        'cpu_s': round(cpu, 2),
        'returncode': result.returncode,
        'log': str(log),
    }
    if result.returncode != 0:
        lines = log.read_text(encoding='utf-8', errors='replace').strip().splitlines()
        step['error'] = '\n'.join(lines[-12:])
        print(f'  {name} FAILED (exit {result.returncode}):\n{step["error"]}', file=sys.stderr)
    print(f'  {name}: {wall:.1f} s wall, {cpu:.1f} s CPU', file=sys.stderr, flush=True)
    return step


def cli(*args: str | Path) -> list[str]:
    """The command line of one ``id-learning`` subcommand in this interpreter."""
    return [sys.executable, '-m', 'id_learning.cli', *map(str, args)]


# -- the published model ----------------------------------------------------------------------
def sigmoid_friction(
    v: np.ndarray, phi1: np.ndarray, phi2: np.ndarray, phi3: np.ndarray
) -> np.ndarray:
    """Gaz et al.'s friction (N, n) [N*m]: phi1/(1+exp(-phi2 (v+phi3))) - phi1/(1+exp(-phi2 phi3)).

    Zero at v = 0 by construction.
    """
    return phi1 / (1.0 + np.exp(-phi2 * (v + phi3))) - phi1 / (1.0 + np.exp(-phi2 * phi3))


class PublishedModel:
    """A published identified model: a URDF's RNEA plus a friction law; ``predict`` as a model's.

    Only what ``evaluation.scoring.score_model`` calls: ``predict(q, v, a)`` -> (N, n) [N*m].
    """

    is_sequence_model = False

    def __init__(
        self,
        robot: Any,
        friction: dict[str, Any] | None,
        urdf: Path | None = None,
        gravity: float | None = None,
    ):
        """The URDF's RNEA (``urdf``, default the robot config's), with ``gravity`` [m/s^2]
        (default pinocchio's), plus ``friction`` (``check_friction``; None: none)."""
        from id_learning.physics import RigidBodyDynamics
        from id_learning.physics.rigid_body import build_pinocchio_model

        config = robot if urdf is None else replace(robot, urdf_path=Path(urdf).resolve())
        g = None if gravity is None else np.array([0.0, 0.0, -float(gravity)])
        self.dynamics = RigidBodyDynamics(build_pinocchio_model(config), config.joints, g)
        self.urdf = config.urdf_path
        self.friction = check_friction(friction, robot.n_joints) if friction else None

    def friction_torque(self, v: np.ndarray) -> np.ndarray:
        """(N, n) friction torque at velocities v [N*m]."""
        f = self.friction
        if f is None:
            return np.zeros_like(v)
        if f['model'] == 'sigmoid':
            return sigmoid_friction(v, f['phi1'], f['phi2'], f['phi3'])
        return f['viscous'] * v + f['coulomb'] * np.sign(v)

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """RNEA(q, v, a) + friction(v), (N, n) [N*m]."""
        return self.dynamics.rnea(q, v, a) + self.friction_torque(np.asarray(v, dtype=float))


def check_friction(friction: dict[str, Any], n: int) -> dict[str, Any]:
    """A friction law's parameters as (n,) arrays; refuses an unknown model or a wrong length."""
    keys = {'sigmoid': ('phi1', 'phi2', 'phi3'), 'viscous_coulomb': ('viscous', 'coulomb')}
    model = friction.get('model')
    if model not in keys:
        raise ValueError(f'published friction model {model!r}: expected one of {sorted(keys)}')
    out: dict[str, Any] = {'model': model}
    for key in keys[model]:
        value = np.asarray(friction[key], dtype=float)
        if value.shape != (n,):
            raise ValueError(f'published friction {key}: {value.shape[0]} values for {n} joints')
        out[key] = value
    return out


def panda_published_friction(params_json: Path) -> dict[str, Any]:
    """The paper's identified sigmoid friction from panda_gaz2019_params.json."""
    params = json.loads(params_json.read_text(encoding='utf-8'))
    return {
        'model': 'sigmoid',
        **{f'phi{k}': params[f'friction_phi{k}'] for k in (1, 2, 3)},
    }


def preprocess_of(run_dir: Path, target: str) -> Any:
    """The run's preprocessing (run.json), or the package's defaults for ``target``."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.training.datasets import preprocess_from_dict

    run_file = run_dir / 'run.json'
    if run_file.is_file():
        return preprocess_from_dict(
            json.loads(run_file.read_text(encoding='utf-8'))['preprocessing']
        )
    return PreprocessConfig(target=target)  # type: ignore[arg-type]


def load_dataset(bags: list[Path], robot: Any, config: Any) -> Any:
    """The preprocessed dataset exactly as ``train`` builds it (each bag, segment on its own)."""
    from id_learning.training.datasets import combine_datasets, load_datasets

    return combine_datasets(load_datasets(bags, robot, config, progress=False))


def heldout_rmse(model: Any, dataset: Any) -> list[float]:
    """(n,) RMSE on the test part [N*m], through the label filter: the trainer's ``rmse_nm``."""
    from id_learning.evaluation.scoring import score_model

    score = score_model(model, dataset, dataset.target_scaler.scale())
    return [float(x) for x in score.metrics['rmse_nm']]


# -- the robots ---------------------------------------------------------------------------------
def urdf_limits(urdf: Path, joints: list[str]) -> dict[str, list[float]]:
    """Position, velocity and effort limits of ``joints`` from a URDF's <limit> tags."""
    root = ET.parse(urdf).getroot()
    found: dict[str, dict[str, float]] = {}
    for joint in root.iter('joint'):
        limit = joint.find('limit')
        if limit is not None:
            found[joint.get('name', '')] = {k: float(v) for k, v in limit.attrib.items()}
    missing = [j for j in joints if j not in found]
    if missing:
        raise ValueError(f'{urdf}: no <limit> for joints {missing}')
    return {
        'position_lower': [found[j]['lower'] for j in joints],
        'position_upper': [found[j]['upper'] for j in joints],
        'velocity': [found[j]['velocity'] for j in joints],
        'torque': [found[j]['effort'] for j in joints],
    }


def write_panda_real_config(panda_dir: Path, out: Path) -> tuple[Path, Path]:
    """Write the real Panda's robot config and NPZ import mapping into ``out``; their paths.

    The URDF stays in ``panda_dir`` (absolute path); its limits are the config's, the rest
    (IPO period, label cut-offs, drives, acceleration limits) is config/panda.yaml's.
    """
    out.mkdir(parents=True, exist_ok=True)
    base = yaml.safe_load((REPO / 'config' / 'panda.yaml').read_text(encoding='utf-8'))
    joints = list(base['joints'])
    urdf = (panda_dir / PANDA_URDF).resolve()
    limits = urdf_limits(urdf, joints)
    robot = {
        'name': 'panda_gaz2019',
        'urdf': str(urdf),
        'joints': joints,
        'payload_frame': 'panda_link8',
        'ipo_period_s': PANDA_PERIOD_S,
        'lowpass_cutoff_hz': base['lowpass_cutoff_hz'],
        'drives': base['drives'],
        'limits': {**limits, 'acceleration': base['limits']['acceleration']},
    }
    mapping = {
        'format': 'npz',
        'time': {'column': 't', 'unit': 's'},
        'resample': {
            'method': 'interpolate',
            'period_s': PANDA_PERIOD_S,
            'max_gap_s': PANDA_MAX_GAP_S,
        },
        'joints': [
            {
                'name': name,
                'position': {'column': 'q', 'index': i, 'unit': 'rad'},
                'velocity': {'column': 'qd', 'index': i, 'unit': 'rad/s'},
                'torque': {'column': 'tau', 'index': i, 'unit': 'Nm'},
            }
            for i, name in enumerate(joints)
        ],
    }
    robot_yaml, mapping_yaml = out / 'robot.yaml', out / 'import_mapping.yaml'
    robot_yaml.write_text(yaml.safe_dump(robot, sort_keys=False), encoding='utf-8')
    mapping_yaml.write_text(yaml.safe_dump(mapping, sort_keys=False), encoding='utf-8')
    return robot_yaml, mapping_yaml


def prepare_panda_real(panda_dir: Path, out: Path) -> Job:
    """Write config and mapping, import the log into a bag (timed); the published model too."""
    from id_learning.robot import load_robot_config

    robot_yaml, mapping_yaml = write_panda_real_config(panda_dir, out)
    bag = out / 'bag'
    job = Job('panda_real', robot_yaml, [bag], 'joint')
    job.steps['import'] = run_step(
        'import',
        cli('import', panda_dir / PANDA_NPZ, '--mapping', mapping_yaml, '--robot', robot_yaml,
            '--out', bag, '--force'),
        out / 'import.log',
    )  # fmt: skip
    robot = load_robot_config(robot_yaml)
    params = panda_dir / PANDA_PARAMS
    gravity = json.loads(params.read_text(encoding='utf-8'))['gravity']
    job.published = PublishedModel(robot, panda_published_friction(params), gravity=gravity)
    return job


def write_twin_config(name: str, out: Path, seed: int) -> Path:
    """Write a twin config for config/panda.yaml or config/ur5.yaml with TWIN_EFFECTS[name]."""
    base = yaml.safe_load((REPO / 'config' / 'twin_default.yaml').read_text(encoding='utf-8'))
    config = {
        'robot': str(REPO / 'config' / TWIN_ROBOTS[name]),
        'seed': seed,
        'start_time_ns': base['start_time_ns'],
        'joint_torque_sensors': False,
        'excitation': base['excitation'],
        'effects': TWIN_EFFECTS[name],
        'measurement': TWIN_MEASUREMENT,
    }
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'twin.yaml'
    path.write_text(yaml.safe_dump(config, sort_keys=False), encoding='utf-8')
    return path


def prepare_twin(name: str, out: Path, duration: float, seed: int) -> Job:
    """Simulate a twin into a bag (timed)."""
    if name == 'mabi_twin':
        twin_yaml = REPO / 'config' / 'twin_default.yaml'
    else:
        twin_yaml = write_twin_config(name, out, seed)
    twin = yaml.safe_load(twin_yaml.read_text(encoding='utf-8'))
    robot_yaml = (twin_yaml.parent / twin['robot']).resolve()
    hidden = [k for k, v in (twin.get('effects') or {}).items() if v.get('enabled')]
    bag = out / 'bag'
    job = Job(name, robot_yaml, [bag], 'motor', hidden_effects=hidden)
    job.steps['simulate'] = run_step(
        'simulate',
        cli('simulate', '--config', twin_yaml, '--out', bag, '--seed', seed,
            '--duration', duration, '--force', '--quiet'),
        out / 'simulate.log',
    )  # fmt: skip
    return job


def bag_has_topic(bag: Path, topic: str) -> bool:
    """Whether a rosbag2 folder's metadata.yaml lists ``topic`` with messages."""
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text(encoding='utf-8')) or {}
    info = meta.get('rosbag2_bagfile_information', {})
    for entry in info.get('topics_with_message_count', []):
        if entry.get('topic_metadata', {}).get('name') == topic:
            return int(entry.get('message_count', 0)) > 0
    return False


def prepare_robot_dir(folder: Path) -> Job:
    """A user's folder: its bags, robot.yaml, the target the bags allow, published.yaml."""
    from id_learning.robot import load_robot_config

    robot_yaml = folder / 'robot.yaml'
    if not robot_yaml.is_file():
        raise FileNotFoundError(f'{folder}: no robot.yaml')
    bags = sorted(p for p in folder.iterdir() if (p / 'metadata.yaml').is_file())
    if not bags:
        raise FileNotFoundError(f'{folder}: no bag folders (with metadata.yaml)')
    robot = load_robot_config(robot_yaml)
    has_current = all(bag_has_topic(b, robot.topics.motor_currents) for b in bags)
    job = Job(folder.name, robot_yaml, bags, 'motor' if has_current else 'joint')
    published_yaml = folder / 'published.yaml'
    if published_yaml.is_file():
        spec = yaml.safe_load(published_yaml.read_text(encoding='utf-8')) or {}
        urdf = folder / spec['urdf'] if spec.get('urdf') else None
        job.published = PublishedModel(robot, spec.get('friction'), urdf, spec.get('gravity'))
    return job


# -- train, score, diagnose ---------------------------------------------------------------------
def train_and_diagnose(job: Job, out: Path, max_seconds: float) -> dict[str, Any]:
    """Train every kind, score the published model, diagnose; the robot's JSON entry."""
    from id_learning.models.registry import load_model
    from id_learning.robot import load_robot_config

    bags: list[str | Path] = []
    for bag in job.bags:
        bags += ['--bag', bag]
    run_dir, diagnosis_dir = out / 'run', out / 'diagnosis'
    common = ['--robot', job.robot_yaml, '--target', job.target, '--quiet']
    job.steps['train'] = run_step(
        'train',
        cli('train', *bags, *common, '--models', 'all', '--out', run_dir,
            '--max-seconds-per-model', max_seconds, '--force'),
        out / 'train.log',
    )  # fmt: skip
    entry: dict[str, Any] = {
        'robot_config': str(job.robot_yaml),
        'bags': [str(b) for b in job.bags],
        'target': job.target,
        'rmse_nm': {},
        'failed_models': {},
    }
    metrics_file = run_dir / 'metrics.json'
    robot = load_robot_config(job.robot_yaml)
    entry['joints'] = list(robot.joints)
    if metrics_file.is_file():
        metrics = json.loads(metrics_file.read_text(encoding='utf-8'))
        for kind, m in metrics['models'].items():
            entry['rmse_nm'][kind] = m['rmse_nm']
        job.steps['train']['train_seconds'] = {
            kind: m.get('train_seconds') for kind, m in metrics['models'].items()
        }
        entry['failed_models'] = metrics.get('failed', {})
        entry['cut_short'] = metrics.get('cut_short', {})
        entry['identification'] = identification_summary(run_dir / 'models' / 'rnea_id')
        entry['n_test_samples'] = metrics.get('n_samples')
        entry['label_noise_floor_nm'] = metrics.get('label_noise_floor_nm')

    # The published model, and one trained model again as a check, on the trainer's dataset.
    start, start_cpu = time.perf_counter(), time.process_time()
    try:
        config = preprocess_of(run_dir, job.target)
        dataset = load_dataset(job.bags, robot, config)
        if job.published is not None:
            entry['rmse_nm']['published'] = heldout_rmse(job.published, dataset)
        if entry['rmse_nm']:
            kind = next(k for k in entry['rmse_nm'] if k != 'published')
            again = heldout_rmse(load_model(run_dir / 'models' / kind, robot, kind), dataset)
            entry['rescoring_check'] = {
                'model': kind,
                'max_abs_diff_nm': float(
                    np.max(np.abs(np.subtract(again, entry['rmse_nm'][kind])))
                ),
            }
    except Exception as err:  # reported with the robot, the others go on
        entry['scoring_error'] = f'{type(err).__name__}: {err}'
        print(f'  scoring FAILED: {entry["scoring_error"]}', file=sys.stderr)
    job.steps['score_published'] = {
        'wall_s': round(time.perf_counter() - start, 2),
        'cpu_s': round(time.process_time() - start_cpu, 2),
        'in_process': True,
    }

    job.steps['diagnose'] = run_step(
        'diagnose',
        cli('diagnose', *bags, *common, '--out', diagnosis_dir),
        out / 'diagnose.log',
    )
    effects_file = diagnosis_dir / 'effects.json'
    if effects_file.is_file():
        entry['diagnosis'] = summarise_effects(
            json.loads(effects_file.read_text(encoding='utf-8'))
        )
    entry['steps'] = job.steps
    if job.hidden_effects is not None:
        entry['hidden_effects'] = job.hidden_effects
    return entry


def identification_summary(folder: Path) -> dict[str, Any] | None:
    """What rnea_id identified: its CPU time, the claims judged, the bodies off their prior."""
    path = folder / 'model.json'
    if not path.is_file():
        return None
    report = json.loads(path.read_text(encoding='utf-8'))['fitted']['physics']['report']
    confirmation = report.get('confirmation') or {}
    return {
        'cpu_s': report.get('cpu_seconds'),
        'wall_s': report.get('seconds'),
        'claims': {
            c['claim']: {'confirmed': c['confirmed'], 'p_value_holm': c['p_value_holm']}
            for c in confirmation.get('claims', [])
        },
        'unjudged': confirmation.get('unjudged', []),
        'balancers': [b['joint'] for b in report.get('balancers', [])],
        'bodies_off_prior': [
            {k: b[k] for k in ('body', 'joint', 'mass_kg', 'urdf_mass_kg', 'mass_z')}
            for b in report.get('bodies', [])
            if b.get('departs') and not b.get('held_at_prior')
        ],
        'cut_short': report.get('cut_short', []),
    }


def summarise_effects(effects: dict[str, Any]) -> dict[str, Any]:
    """What a diagnosis named (effects.json): effects, alias sets, held-out RMSE, its stop."""
    return {
        'effects': [
            {
                'label': e['label'],
                'status': e['status'],
                'confidence': e['confidence'],
                'variance_explained_total': e.get('variance_explained_total'),
            }
            for e in effects.get('effects', [])
        ],
        'alias_sets': [
            [m['label'] for m in alias.get('members', [])]
            for alias in effects.get('alias_sets', [])
        ],
        'untestable': sorted(
            {
                f'{u["name"]}[{u["joint"]}]' if u.get('joint') else u['name']
                for u in effects.get('untestable', [])
                if u.get('all_variants')
            }
        ),
        'structured_remainder_joints': [
            r['joint'] for r in effects.get('unexplained_remainder', []) if r.get('structured')
        ],
        'held_out_rmse_nm': {
            k: effects.get('held_out_rmse_nm', {}).get(k) for k in ('before', 'after')
        },
        'nominal_joints': effects.get('held_out_rmse_nm', {}).get('nominal_joints', []),
        'stop_reason': effects.get('stop_reason'),
    }


# -- printing -----------------------------------------------------------------------------------
def rmse_table(entry: dict[str, Any]) -> list[str]:
    """Markdown table: rows models, columns joints (j1..jn) and their mean [N*m]."""
    n = len(entry['joints'])
    head = ['model', *[f'j{i + 1}' for i in range(n)], 'mean']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for kind, values in entry['rmse_nm'].items():
        cells = [f'{x:.3g}' for x in values] + [f'{float(np.mean(values)):.3g}']
        lines.append(f'| {kind} | ' + ' | '.join(cells) + ' |')
    return lines


def robot_lines(name: str, entry: dict[str, Any]) -> list[str]:
    """The robot's section: table, named effects, times, failures."""
    if 'skipped' in entry:
        return [f'## {name}', '', f'Skipped: {entry["skipped"]}', '']
    if 'error' in entry:
        return [f'## {name}', '', f'Failed: {entry["error"]}', '']
    lines = [
        f'## {name}',
        '',
        f'Target `{entry["target"]}`; joints j1..j{len(entry["joints"])} = '
        f'{", ".join(entry["joints"])}; held-out RMSE [N*m] through the label filter on the '
        f'test part (last 30 % in time, {entry.get("n_test_samples")} samples):',
        '',
        *rmse_table(entry),
        '',
    ]
    if entry.get('label_noise_floor_nm'):
        floor = ', '.join(f'{x:.3g}' for x in entry['label_noise_floor_nm'])
        lines += [f'Label-noise floor [N*m]: {floor}.', '']
    check = entry.get('rescoring_check')
    if check:
        lines += [
            f'Rescored `{check["model"]}` on the dataset the published model was scored on: '
            f'max |difference| to metrics.json {check["max_abs_diff_nm"]:.2g} N*m.',
            '',
        ]
    for kind, why in entry.get('failed_models', {}).items():
        lines.append(f'- model `{kind}` failed: {why}')
    if entry.get('scoring_error'):
        lines.append(f'- scoring the published model failed: {entry["scoring_error"]}')
    if entry.get('hidden_effects') is not None:
        lines.append(f'Hidden effects (twin): {", ".join(entry["hidden_effects"]) or "none"}.')
    diagnosis = entry.get('diagnosis')
    if diagnosis:
        named = [
            f'{e["label"]} ({e["status"]}, {e["confidence"]})' for e in diagnosis['effects']
        ] or ['none']
        lines.append(f'Diagnosis named: {"; ".join(named)}.')
        if diagnosis['alias_sets']:
            sets = ' | '.join(', '.join(s) for s in diagnosis['alias_sets'])
            lines.append(f'Alias sets: {sets}.')
        before, after = (diagnosis['held_out_rmse_nm'][k] for k in ('before', 'after'))
        if before and after:
            lines.append(
                'Diagnosis held-out RMSE [N*m] nominal -> refit: '
                + ', '.join(f'{b:.3g}->{a:.3g}' for b, a in zip(before, after, strict=True))
                + f'; stop: {diagnosis["stop_reason"]}.'
            )
    ident = entry.get('identification')
    if ident:
        claims = ', '.join(
            f'{label} {"confirmed" if c["confirmed"] else "refused"}'
            for label, c in ident['claims'].items()
        )
        lines.append(
            f'rnea_id: {ident["cpu_s"]:.1f} s CPU; claims judged on held-out blocks: '
            f'{claims or "none"}; balancers kept: {ident["balancers"] or "none"}; bodies off '
            f'their prior: {ident["bodies_off_prior"] or "none"}.'
        )
    if entry.get('cut_short'):
        lines.append(f'Cut short by their budget: {entry["cut_short"]}.')
    lines += ['', '| step | wall [s] | CPU [s] | note |', '|---|---|---|---|']
    for step, s in entry['steps'].items():
        note = 'FAILED' if s.get('returncode') else ''
        if step == 'train' and s.get('train_seconds'):
            note += ' fit [s]: ' + ', '.join(
                f'{k} {v:.1f}' for k, v in s['train_seconds'].items() if v is not None
            )
        if s.get('in_process'):
            note += ' in this process: dataset load + scoring'
        lines.append(f'| {step} | {s["wall_s"]:.1f} | {s["cpu_s"]:.1f} | {note.strip()} |')
    for step, s in entry['steps'].items():
        if s.get('error'):
            lines += ['', f'`{step}` failed:', '', '```', s['error'], '```']
    return [*lines, '']


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument(
        '--robots',
        default=','.join(BUILTIN),
        help=f'comma-separated, of {", ".join(BUILTIN)} (empty: only --robot-dir)',
    )
    parser.add_argument(
        '--robot-dir', type=Path, action='append', default=[], help='bags + robot.yaml'
    )
    parser.add_argument('--panda-dir', type=Path, default=DEFAULT_PANDA_DIR)
    parser.add_argument('--max-seconds-per-model', type=float, default=60.0)
    parser.add_argument('--duration', type=float, default=120.0, help='twin recordings [s]')
    parser.add_argument(
        '--twin-duration',
        action='append',
        default=[],
        metavar='NAME=SECONDS',
        help='one twin recording of another length, e.g. mabi_twin=600 (repeatable)',
    )
    parser.add_argument('--seed', type=int, default=2026, help="the twins' seed")
    parser.add_argument('--out', type=Path, default=REPO / 'out' / 'real_robots')
    parser.add_argument('--no-results', action='store_true', help='do not write docs/results')
    args = parser.parse_args(argv)
    args.out = args.out.resolve()
    names = [r for r in args.robots.split(',') if r.strip() and r != 'none']
    unknown = sorted(set(names) - set(BUILTIN))
    if unknown:
        parser.error(f'unknown robots {unknown}; known: {list(BUILTIN)}')
    if not names and not args.robot_dir:
        parser.error('no robot: give --robots or --robot-dir')
    durations: dict[str, float] = {}
    for item in args.twin_duration:
        name, _, seconds = item.partition('=')
        if name not in TWIN_ROBOTS and name != 'mabi_twin':
            parser.error(f'--twin-duration {item}: {name!r} is no twin robot')
        try:
            durations[name] = float(seconds)
        except ValueError:
            parser.error(f'--twin-duration {item}: SECONDS must be a number')

    settings = {
        'max_seconds_per_model': args.max_seconds_per_model,
        'twin_duration_s': args.duration,
        'twin_durations_s': durations,
        'twin_seed': args.seed,
        'out': str(args.out),
    }
    robots: dict[str, dict[str, Any]] = {}
    todo: list[tuple[str, Any]] = [(n, None) for n in names]
    todo += [(Path(d).name, Path(d)) for d in args.robot_dir]
    for name, folder in todo:
        out = args.out / name
        out.mkdir(parents=True, exist_ok=True)
        print(f'{name}:', file=sys.stderr, flush=True)
        try:
            if name == 'panda_real' and folder is None:
                if not (args.panda_dir / PANDA_NPZ).is_file():
                    reason = f'no {PANDA_NPZ} in {args.panda_dir}'
                    print(f'{name}: skipped: {reason}', flush=True)
                    robots[name] = {'skipped': reason}
                    continue
                job = prepare_panda_real(args.panda_dir, out)
            elif folder is not None:
                job = prepare_robot_dir(folder)
            else:
                job = prepare_twin(name, out, durations.get(name, args.duration), args.seed)
            first = next(iter(job.steps.values()), {})
            if first.get('returncode'):
                robots[name] = {'error': first['error'], 'steps': job.steps}
            else:
                robots[name] = train_and_diagnose(job, out, args.max_seconds_per_model)
        except Exception as err:  # one robot's failure stops no other
            robots[name] = {'error': f'{type(err).__name__}: {err}'}
        print('\n'.join(robot_lines(name, robots[name])), flush=True)

    document = {'benchmark': 'real_robots', 'settings': settings, 'robots': robots}
    if not args.no_results:
        body = [
            f'`python benchmarks/real_robots.py --robots {args.robots} '
            f'--max-seconds-per-model {args.max_seconds_per_model:g} '
            f'--duration {args.duration:g} --seed {args.seed}'
            + ''.join(f' --twin-duration {item}' for item in args.twin_duration)
            + ''.join(f' --robot-dir {d}' for d in args.robot_dir)
            + '`',
            '',
        ]
        for name, entry in robots.items():
            body += robot_lines(name, entry)
        paths = write_results('real_robots', document, body)
        print(f'wrote {paths[0]} and {paths[1]}', file=sys.stderr)
    print(json.dumps({**document, 'environment': environment()}, default=_json_default))
    return 0


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return str(value)


if __name__ == '__main__':
    sys.exit(main())
