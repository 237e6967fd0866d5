"""Mini-batch Adam with early stopping on a validation part: how every network model fits.

Deterministic on the CPU for a given seed (explicit generators, no global RNG); uses all cores;
runs on a GPU when one is present and asked for.
"""

from __future__ import annotations

import copy
import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import torch
from tqdm import tqdm

from id_learning.errors import ConfigError

__all__ = ['OptimConfig', 'TrainHistory', 'configure_torch', 'select_device', 'train_module']

_LOG = logging.getLogger(__name__)

LossFn = Callable[..., torch.Tensor]


@dataclass(frozen=True)
class OptimConfig:
    """Optimiser settings.

    Attributes:
        learning_rate: Adam step size.
        batch_size: samples per mini-batch.
        max_epochs: upper bound on epochs.
        patience: stop after this many epochs without a better validation loss.
        weight_decay: L2 penalty (Adam's weight_decay).
        seed: seeds the initial weights and the batch order.
        max_seconds: wall-clock budget for the fit [s], or None for no limit.
    """

    learning_rate: float = 1e-3
    batch_size: int = 512
    max_epochs: int = 300
    patience: int = 25
    weight_decay: float = 0.0
    seed: int = 0
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        if self.learning_rate <= 0:
            raise ConfigError(f'learning_rate must be > 0, got {self.learning_rate}')
        if self.batch_size < 1 or self.max_epochs < 1 or self.patience < 1:
            raise ConfigError('batch_size, max_epochs and patience must be >= 1')


@dataclass
class TrainHistory:
    """What happened during a fit."""

    train_loss: list[float] = field(default_factory=list)
    validation_loss: list[float] = field(default_factory=list)
    best_epoch: int = -1
    best_validation_loss: float = float('inf')
    seconds: float = 0.0
    stopped_by: str = 'max_epochs'

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary (losses on the normalised scale)."""
        return {
            'epochs': len(self.train_loss),
            'best_epoch': self.best_epoch,
            'best_validation_loss': self.best_validation_loss,
            'final_train_loss': self.train_loss[-1] if self.train_loss else None,
            'seconds': self.seconds,
            'stopped_by': self.stopped_by,
        }


def configure_torch(threads: int | None = None) -> None:
    """Use all cores (or ``threads``) and deterministic algorithms."""
    torch.set_num_threads(threads or os.cpu_count() or 1)
    torch.use_deterministic_algorithms(True, warn_only=True)


def select_device(device: str = 'auto') -> torch.device:
    """'auto' picks CUDA when available, else the CPU; 'cpu' or 'cuda' force one."""
    if device == 'auto':
        return torch.device('cuda' if torch.cuda.is_available() else 'cpu')
    if device == 'cuda' and not torch.cuda.is_available():
        raise ConfigError("device 'cuda' was asked for, but no CUDA device is available")
    return torch.device(device)


def _batches(n: int, batch_size: int, generator: torch.Generator) -> list[torch.Tensor]:
    order = torch.randperm(n, generator=generator)
    return list(order.split(batch_size))


def train_module(
    module: torch.nn.Module,
    loss_fn: LossFn,
    fit_tensors: Sequence[torch.Tensor],
    validation_tensors: Sequence[torch.Tensor],
    config: OptimConfig,
    *,
    progress: bool = False,
    description: str = 'training',
) -> TrainHistory:
    """Fit ``module`` by minimising ``loss_fn(*batch)``; keep the best validation weights.

    Args:
        module: the network(s); its parameters are optimised in place.
        loss_fn: maps the tensors of a batch (same order as ``fit_tensors``) to a scalar loss.
        fit_tensors: tensors with the sample axis first, all of one length.
        validation_tensors: the same for the validation part.
        config: optimiser settings.
        progress: show a progress bar over epochs.
        description: progress bar label.
    """
    generator = torch.Generator().manual_seed(config.seed)
    optimiser = torch.optim.Adam(
        module.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay
    )
    history = TrainHistory()
    best_state = copy.deepcopy(module.state_dict())
    n = len(fit_tensors[0])
    start = time.perf_counter()
    bar = tqdm(
        range(config.max_epochs), desc=description, unit='epoch', disable=not progress, leave=False
    )
    stale = 0
    for epoch in bar:
        module.train()
        total, count = 0.0, 0
        for rows in _batches(n, config.batch_size, generator):
            optimiser.zero_grad(set_to_none=True)
            loss = loss_fn(*(t[rows] for t in fit_tensors))
            loss.backward()
            optimiser.step()
            total += float(loss.detach()) * len(rows)
            count += len(rows)
        module.eval()
        with torch.no_grad():
            validation = float(loss_fn(*validation_tensors))
        history.train_loss.append(total / max(count, 1))
        history.validation_loss.append(validation)
        if validation < history.best_validation_loss:
            history.best_validation_loss, history.best_epoch = validation, epoch
            best_state = copy.deepcopy(module.state_dict())
            stale = 0
        else:
            stale += 1
        bar.set_postfix(train=f'{history.train_loss[-1]:.2e}', val=f'{validation:.2e}')
        if stale >= config.patience:
            history.stopped_by = 'early_stopping'
            break
        if config.max_seconds is not None and time.perf_counter() - start > config.max_seconds:
            history.stopped_by = 'time_budget'
            break
    module.load_state_dict(best_state)
    history.seconds = time.perf_counter() - start
    _LOG.info('%s: %s', description, history.to_dict())
    return history
