"""What an artifact's metadata must say to be loaded, beyond the integrity of its files.

``artifact.read_artifact`` runs these on every load (train's evaluation, ``evaluate``,
``closed-loop``, the predictor and its fallback all load through it), after the files are found
whole. A hash proves only that nothing changed since the hash was written, not that what was
written makes sense, so each check holds for a model.json rehashed after an edit too:

- JSON documents the package reads hold each key once per object (``loads_unique``): with a key
  twice, which value counts is the parser's choice, not the writer's;
- every scaler (``{low, high}``) holds one finite range per column it scales, high above low:
  the length the model's inputs or outputs have, no zero width (a column the model never saw
  vary cannot be scaled) and none inverted;
- the targets the metadata names (the run's preprocessing, the model's own) agree;
- a physics model's parameters have the sign physics gives them (``PHYSICAL_SIGNS``): friction
  dissipates energy, inertias and masses are not negative;
- an artifact from a newer package version loads with a warning that names both versions.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from id_learning import __version__
from id_learning.config_io import DuplicateKeyError, loads_unique, short_json
from id_learning.errors import CheckpointError

__all__ = [
    'PHYSICAL_SIGNS',
    'DuplicateKeyError',
    'check_metadata',
    'check_physical_parameters',
    'check_scalers',
    'check_targets',
    'check_version',
    'loads_unique',
]

_LOG = logging.getLogger(__name__)


# -- versions ------------------------------------------------------------------------------------
def _release(version: str) -> tuple[int, ...] | None:
    """The numeric release of a version string ('1.2.3.dev0' -> (1, 2, 3)); None if it has none."""
    found = re.match(r'\s*v?(\d+(?:\.\d+)*)', version)
    return tuple(int(part) for part in found.group(1).split('.')) if found else None


def check_version(metadata: Mapping[str, Any], path: Path) -> None:
    """Warn where the artifact was written by a newer id_learning than this one.

    A newer version may have added fields or changed their meaning; this one reads the fields it
    knows and ignores the rest. Artifacts without a version (older than the field) load silently.
    """
    saved = metadata.get('package_version')
    if saved is None:
        return
    written, running = _release(str(saved)), _release(__version__)
    if written is None:
        _LOG.warning('%s: package_version %r is no version number', path, saved)
    elif running is not None and written > running:
        _LOG.warning(
            '%s: written by id_learning %s, newer than this id_learning %s: what the newer '
            'version added or changed is not understood here; update id_learning',
            path,
            saved,
            __version__,
        )


# -- scalers -------------------------------------------------------------------------------------
#: Summaries that describe a fit and never enter a prediction (``artifact.SUMMARY_KEYS``).
_SUMMARY_KEYS = ('training', 'history', 'report', 'diagnosis')


#: Per scaler name, the quantities whose columns it scales, one column per joint each.
_SCALERS = {
    'input_scaler': ('q', 'v', 'a'),
    'state_scaler': ('q', 'v'),
    'target_scaler': ('tau',),
    'residual_scaler': ('tau',),
}
#: The same for the Lagrangian models' ``scaling``.
_SCALED = {'position': ('q',), 'velocity': ('v',), 'torque': ('tau',)}


def _scaled_quantities(field: str) -> tuple[str, ...] | None:
    """The quantities a scaler of this name scales (one column per joint each); None: unknown."""
    parent, _, leaf = field.rpartition('.')
    return _SCALED.get(leaf) if parent.endswith('scaling') else _SCALERS.get(leaf)


def _scalers(value: Any, where: str) -> list[tuple[str, Any]]:
    """Every ``{low, high}`` mapping within ``value`` (summaries left out), with its field."""
    found: list[tuple[str, Any]] = []
    if isinstance(value, Mapping):
        if 'low' in value or 'high' in value:
            return [(where, value)]
        for key, item in value.items():
            if key not in _SUMMARY_KEYS:
                found += _scalers(item, f'{where}.{key}')
    return found


def _numbers(value: Any, field: str, path: Path) -> np.ndarray:
    """A scaler's list of finite numbers as an array.

    Raises:
        CheckpointError: not a list of numbers, or one is not finite; names the field.
    """
    if not isinstance(value, list) or not all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in value
    ):
        raise CheckpointError(f'{path}: {field} is not a list of numbers: {short_json(value)}')
    array = np.asarray(value, dtype=float)
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise CheckpointError(f'{path}: {field}[{int(bad[0])}] is {array[bad[0]]}')
    return array


def check_scalers(metadata: Mapping[str, Any], path: Path, joints: tuple[str, ...]) -> None:
    """Refuse a scaler of the wrong length, of zero width or inverted in any column.

    Scalers are the ``{low, high}`` mappings in ``fitted`` (input, state, target, residual and
    the Lagrangian models' scaling) and the run's label scaler ``target_scaler``.

    Raises:
        CheckpointError: names the file, the field, the index and the column it scales.
    """
    found = _scalers(metadata.get('fitted'), 'fitted')
    if 'target_scaler' in metadata:
        found.append(('target_scaler', metadata['target_scaler']))
    for field, scaler in found:
        if not isinstance(scaler, Mapping) or set(scaler) != {'low', 'high'}:
            raise CheckpointError(
                f'{path}: {field} is not a scaler (low, high): {short_json(scaler)}'
            )
        low = _numbers(scaler['low'], f'{field}.low', path)
        high = _numbers(scaler['high'], f'{field}.high', path)
        quantities = _scaled_quantities(field)
        columns = [f'{x} of {joint}' for x in quantities or () for joint in joints]
        expected = len(columns) if quantities else len(low)
        for name, values in (('low', low), ('high', high)):
            if len(values) != expected:
                raise CheckpointError(
                    f'{path}: {field}.{name} has {len(values)} values, expected {expected} ('
                    + (
                        f'{", ".join(quantities)} of each of {len(joints)} joints)'
                        if quantities
                        else 'as many as low)'
                    )
                )
        width = high - low
        for problem, bad in (('zero width', width == 0), ('high below low', width < 0)):
            index = np.flatnonzero(bad)
            if index.size:
                k = int(index[0])
                column = f' ({columns[k]})' if columns else ''
                raise CheckpointError(
                    f'{path}: {field} has {problem} at index {k}{column}: low {low[k]:g}, high '
                    f'{high[k]:g} ({index.size} such column(s)); a fitted scaler spans the '
                    'range its training data covered: the file was edited, or the model was '
                    'fitted where this column never varied (refit on data where it does)'
                )


# -- targets -------------------------------------------------------------------------------------
TARGETS = ('motor', 'joint')


def check_targets(metadata: Mapping[str, Any], path: Path) -> None:
    """Refuse metadata whose fields name different targets (or one that is no target).

    Raises:
        CheckpointError: names both fields and their values.
    """
    fitted = metadata.get('fitted')
    fitted = fitted if isinstance(fitted, Mapping) else {}
    physics = fitted.get('physics')
    holders = {
        'preprocessing.target': metadata.get('preprocessing'),
        'fitted.target': fitted,
        'fitted.physics.target': physics,
    }
    named: dict[str, Any] = {}
    for field, holder in holders.items():
        if isinstance(holder, Mapping) and 'target' in holder:
            if holder['target'] not in TARGETS:
                raise CheckpointError(
                    f'{path}: {field} is {holder["target"]!r}, not one of {list(TARGETS)}'
                )
            named[field] = holder['target']
    if len(set(named.values())) > 1:
        first, *others = named.items()
        other = next(item for item in others if item[1] != first[1])
        raise CheckpointError(
            f'{path}: {first[0]} is {first[1]!r} but {other[0]} is {other[1]!r}: a model '
            'predicts one torque; the file was edited or is corrupt'
        )


# -- physical parameters -------------------------------------------------------------------------
#: Per model kind, its parameters whose sign physics fixes: tensor name -> (what it is, unit,
#: the bound, whether the bound itself is allowed). Viscous and Coulomb-like friction below zero
#: would push the joint (inject energy); inertias and masses are not negative; a Stribeck
#: velocity divides; a label gain g scales the torque by 1 + g, which must stay positive.
_IDENTIFIED = {
    'rotor': ('rotor inertia', 'kg*m^2', 0.0, True),
    'friction.viscous': ('viscous friction', 'N*m*s/rad', 0.0, True),
    'friction.coulomb': ('Coulomb friction', 'N*m', 0.0, True),
    'friction.stribeck': ('Stribeck friction', 'N*m', 0.0, True),
    'friction.load_dependent': ('load-dependent friction', '1', 0.0, True),
    'stribeck_velocity': ('Stribeck velocity', 'rad/s', 0.0, False),
    'gain': ('label gain', '1', -1.0, False),
}
PHYSICAL_SIGNS: dict[str, dict[str, tuple[str, str, float, bool]]] = {
    'rnea_lq': {
        'rotor_inertia_motor_side': ('rotor inertia', 'kg*m^2', 0.0, True),
        'viscous': ('viscous friction', 'N*m*s/rad', 0.0, True),
        'coulomb': ('Coulomb friction', 'N*m', 0.0, True),
    },
    'rnea_id': _IDENTIFIED,
    **{
        kind: {f'physics.{name}': sign for name, sign in _IDENTIFIED.items()}
        for kind in ('rnea_id_mlp', 'delan_id', 'lnn_mlp_id')
    },
}
#: The body masses of an identified rigid body: every 10th inertial parameter (pinocchio's order).
_THETA = {
    'rnea_id': 'theta',
    **dict.fromkeys(('rnea_id_mlp', 'delan_id', 'lnn_mlp_id'), 'physics.theta'),
}
#: Values a convex solver leaves just beyond a bound it held (relative to the array's scale).
_SOLVER_SLACK = 1e-6


def _below(values: np.ndarray, bound: float, inclusive: bool) -> np.ndarray:
    slack = _SOLVER_SLACK * max(float(np.max(np.abs(values), initial=0.0)), 1e-12)
    return values < bound - slack if inclusive else values <= bound


def check_physical_parameters(
    kind: str, tensors: Mapping[str, np.ndarray], path: Path, joints: tuple[str, ...]
) -> None:
    """Refuse a physics model whose parameters have the wrong sign (``PHYSICAL_SIGNS``).

    Kinds without parameters of a fixed sign pass. The networks' physics (datasheet constants)
    comes from the robot config; ``rnea_effects`` coefficients are corrections to the nominal
    model judged with their uncertainty by the diagnosis, so a small negative one is not refused.

    Raises:
        CheckpointError: names the file and, per parameter out of its range, the first joint
            and its value (one line for all of them).
    """
    problems: list[str] = []
    for name, (what, unit, bound, inclusive) in PHYSICAL_SIGNS.get(kind, {}).items():
        if name not in tensors:
            continue  # a missing tensor is the kind's load_state's to name
        values = np.asarray(tensors[name], dtype=float).reshape(-1)
        bad = np.flatnonzero(_below(values, bound, inclusive))
        if bad.size:
            j = int(bad[0])
            joint = joints[j] if len(values) == len(joints) else f'index {j}'
            rule = f'{">=" if inclusive else ">"} {bound:g}'
            why = ', friction below zero injects energy' if 'friction' in what else ''
            more = f'; {bad.size} joints so' if bad.size > 1 else ''
            problems.append(
                f'{what} ({name}) of {joint} is {values[j]:.6g} {unit} (must be {rule}{why}{more})'
            )
    theta = _THETA.get(kind)
    if theta is not None and theta in tensors:
        masses = np.asarray(tensors[theta], dtype=float).reshape(-1)[::10]
        bad = np.flatnonzero(_below(masses, 0.0, True))
        if bad.size:
            problems.append(f'body {int(bad[0])} has mass {masses[bad[0]]:.6g} kg ({theta})')
    if problems:
        raise CheckpointError(
            f'{path}: {kind} is non-physical: {"; ".join(problems)}. The weights were edited, '
            f'or fitted before {kind} held them to their sign: retrain'
        )


def check_metadata(
    metadata: Mapping[str, Any],
    tensors: Mapping[str, np.ndarray],
    meta_path: Path,
    weights_path: Path,
    joints: tuple[str, ...],
) -> None:
    """Every check of this module on one artifact (see the module docstring).

    Raises:
        CheckpointError: the first problem found, naming the file and the field.
    """
    check_targets(metadata, meta_path)
    check_scalers(metadata, meta_path, joints)
    check_physical_parameters(str(metadata.get('kind')), tensors, weights_path, joints)
    check_version(metadata, meta_path)
