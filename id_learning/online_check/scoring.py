"""The online check's comparison: what the nodes returned against the offline model and the label.

Runs after the nodes are stopped (nothing competes for the cores), on plain arrays: matches each
received reference and tau_u to its excerpt row by stamp, puts online and offline torque through
the label filter, and runs the artifact on exactly the references the node received.
"""

from __future__ import annotations

import time

import numpy as np

from id_learning.online_check.plan import CheckSetup, Excerpt
from id_learning.online_check.result import NS_PER_S, OnlineCheckError, OnlineCheckResult
from id_learning.online_check.ros import Collected

__all__ = ['score']

#: Per excerpt row: the reference's q, v and a in the model's joint order.
_References = dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]


def score(
    setup: CheckSetup,
    excerpt: Excerpt,
    collected: Collected,
    notes: list[str],
    began: float,
) -> OnlineCheckResult:
    """Compare what came back with the offline prediction and the label; ``began``: monotonic.

    Raises:
        OnlineCheckError: a message carries other joints, or no tau_u matches an excerpt sample.
    """
    ref_by_row, tau_by_row = _by_row(setup, excerpt, collected)
    matched = sorted(set(tau_by_row) & set(ref_by_row))
    if not matched:
        raise OnlineCheckError(
            f'no tau_u came back for the {excerpt.n_samples} samples of the excerpt '
            f'({len(collected.references)} references and {len(collected.outputs)} outputs '
            f'received); predictor diagnostics: {collected.predictor}'
        )
    dataset, test_start = excerpt.dataset, excerpt.test_start
    index = np.asarray(matched)
    online = np.vstack([tau_by_row[r] for r in matched])
    offline_matched = excerpt.offline[index - test_start]
    label = dataset.tau[index]

    def through_filter(excerpt_torque: np.ndarray) -> np.ndarray:
        spliced = excerpt.along.copy()
        spliced[index] = excerpt_torque
        out: np.ndarray = dataset.filter_like_labels(spliced)[index]
        return out

    n_missing = excerpt.n_samples - len(tau_by_row)
    if n_missing:
        predictor_diag = collected.predictor
        notes.append(
            f'{n_missing} samples got no tau_u: the predictor received '
            f'{predictor_diag.get("received", "?")} of {collected.n_inputs} references, '
            f'rejected {predictor_diag.get("rejected", "?")} and published '
            f'{predictor_diag.get("published", "?")} (this check received '
            f'{len(collected.outputs)}); its input queue keeps the newest input_depth samples, '
            'so a stall of the machine drops older ones'
        )
    node_model = _node_model(setup, ref_by_row, matched)
    stamps, robot = dataset.stamps_ns, setup.robot
    return OnlineCheckResult(
        kind=setup.kind,
        artifact=setup.artifact,
        bag=setup.bag,
        joints=setup.joints,
        test_start_s=(stamps[test_start] - stamps[0]) / NS_PER_S,
        test_s=(excerpt.test_stop - test_start) * robot.ipo_period_s,
        excerpt_start_s=excerpt.excerpt_start_s,
        excerpt_s=excerpt.excerpt_s,
        is_clipped=excerpt.is_clipped,
        n_samples=excerpt.n_samples,
        n_inputs=collected.n_inputs,
        n_outputs=len(tau_by_row),
        n_missing=n_missing,
        rmse_online_nm=_rmse(through_filter(online), label),
        rmse_offline_nm=_rmse(through_filter(offline_matched), label),
        max_abs_online_offline_nm=np.max(np.abs(online - offline_matched), axis=0),
        max_abs_node_error_nm=np.max(np.abs(online - node_model), axis=0),
        max_input_diff=_input_diff(excerpt, ref_by_row),
        predictor=collected.predictor,
        replay=collected.replay,
        notes=tuple(notes),
        wall_s=time.monotonic() - began,
    )


def _by_row(
    setup: CheckSetup, excerpt: Excerpt, collected: Collected
) -> tuple[_References, dict[int, np.ndarray]]:
    """The received references and tau_u by excerpt row (the last of each), in joint order."""
    stamps, period_ns, joints = excerpt.dataset.stamps_ns, setup.period_ns, setup.joints

    def row_of(stamp: int) -> int | None:
        slot = round((stamp - int(stamps[0])) / period_ns)
        if (
            excerpt.test_start <= slot < excerpt.stop
            and abs(stamp - int(stamps[slot])) <= period_ns // 4
        ):
            return slot
        return None

    ref_by_row: _References = {}
    for stamp, names, q, v, a in sorted(collected.references, key=lambda item: item[0]):
        row = row_of(stamp)
        if row is not None:
            cols = _columns(names, joints, 'the reference')
            ref_by_row[row] = (np.asarray(q)[cols], np.asarray(v)[cols], np.asarray(a)[cols])
    tau_by_row: dict[int, np.ndarray] = {}
    for stamp, names, effort in collected.outputs:
        row = row_of(stamp)
        if row is not None:
            tau_by_row[row] = np.asarray(effort)[_columns(names, joints, 'tau_u')]
    return ref_by_row, tau_by_row


def _input_diff(excerpt: Excerpt, ref_by_row: _References) -> dict[str, np.ndarray]:
    """Max |reference - dataset controller input| per joint, for 'q', 'v' and 'a'."""
    controller = excerpt.dataset.controller
    ref_rows = np.asarray(sorted(ref_by_row))
    q_ref, v_ref, a_ref = (np.vstack([ref_by_row[r][k] for r in ref_rows]) for k in range(3))
    return {
        'q': np.max(np.abs(q_ref - controller.q[ref_rows]), axis=0),
        'v': np.max(np.abs(v_ref - controller.v[ref_rows]), axis=0),
        'a': np.max(np.abs(a_ref - controller.a[ref_rows]), axis=0),
    }


def _node_model(setup: CheckSetup, ref_by_row: _References, matched: list[int]) -> np.ndarray:
    """The artifact on exactly the node's inputs: the references it answered, in order.

    A sequence model's window skips a dropped sample as the node's does; clamped as the node
    clamps.
    """
    q_node, v_node, a_node = (np.vstack([ref_by_row[r][k] for r in matched]) for k in range(3))
    limit = setup.robot.limits.torque
    out: np.ndarray = np.clip(setup.model.predict(q_node, v_node, a_node), -limit, limit)
    return out


def _rmse(prediction: np.ndarray, target: np.ndarray) -> np.ndarray:
    out: np.ndarray = np.sqrt(np.mean((prediction - target) ** 2, axis=0))
    return out


def _columns(names: tuple[str, ...], joints: tuple[str, ...], what: str) -> list[int]:
    """Column of each of ``joints`` in a message with ``names``."""
    if sorted(names) != sorted(joints):
        raise OnlineCheckError(f'{what} carries joints {list(names)}, expected {list(joints)}')
    return [names.index(joint) for joint in joints]
