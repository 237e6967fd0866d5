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
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
import torch
from tqdm import tqdm

from id_learning.errors import ConfigError
from id_learning.models.data import TrainingData
from id_learning.models.through_filter import ThroughFilterLoss, WindowPredictor

__all__ = [
    'EpochHook',
    'NetworkSettings',
    'OptimConfig',
    'TrainHistory',
    'configure_torch',
    'fit_network',
    'select_device',
    'train_module',
]

_LOG = logging.getLogger(__name__)

LossFn = Callable[..., torch.Tensor]
#: Called with (epoch, validation loss) after each epoch; True stops the fit.
EpochHook = Callable[[int, float], bool]


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
        lr_decay: on a plateau (``lr_decay_patience`` epochs without a better validation loss)
            the learning rate is multiplied by this and the fit goes on from the best weights;
            1 for a constant rate. Early stopping still counts every epoch since the best.
        lr_decay_patience: epochs without progress before each decay.
    """

    learning_rate: float = 1e-3
    batch_size: int = 512
    max_epochs: int = 300
    patience: int = 25
    weight_decay: float = 0.0
    seed: int = 0
    max_seconds: float | None = None
    lr_decay: float = 1.0
    lr_decay_patience: int = 10

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        if self.learning_rate <= 0:
            raise ConfigError(f'learning_rate must be > 0, got {self.learning_rate}')
        if not 0.0 < self.lr_decay <= 1.0:
            raise ConfigError(f'lr_decay must be in (0, 1], got {self.lr_decay}')
        if self.lr_decay_patience < 1:
            raise ConfigError(f'lr_decay_patience must be >= 1, got {self.lr_decay_patience}')
        if self.lr_decay < 1.0 and self.lr_decay_patience >= self.patience:
            raise ConfigError(
                f'lr_decay_patience ({self.lr_decay_patience}) must be below patience '
                f'({self.patience}), or early stopping ends the fit before any decay'
            )
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

    @property
    def never_improved(self) -> bool:
        """Whether the validation loss never fell below its first epoch's in a longer fit."""
        return self.best_epoch == 0 and len(self.validation_loss) > 1

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary (losses on the normalised scale)."""
        return {
            'epochs': len(self.train_loss),
            'never_improved': self.never_improved,
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


def is_over(config: OptimConfig, start: float) -> bool:
    """Whether the fit started at ``start`` (perf_counter) has used its time budget."""
    return config.max_seconds is not None and time.perf_counter() - start > config.max_seconds


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
    on_epoch: EpochHook | None = None,
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
        on_epoch: called with (epoch, validation loss) after each epoch; True stops the fit
            (``stopped_by='pruned'``), as a sweep's pruner asks.
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
            if is_over(config, start):
                break  # an epoch of long windows can outlast a budget several times
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
        if on_epoch is not None and on_epoch(epoch, validation):
            history.stopped_by = 'pruned'
            break
        if stale >= config.patience:
            history.stopped_by = 'early_stopping'
            break
        if config.lr_decay < 1.0 and stale and stale % config.lr_decay_patience == 0:
            # A plateau: a smaller step from the best weights (Adam's moments kept).
            module.load_state_dict(best_state)
            for group in optimiser.param_groups:
                group['lr'] *= config.lr_decay
        if is_over(config, start):
            history.stopped_by = 'time_budget'
            break
    module.load_state_dict(best_state)
    history.seconds = time.perf_counter() - start
    _LOG.info('%s: %s', description, history.to_dict())
    if history.never_improved:
        _LOG.warning(
            '%s: the validation loss never improved after the first epoch (%.3g, then %.3g '
            'after %d epochs, training loss %.3g): the weights kept are those of epoch 0, which '
            'learned nothing that carries to the validation part; record more varied motion, '
            'or lower the learning rate',
            description,
            history.validation_loss[0],
            history.validation_loss[-1],
            len(history.validation_loss),
            history.train_loss[-1],
        )
    return history


class NetworkSettings(Protocol):
    """What ``fit_network`` reads of a network model's config (read-only, as frozen fields)."""

    @property
    def kind(self) -> str:
        """The model kind."""
        ...

    @property
    def seed(self) -> int:
        """The seed of the weights and batches."""
        ...

    @property
    def stride(self) -> int:
        """Rows between training samples (the study's way)."""
        ...

    @property
    def windows_per_batch(self) -> int:
        """Contiguous windows per batch (through the filter)."""
        ...

    @property
    def eval_stride(self) -> int:
        """Rows between evaluated samples inside a window."""
        ...

    def optim(self) -> OptimConfig:
        """The optimiser settings."""
        ...


def fit_network(
    network: torch.nn.Module,
    predict: WindowPredictor,
    data: TrainingData,
    target: np.ndarray,
    scale: np.ndarray,
    *,
    config: NetworkSettings,
    device: torch.device,
    progress: bool = False,
    history: int = 0,
    on_epoch: EpochHook | None = None,
) -> TrainHistory:
    """Fit a network the dataset's way; leave it on the CPU in evaluation mode.

    Through the filter (the default preprocessing): on contiguous windows, the predicted torque
    filtered like the labels (``ThroughFilterLoss``; ``windows_per_batch`` windows per step).
    The study's way: on every ``stride``-th sample, the prediction compared with the label as is.
    Either way the loss is the study's normalised MSE and the best validation weights are kept.

    Args:
        network: the module to fit (its parameters are optimised in place).
        predict: torque (B, P, n) at columns ``positions`` (P,) of dataset rows ``rows``
            (B, history + W) in time order; the pointwise way passes (B, history + 1) rows and
            the last column.
        data: the training data.
        target: (N, n) what the network's torque must match [N*m]: the labels, or the labels
            minus a fixed physics part (filtered like them when fitting through the filter).
        scale: (n,) per-joint normalisation [N*m].
        config: the model's settings.
        device: where to fit.
        progress: show a progress bar over epochs.
        history: samples before each evaluated one that ``predict`` reads (sequence models).
        on_epoch: see ``train_module``.

    Raises:
        DatasetError: the training part is too short to fit through the filter.
    """
    network.to(device)
    if data.dataset.is_through_filter:
        windows = ThroughFilterLoss(
            data.dataset,
            data.fit_rows,
            data.validation_rows,
            target,
            scale=scale,
            device=device,
            eval_stride=config.eval_stride,
            history=history,
            seed=config.seed,
        )

        def window_loss(items: torch.Tensor) -> torch.Tensor:
            return windows.loss(predict, items)

        history_ = train_module(
            network,
            window_loss,
            windows.fit_items,
            windows.validation_items,
            replace(config.optim(), batch_size=config.windows_per_batch),
            progress=progress,
            description=f'{config.kind} (through the filter)',
            on_epoch=on_epoch,
        )
    else:
        target_t = torch.as_tensor(np.ascontiguousarray(target), dtype=torch.float32).to(device)
        scale_t = torch.as_tensor(np.asarray(scale), dtype=torch.float32).to(device)
        offsets = torch.arange(-history, 1, device=device)
        last = torch.tensor([history], device=device)

        def point_loss(rows: torch.Tensor) -> torch.Tensor:
            torque = predict(rows[:, None] + offsets, last)[:, 0]
            return torch.mean(((torque - target_t[rows]) / scale_t) ** 2)

        def part(rows: np.ndarray) -> list[torch.Tensor]:
            index = rows[rows >= history][:: config.stride]
            return [torch.as_tensor(index, device=device)]

        history_ = train_module(
            network,
            point_loss,
            part(data.fit_rows),
            part(data.validation_rows),
            config.optim(),
            progress=progress,
            description=config.kind,
            on_epoch=on_epoch,
        )
    network.to('cpu').eval()
    return history_
