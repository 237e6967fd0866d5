"""train_module: early stopping keeps the best weights; a plateau decays the learning rate."""

from __future__ import annotations

import pytest
import torch

from id_learning.errors import ConfigError
from id_learning.models.fitting import OptimConfig, train_module

LEARNING_RATE = 0.01


class Scalar(torch.nn.Module):
    """One weight w, starting at 0."""

    def __init__(self) -> None:
        super().__init__()
        self.w = torch.nn.Parameter(torch.zeros(()))


def run(config: OptimConfig) -> tuple[list[float], Scalar, object]:
    """Fit w towards 100 while the validation loss (w^2) only grows: no epoch beats the first.

    Far from its optimum Adam's step is the learning rate, so w after each epoch shows the rate.
    """
    module = Scalar()
    seen: list[float] = []
    fit = [torch.full((4,), 100.0)]  # one batch per epoch
    validation = [torch.zeros(4)]

    def loss(target: torch.Tensor) -> torch.Tensor:
        return torch.mean((module.w - target) ** 2)

    def record(epoch: int, validation_loss: float) -> bool:
        del epoch, validation_loss
        seen.append(float(module.w.detach()))
        return False

    history = train_module(module, loss, fit, validation, config, on_epoch=record)
    return seen, module, history


def test_early_stopping_after_patience_epochs_keeps_the_best_weights(
    caplog: pytest.LogCaptureFixture,
) -> None:
    seen, module, history = run(
        OptimConfig(learning_rate=LEARNING_RATE, batch_size=4, max_epochs=50, patience=5)
    )
    assert len(seen) == 6
    assert history.stopped_by == 'early_stopping'
    assert history.best_epoch == 0
    # A fit whose validation loss never improved is said: its weights learned nothing.
    assert history.to_dict()['never_improved'] is True
    assert 'never improved after the first epoch' in caplog.text
    assert float(module.w.detach()) == pytest.approx(seen[0])
    assert seen == pytest.approx([LEARNING_RATE * k for k in range(1, 7)], rel=1e-3)


def test_a_plateau_restarts_from_the_best_weights_with_a_smaller_rate() -> None:
    config = OptimConfig(
        learning_rate=LEARNING_RATE,
        batch_size=4,
        max_epochs=50,
        patience=7,
        lr_decay=0.1,
        lr_decay_patience=2,
    )
    seen, module, history = run(config)
    # Epochs 0-2 at the full rate; after epoch 2 (two without progress) back to epoch 0's
    # weights at a tenth of it; after epoch 4 again, at a hundredth; stop after epoch 7.
    rate = LEARNING_RATE
    expected = [rate, 2 * rate, 3 * rate, 1.1 * rate, 1.2 * rate, 1.01 * rate, 1.02 * rate]
    assert seen[:7] == pytest.approx(expected, rel=1e-3)
    assert len(seen) == 8
    assert history.stopped_by == 'early_stopping'
    assert float(module.w.detach()) == pytest.approx(rate, rel=1e-3)


@pytest.mark.parametrize(
    ('settings', 'key'),
    [
        ({'lr_decay': 0.0}, 'lr_decay'),
        ({'lr_decay': 1.5}, 'lr_decay'),
        ({'lr_decay_patience': 0}, 'lr_decay_patience'),
        ({'lr_decay': 0.5, 'lr_decay_patience': 25, 'patience': 25}, 'lr_decay_patience'),
    ],
)
def test_invalid_decay_settings_are_refused_naming_the_key(settings: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        OptimConfig(**settings)
