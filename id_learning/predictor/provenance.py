"""Where a model artifact comes from: whether the training run that holds it finished.

A model a run wrote is ``<run>/models/<kind>``. The model itself is complete once its folder
exists, but a run killed or still going may miss its report and the physics prior beside the
model (the predictor's fallback); the predictor node says so once at start.
"""

from __future__ import annotations

from pathlib import Path

from id_learning.errors import CheckpointError

__all__ = ['incomplete_run']


def incomplete_run(artifact: Path | str) -> str | None:
    """Why the run holding ``artifact`` is incomplete, or holds another run's model there.

    None for a whole run's own model or a lone artifact.
    """
    from id_learning.training.run_folder import MODELS_DIR, check_run_model, refuse_incomplete_run

    artifact = Path(artifact)
    if artifact.parent.name != MODELS_DIR:
        return None
    try:
        refuse_incomplete_run(artifact.parent.parent)
        check_run_model(artifact)  # and the model the one the run saved, not another run's
    except CheckpointError as err:
        return str(err)
    return None
