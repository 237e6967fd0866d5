"""What a twin simulation gives: the recording and its ground truth."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from id_learning.dataset.recording import Recording

__all__ = ['TwinResult', 'rms_figures']


@dataclass(frozen=True, eq=False)
class TwinResult:
    """A simulated recording with its ground truth.

    Attributes:
        recording: what the sensors recorded, in the bag contract's quantities.
        components: noise-free tau_u contributions [N*m] per name, each (N, n); they sum to
            ``tau_u_clean`` (each already divided by the torque-constant scale).
        tau_u_clean: (N, n) tau_u a perfect current sensor would give [N*m].
        tau_joint_clean: (N, n) torque through the gear output (what a joint torque sensor sees).
        q_true, v_true, a_true: (N, n) the true motion at the sample times.
        parameters: true parameters and noise levels (JSON-ready).
    """

    recording: Recording
    components: dict[str, np.ndarray]
    tau_u_clean: np.ndarray
    tau_joint_clean: np.ndarray
    q_true: np.ndarray
    v_true: np.ndarray
    a_true: np.ndarray
    parameters: dict[str, Any]

    def take(self, rows: slice) -> TwinResult:
        """Some rows of the run, its ground truth's RMS figures those of the rows.

        A bag of a part of a simulation (the last minutes of a long one) is written from this:
        the RMS ``ground_truth.json`` states is checked against the arrays beside it, so its
        noise-free torque and floor are used. Its needed torque is not: ``twin.needed_torque``
        rebuilds the whole simulation's stamps, which a part does not hold (said in a note).
        """
        recording = self.recording
        fields = ('stamps_ns', 'position', 'velocity', 'current', 'joint_torque')
        cut = {k: getattr(recording, k)[rows] for k in fields if getattr(recording, k) is not None}
        components = {name: x[rows] for name, x in self.components.items()}
        tau_u_clean = self.tau_u_clean[rows]
        return replace(
            self,
            recording=replace(recording, **cut),
            components=components,
            tau_u_clean=tau_u_clean,
            tau_joint_clean=self.tau_joint_clean[rows],
            q_true=self.q_true[rows],
            v_true=self.v_true[rows],
            a_true=self.a_true[rows],
            parameters=self.parameters | rms_figures(components, tau_u_clean),
        )


def rms_figures(components: dict[str, np.ndarray], tau_u_clean: np.ndarray) -> dict[str, Any]:
    """``ground_truth.json``'s RMS of each noise-free component and of tau_u, per joint."""
    return {
        'component_rms_nm': {
            name: np.sqrt(np.mean(value**2, axis=0)).tolist() for name, value in components.items()
        },
        'tau_u_clean_rms_nm': np.sqrt(np.mean(tau_u_clean**2, axis=0)).tolist(),
    }
