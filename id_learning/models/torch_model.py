"""The one base of the torch models: a fitted network, its fit, its weights, its training summary.

Every network kind (MLP, LSTM, the Lagrangian networks, the Newtonian networks on a physics
prior) fits through ``fitting.fit_network`` (through the label filter or the study's way, early
stopping, time budget), keeps the network on the CPU in evaluation mode, saves it as a state
dict and refuses to predict before it is fitted or loaded. A model file then holds only what
makes it differ: how its network is built, which inputs it reads, and its own metadata.
"""

from __future__ import annotations

from typing import Any, ClassVar, Generic, TypeVar

import numpy as np
import torch
from torch import nn

from id_learning.models.base import InverseDynamicsModel, ModelConfig
from id_learning.models.data import TrainingData
from id_learning.models.fitting import (
    EpochHook,
    NetworkSettings,
    TrainHistory,
    fit_network,
)
from id_learning.models.network_common import load_module_state, module_state
from id_learning.models.through_filter import WindowPredictor
from id_learning.robot.config import RobotConfig

__all__ = ['TorchModel']

_Net = TypeVar('_Net', bound=nn.Module)


class TorchModel(InverseDynamicsModel, Generic[_Net]):
    """A model whose fitted state is one torch network (``network_``) and its training summary.

    Attributes:
        network_: the fitted network on the CPU (float32, evaluation mode); None before
            ``fit`` or ``load_state``.
        history_: what happened during the fit (losses per epoch, best epoch); None after a
            load, which restores only its summary (``fitted_metadata``).
    """

    #: The fitted-metadata key of the training summary (the Lagrangian kinds write 'history').
    history_key: ClassVar[str] = 'training'
    #: Called with (epoch, validation loss) after each epoch of a fit; True stops it (a
    #: sweep's pruner). Not saved with the model.
    epoch_hook: EpochHook | None = None

    def __init__(self, config: ModelConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.network_: _Net | None = None
        self.history_: TrainHistory | None = None
        #: The summary a loaded model's metadata held (a fitted one derives it from history_).
        self._history_summary: dict[str, Any] | None = None

    @property
    def is_fitted(self) -> bool:
        """Whether the model has weights (fitted or loaded)."""
        return self.network_ is not None

    def network(self) -> _Net:
        """The fitted network.

        Raises:
            RuntimeError: the model is neither fitted nor loaded.
        """
        if self.network_ is None:
            raise RuntimeError(
                f'{self.kind} model is not fitted: call fit() or load_state() first'
            )
        return self.network_

    def _fit_network(
        self,
        network: _Net,
        predict: WindowPredictor,
        data: TrainingData,
        target: np.ndarray,
        scale: np.ndarray,
        *,
        config: NetworkSettings,
        device: torch.device,
        progress: bool,
        history: int = 0,
    ) -> None:
        """Fit ``network`` to ``target`` (``fitting.fit_network``) and keep it and its summary.

        ``history``: samples before each predicted one the network reads (an LSTM's window).
        """
        summary = fit_network(
            network,
            predict,
            data,
            target,
            scale,
            config=config,
            device=device,
            progress=progress,
            history=history,
            on_epoch=self.epoch_hook,
        )
        self.network_ = network
        self.history_ = summary
        self._history_summary = None

    def _load_network(
        self, network: _Net, tensors: dict[str, np.ndarray], fitted: dict[str, Any]
    ) -> None:
        """Load saved weights into a freshly built ``network`` and restore the summary.

        Raises:
            CheckpointError: names or shapes of the tensors differ from the network's.
        """
        load_module_state(network, tensors, self.kind)
        self.network_ = network.eval()
        history = fitted.get(self.history_key)
        self.history_ = None
        self._history_summary = dict(history) if isinstance(history, dict) else None

    def state(self) -> dict[str, np.ndarray]:
        """The network's weights, named like its state_dict keys."""
        return module_state(self.network())

    def _history_metadata(self) -> dict[str, Any]:
        """The training summary under ``history_key``, when there is one."""
        summary = self.history_.to_dict() if self.history_ is not None else self._history_summary
        return {} if summary is None else {self.history_key: summary}
