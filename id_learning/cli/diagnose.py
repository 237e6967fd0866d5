"""The ``diagnose`` subcommand, and ``diagnose_bags``, which ``demo`` runs as well.

The diagnosis names the physical effects the nominal model misses and saves the augmented model
as an ``rnea_effects`` artifact; one function does that for both commands.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from id_learning.cli import options

__all__ = ['add_diagnose_command', 'cmd_diagnose', 'diagnose_bags']


def diagnose_bags(
    bags: Sequence[Path],
    robot: Any,
    preprocess: Any,
    out: Path,
    *,
    effects: Sequence[str] | None = None,
    progress: bool = True,
    recordings: Sequence[Any] | None = None,
    trim_unpaired_tail: bool = False,
    force: bool = False,
    final: Path | None = None,
) -> Any:
    """Diagnose bags; write report.md, effects.json, figures and the rnea_effects model to ``out``.

    ``preprocess``: the ``PreprocessConfig`` (target and mode). ``recordings``: the bags already
    loaded (same order), to skip reading them again. ``out`` is written whole or not at all
    (``id_learning.outputs``); ``force`` replaces an earlier result there. ``final``: where
    ``out`` will be in the end, when it is written inside another command's partial folder
    (the model names its effects.json by it).

    Returns:
        the ``DiagnosisResult``.

    Raises:
        OutputError: ``out`` is refused, or a write failed.
    """
    from id_learning.diagnosis import DiagnosisConfig
    from id_learning.outputs import result_folder

    settings: dict[str, Any] = {'preprocess': preprocess}
    if effects:
        settings['effects'] = tuple(effects)
    config = DiagnosisConfig(**settings)  # bad settings are refused before anything is written
    with result_folder(out, command='diagnose', force=force, inputs=bags) as folder:
        return _diagnose_into(
            folder.work,
            final or folder.out,
            bags,
            robot,
            config,
            progress=progress,
            recordings=recordings,
            trim_unpaired_tail=trim_unpaired_tail,
        )


def _diagnose_into(
    work: Path,
    out: Path,
    bags: Sequence[Path],
    robot: Any,
    config: Any,
    *,
    progress: bool,
    recordings: Sequence[Any] | None,
    trim_unpaired_tail: bool,
) -> Any:
    """``diagnose_bags``'s work: written into ``work``, which becomes ``out``."""
    from id_learning.dataset.recording import load_recording
    from id_learning.diagnosis import diagnose
    from id_learning.models.effects import RneaEffectsModel
    from id_learning.models.registry import save_model
    from id_learning.physics.rigid_body import RigidBodyDynamics

    target = config.preprocess.target
    if recordings is None:
        recordings = []
        gravity = RigidBodyDynamics.from_config(robot).gravity  # the sign check's, every bag
        for bag in bags:
            print(f'loading {bag} ...', flush=True)
            recordings.append(
                load_recording(
                    Path(bag),
                    robot,
                    require_current=target == 'motor',
                    progress=progress,
                    trim_unpaired_tail=trim_unpaired_tail,
                    gravity=gravity,
                )
            )
    print('diagnosing: nominal model vs measurements, forward selection of named effects ...',
          flush=True)  # fmt: skip
    result = diagnose(recordings, robot, config, out_dir=work)
    model = RneaEffectsModel.from_augmented(
        result.augmented_model, source=str(out / 'effects.json')
    )
    save_model(model, work / 'model', extra={'diagnosis': {'sources': result.sources}})
    return result


def cmd_diagnose(args: argparse.Namespace) -> int:
    """Find the effects the nominal model misses; report, effects.json and a model artifact."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.diagnosis.report import render_summary

    out = Path(args.out)
    result = diagnose_bags(
        options.bag_paths(args.bag),
        options.load_robot(args),
        PreprocessConfig(target=args.target, mode=args.preprocessing),
        out,
        effects=options.effect_names(args.effects),
        progress=not args.quiet,
        trim_unpaired_tail=args.trim_unpaired_tail,
        force=args.force,
    )
    print(render_summary(result))
    print(
        f'report: {out / "report.md"}; effects: {out / "effects.json"}; waterfall: '
        f'{out / "waterfall.png"}; model (rnea_effects): {out / "model"}'
    )
    return 0


def add_diagnose_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``diagnose`` to the subcommands ``sub``."""
    p = sub.add_parser(
        'diagnose',
        help='name the physical effects the nominal model misses, add them, show the gap shrink',
    )
    p.add_argument('--bag', required=True, action='append', help='bag folder (repeatable)')
    p.add_argument(
        '--out', required=True, help='folder for report.md, effects.json, figures and model/'
    )
    options.target_option(p)
    options.preprocessing_option(p)
    p.add_argument(
        '--effects',
        help='comma-separated candidate effects to try (default: the whole library)',
    )
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    p.add_argument(
        '--force', action='store_true', help='replace a result already in --out (never a bag)'
    )
    options.trim_option(p)
    options.robot_option(p)
    p.set_defaults(func=cmd_diagnose)
