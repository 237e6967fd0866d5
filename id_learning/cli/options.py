"""Options shared by several subcommands, and the readers of their values.

One definition per option (``--robot``, ``--target``, ``--preprocessing``) and per value format
(model kinds, ``--hyper`` items, comma lists), used by every command module that offers it.
Nothing heavy is imported at module level, so that ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from id_learning.cli.paths import default_robot_config
from id_learning.errors import ConfigError
from id_learning.models.hyper_schema import HYPER_RANGES

if TYPE_CHECKING:
    from id_learning.evaluation.study import StudyTable
    from id_learning.robot.config import RobotConfig

__all__ = [
    'PATH_ARGUMENTS',
    'PREPROCESSING_CHOICES',
    'SEED_MAX',
    'SPLIT_SEED_CONTRADICTION',
    'bag_paths',
    'comma_names',
    'effect_names',
    'empty_paths',
    'finite',
    'fit_seconds',
    'hyper_parameters',
    'integer',
    'load_robot',
    'model_kinds',
    'non_empty_name',
    'positive_float',
    'preprocessing_option',
    'refuse_contradictions',
    'refuse_two_budgets',
    'refuse_two_devices',
    'robot_option',
    'split_seed',
    'target_option',
]

#: ``--preprocessing`` values (``dataset.preprocess.PREPROCESS_MODES``; not imported here, so
#: that ``--help`` stays fast).
PREPROCESSING_CHOICES = ('through_filter', 'study')
#: The largest seed numpy's and Optuna's generators take (a 32-bit unsigned integer).
SEED_MAX = 2**32 - 1


def robot_option(
    p: argparse.ArgumentParser, help_text: str = 'robot config YAML (default: MABI MAX 100)'
) -> None:
    """The --robot option: the robot config YAML."""
    p.add_argument('--robot', help=help_text)


def target_option(p: argparse.ArgumentParser) -> None:
    """The --target option: which torque is the label."""
    p.add_argument(
        '--target',
        choices=('motor', 'joint'),
        default='motor',
        help='motor: tau_u from currents (default); joint: measured joint torque',
    )


def preprocessing_option(p: argparse.ArgumentParser) -> None:
    """The --preprocessing option: fit through the label filter, or the study's way."""
    p.add_argument(
        '--preprocessing',
        choices=PREPROCESSING_CHOICES,
        default='through_filter',
        help="through_filter (default): models see a controller's inputs and their torque is "
        "filtered like the labels before it meets them; study: the reference study's pipeline "
        '(low-passed inputs, torque compared with the low-passed labels as is), for comparison',
    )


def split_option(p: argparse.ArgumentParser) -> None:
    """The --split and --split-seed options: which samples train and which test."""
    p.add_argument(
        '--split',
        choices=('contiguous', 'shuffled'),
        default='contiguous',
        help='contiguous (default): the first 70 %% of each bag in time train, the rest tests; '
        'shuffled: 70 %% of the samples drawn at random train (the study says only "70/30"); '
        'the bags stay whole in time either way',
    )
    p.add_argument(
        '--split-seed',
        type=seed,
        help='seeds the draw of a shuffled split (default 0); only with --split shuffled',
    )


def split_seed(args: argparse.Namespace) -> int:
    """The seed of ``--split-seed``, 0 when not given (None marks it absent)."""
    return 0 if args.split_seed is None else int(args.split_seed)


#: ``--split-seed`` beside a contiguous split: for ``refuse_contradictions``.
SPLIT_SEED_CONTRADICTION = (
    '--split-seed',
    '--split=contiguous',
    'only a shuffled split draws samples at random',
)


def trim_option(p: argparse.ArgumentParser) -> None:
    """The --trim-unpaired-tail option of the commands that read bags."""
    p.add_argument(
        '--trim-unpaired-tail',
        action='store_true',
        help="drop a torn recording's last messages that have no partner on the other topic "
        '(with a warning) instead of refusing the bag',
    )


def study_table_option(p: argparse.ArgumentParser) -> None:
    """The --study-table option: the reference study's Table 1 as JSON, for the report."""
    p.add_argument(
        '--study-table',
        metavar='PATH',
        help="the reference study's Table 1 as JSON (evaluation/study.py says the keys); the "
        'report places it beside our numbers',
    )


def study_table(args: argparse.Namespace, robot: RobotConfig) -> StudyTable | None:
    """The study table --study-table names, checked against the robot's joint count."""
    from id_learning.evaluation.study import load_study_table

    path = getattr(args, 'study_table', None)
    return None if not path else load_study_table(path, robot.n_joints)


def finite(
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> Callable[[str], float]:
    """An argparse type: a finite float in a range (NaN and inf refused).

    argparse names the option in its refusal: ``argument --duration: must be a finite number
    in (0, 86400], got nan``.
    """

    def parse(text: str) -> float:
        from id_learning.config_io import range_problem

        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
        problem = range_problem(value, low=low, high=high, low_open=low_open, high_open=high_open)
        if problem:
            raise argparse.ArgumentTypeError(f'{problem}, got {text}')
        return value

    parse.__name__ = 'number'  # argparse's fallback message: "invalid number value"
    return parse


def integer(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer in [low, high]."""

    def parse(text: str) -> int:
        from id_learning.config_io import range_problem

        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
        problem = range_problem(value, low=low, high=high, integer=True)
        if problem:
            raise argparse.ArgumentTypeError(f'{problem}, got {text}')
        return value

    parse.__name__ = 'integer'
    return parse


#: An argparse type: a finite float > 0 (a budget, a duration).
positive_float = finite(0.0, low_open=True)
#: An argparse type: a fit's wall-clock budget [s], in the range its ``max_seconds`` takes.
fit_seconds = finite(*HYPER_RANGES['max_seconds'])
#: An argparse type: a seed of numpy's and Optuna's generators.
seed = integer(0, SEED_MAX)


def load_robot(args: argparse.Namespace) -> RobotConfig:
    """The robot config of ``--robot``, else the shipped one, checked against its URDF.

    Every command makes the checks ``train`` makes (joints, limits within the URDF's, payload
    frame, link inertias), so a config that cannot train is refused by import and inspect too,
    with the same message.
    """
    from id_learning.physics import build_pinocchio_model
    from id_learning.robot import load_robot_config

    robot = load_robot_config(args.robot or default_robot_config())
    build_pinocchio_model(robot)
    return robot


def model_kinds(text: str) -> list[str]:
    """Model kinds from a comma-separated list.

    'all' is every kind the package has (registry order), 'study' the study's seven in its
    table order; both mix with other kinds: 'study,rnea_id' is the seven plus the identified
    physics.

    Raises:
        ConfigError: an unknown kind (the message lists the known ones), or an item given twice.
    """
    from id_learning.models.registry import MODEL_KINDS, STUDY_MODELS

    groups = {'all': tuple(MODEL_KINDS), 'study': STUDY_MODELS}
    kinds: list[str] = []
    for item in comma_names(text, '--models'):
        for kind in groups.get(item, (item,) if item else ()):
            if kind not in kinds:
                kinds.append(kind)
    if not kinds:
        raise ConfigError(
            f'--models {text!r}: names no model kind; name some (e.g. rnea_lq,mlp), or leave '
            'it out for all'
        )
    unknown = [kind for kind in kinds if kind not in MODEL_KINDS]
    if unknown:
        raise ConfigError(
            f'--models: unknown model kind(s) {unknown}; known kinds: '
            f'{", ".join(MODEL_KINDS)} (or all: every kind; study: the seven of the study)'
        )
    return kinds


def _finite_values(value: Any, where: str) -> Any:
    """``value`` with every number in it checked finite (a NaN learning rate is refused here).

    Raises:
        ConfigError: a NaN or inf, naming ``where``.
    """
    from id_learning.errors import ConfigError

    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f'{where}: must be a finite number, got {value!r}')
    if isinstance(value, list):
        for index, item in enumerate(value):
            _finite_values(item, f'{where}[{index}]')
    if isinstance(value, dict):
        for key, item in value.items():
            _finite_values(item, f'{where}.{key}')
    return value


def hyper_parameters(items: Sequence[str] | None) -> dict[str, dict[str, Any]]:
    """Per-kind hyper-parameters from KIND.KEY=VALUE items (VALUE read as YAML: 3, 1e-3, tanh).

    Raises:
        ConfigError: an item is not of that form, repeats a KIND.KEY (naming both values), or its
            value is no finite number where it is a number. Types and ranges are checked where
            the config is made (``models.hyper_schema``).
    """
    from id_learning.config_io import parse_yaml

    hyper: dict[str, dict[str, Any]] = {}
    for item in items or ():
        name, sep, value = item.partition('=')
        kind, dot, key = name.partition('.')
        if not (sep and dot and kind and key):
            raise ConfigError(f'--hyper {item!r}: expected KIND.KEY=VALUE, e.g. mlp.max_epochs=50')
        where = f'--hyper {name}'
        parsed = _finite_values(parse_yaml(value, where), where)
        given = hyper.setdefault(kind, {})
        if key in given:
            raise ConfigError(
                f'--hyper {name} given twice ({given[key]!r} and {parsed!r}); give it once'
            )
        given[key] = parsed
    return hyper


def refuse_two_budgets(
    hyper: dict[str, dict[str, Any]], max_seconds: float | None, given_as: str
) -> None:
    """Refuse a kind's ``max_seconds`` hyper-parameter that disagrees with --max-seconds-per-model.

    Both set one fit's budget; neither silently wins. An equal value is no contradiction.

    Args:
        hyper: per kind, hyper-parameters.
        max_seconds: --max-seconds-per-model, or None when not given.
        given_as: how the hyper-parameter was given, with ``{kind}`` and ``{value}`` fields.

    Raises:
        ConfigError: names both options and their values.
    """
    if max_seconds is not None:
        option = f'--max-seconds-per-model {max_seconds:g}'
        _refuse_two(hyper, 'max_seconds', max_seconds, option, given_as)


def refuse_two_devices(hyper: dict[str, dict[str, Any]], device: str, given_as: str) -> None:
    """Refuse a kind's ``device`` hyper-parameter that disagrees with --device cpu or cuda.

    Both set the device a fit runs on; neither silently wins. --device auto (the default)
    leaves a kind's own choice standing; an equal value is no contradiction.

    Args:
        hyper: per kind, hyper-parameters.
        device: --device: auto, cpu or cuda.
        given_as: how the hyper-parameter was given, with ``{kind}`` and ``{value}`` fields.

    Raises:
        ConfigError: names both options and their values.
    """
    if device != 'auto':
        _refuse_two(hyper, 'device', device, f'--device {device}', given_as)


#: The hyper-parameters a run-wide option also sets, and what they set.
_RUN_WIDE = {'max_seconds': 'the time budget', 'device': 'the device'}


def _refuse_two(
    hyper: dict[str, dict[str, Any]], key: str, value: object, option: str, given_as: str
) -> None:
    """Refuse a kind's hyper-parameter ``key`` that differs from ``value``, given as ``option``."""
    for kind, values in hyper.items():
        if key in values and values[key] != value:
            raise ConfigError(
                f'{given_as.format(kind=kind, value=values[key])} contradicts {option}: both set '
                f'{_RUN_WIDE[key]} of each {kind} fit; give one'
            )


def hyper_file(path: str | None) -> dict[str, dict[str, Any]]:
    """Per-kind hyper-parameters from a YAML file {kind: {key: value}} (a sweep's best.yaml).

    Raises:
        ConfigError: the file is unreadable, repeats a key, holds a NaN or inf, or is not of
            that form.
    """
    from pathlib import Path

    from id_learning.config_io import load_yaml_mapping

    if not path:
        return {}
    data = load_yaml_mapping(Path(path))
    flat = [str(key) for key, value in data.items() if not isinstance(value, dict)]
    if flat:
        raise ConfigError(
            f'--hyper-file {path}: expected a mapping of model kind -> {{key: value}} (as a '
            f"sweep's best.yaml), but {', '.join(flat[:3])}{', ...' if len(flat) > 3 else ''} "
            'hold(s) no mapping; is this another kind of file (a robot or twin config)?'
        )
    _finite_values(data, f'--hyper-file {path}')
    return {str(kind): dict(values) for kind, values in data.items()}


def effect_names(text: str | None, option: str = '--effects') -> list[str] | None:
    """The effects of a comma list; None when the option is absent (the whole library).

    Raises:
        ConfigError: the option is given but names nothing ('' or ','): an empty selection is
            refused rather than read as the default set; or it names an effect twice.
    """
    if text is None:
        return None
    names = comma_names(text, option)
    if not names:
        raise ConfigError(
            f'{option} {text!r}: names no effect; name some, or leave it out for all'
        )
    return names


def bag_paths(items: Sequence[str] | None, option: str = '--bag') -> list[Path]:
    """The bags of a repeatable option as Paths, each given once (``bag.distinct.check_distinct``).

    Raises:
        ConfigError: one bag given twice (same folder, or a copy with identical bytes).
    """
    from id_learning.bag.distinct import check_distinct

    return check_distinct(list(items or ()), option)


def comma_names(text: str, option: str | None = None) -> list[str]:
    """The non-empty items of a comma-separated list, stripped.

    Raises:
        ConfigError: ``option`` is given and an item repeats (a repeat is a typo, never a
            weight); the message names the option and the item.
    """
    names = [item.strip() for item in text.split(',') if item.strip()]
    if option is not None:
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise ConfigError(
                f'{option} {text!r}: {", ".join(repeated)} given twice; name each once'
            )
    return names


def non_empty_name(text: str) -> str:
    """An argparse type: a name with something in it ('' and blanks refused)."""
    if not text.strip():
        raise argparse.ArgumentTypeError('must not be empty')
    return text


def refuse_contradictions(args: argparse.Namespace, pairs: Sequence[tuple[str, str, str]]) -> None:
    """Refuse an option that means nothing beside another one given, naming both.

    Each command calls this first, before it reads a file, so the refusal costs nothing.

    Args:
        args: the parsed options.
        pairs: (option, other, why) triples. ``option`` counts as given when its value is not
            None (or, for a flag, True): such options default to None, so that a value typed
            equal to the default is caught too. ``other`` is an option (``--skip-training``,
            given when set) or ``--split=contiguous`` (given when it has that value); a leading
            '!' (``!--plot``) refuses ``option`` when ``other`` is absent instead.

    Raises:
        ConfigError: ``option`` and ``other`` are both given; the one line names both.
    """
    for option, other, why in pairs:
        value = getattr(args, _dest(option), None)
        if value is None or value is False:
            continue
        absent = other.startswith('!')
        name, _, wanted = other.lstrip('!').partition('=')
        present = getattr(args, _dest(name), None)
        given = (str(present) == wanted) if wanted else present not in (None, False)
        if given != absent:
            shown = f'{name} {wanted}' if wanted else name
            relation = 'without' if absent else 'with'
            raise ConfigError(f'{option} means nothing {relation} {shown}: {why}')


def _dest(option: str) -> str:
    """The argparse attribute of an option: '--split-seed' -> 'split_seed'."""
    return option.lstrip('-').replace('-', '_')


#: Arguments that name a file or folder: an empty value would silently mean the working folder.
PATH_ARGUMENTS = (
    'bag', 'config', 'hyper_file', 'mapping', 'out', 'plot', 'robot', 'run', 'source',
    'study_table', 'twin',
)  # fmt: skip


def empty_paths(args: argparse.Namespace, argv: Sequence[str]) -> list[str]:
    """The path arguments given as an empty string: option names (``--out``), else positional."""
    empty = []
    for dest in PATH_ARGUMENTS:
        value = getattr(args, dest, None)
        values = value if isinstance(value, list) else [value]
        if any(isinstance(item, str) and not item.strip() for item in values):
            option = f'--{dest.replace("_", "-")}'
            given = any(token == option or token.startswith(f'{option}=') for token in argv)
            empty.append(option if given else dest)
    return empty
