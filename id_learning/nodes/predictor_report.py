"""What the predictor node says: its warnings at start, its counts, and its final report.

The core counts what became of the samples it was given (``PredictorCounters``); the node adds
what it counts itself (``NodeCounts``): samples refused before the core for an invalid header
stamp, samples published late, and callback errors. No rclpy here: the node passes the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

from id_learning.nodes.endpoints import Foreign, ForeignPublishers
from id_learning.nodes.params import PredictorNodeConfig
from id_learning.predictor import FeedForwardPredictor, Reject
from id_learning.predictor.provenance import incomplete_run
from id_learning.predictor.threads import oversubscription
from id_learning.predictor.timing import StatsSummary

__all__ = [
    'INPUT_TYPES',
    'SHARED_INPUT',
    'SHARED_OUTPUT',
    'TROUBLES',
    'NodeCounts',
    'ahead_text',
    'count_values',
    'final_report',
    'foreign_text',
    'setup_warnings',
    'skipped_cycles',
    'troubles',
]

#: What turns the diagnostics level to warn while it grows (the counts of ``troubles``).
TROUBLES = (
    'rejected',
    'clamped',
    'slew-limited',
    'held',
    'resynchronised',
    'out of range',
    'with the physics prior',
    'cycles skipped',
    'late',
    'points ahead',
)
#: The input_type that takes each message type.
INPUT_TYPES = {
    'trajectory_msgs/msg/JointTrajectory': 'trajectory',
    'sensor_msgs/msg/JointState': 'joint_state',
}


#: What several publishers on the input topic do to the predictor (``endpoints.shared_text``).
SHARED_INPUT = (
    'the predictor takes one reference, so their samples interleave, and those that do not '
    'follow from the one before are rejected (inconsistent): leave one publisher on it'
)

#: What another node's publisher on the predictor's output does (``endpoints.OtherPublishers``).
SHARED_OUTPUT = (
    'a consumer there takes the torques of both, two per cycle, from two models: give each '
    'predictor its own output (another output_topic or namespace) or stop the other'
)


@dataclass
class NodeCounts:
    """What the node counts beside the core."""

    #: Published later than one IPO period after the sample arrived (see latency_from).
    late_samples: int = 0
    callback_errors: int = 0
    #: Refused before the core: a header stamp with nanosec >= 1e9 or a negative sec.
    invalid_stamps: int = 0
    #: Trajectory samples whose point has a time_from_start other than 0 (taken as the current
    #: cycle's all the same; said once, ``ahead_text``).
    points_ahead: int = 0


def skipped_cycles(core: FeedForwardPredictor) -> tuple[int, int]:
    """The IPO cycles the stamps skipped in all, and those of them in holes.

    The core counts gaps within the stale threshold; its time base (``predictor.stamps``) those
    of longer gaps (holes). Together: every cycle from the first stamp seen to the last is a
    sample received or a cycle skipped.
    """
    holes = core.skipped_in_holes
    return core.counters.skipped_cycles + holes, holes


def troubles(core: FeedForwardPredictor, counts: NodeCounts) -> tuple[int, ...]:
    """The counts of ``TROUBLES``, in its order."""
    counters = core.counters
    return (
        counters.rejected + counts.invalid_stamps,
        counters.clamped_samples,
        counters.slew_limited_samples,
        counters.held_samples,
        counters.resyncs,
        counters.out_of_range,
        counters.fallback_samples,
        skipped_cycles(core)[0],
        counts.late_samples,
        counts.points_ahead,
    )


def count_values(core: FeedForwardPredictor, counts: NodeCounts) -> dict[str, object]:
    """The counts on /diagnostics: received, published, rejected per reason and the others."""
    counters = core.counters
    skipped, in_holes = skipped_cycles(core)
    values: dict[str, object] = {
        'received': counters.received + counts.invalid_stamps,
        'published': counters.published,
        'model_torques': counters.predicted,
        'held_samples': counters.held_samples,
        'rejected': counters.rejected + counts.invalid_stamps,
    }
    reasons = {f'rejected_{reason.value}': counters.rejects[reason] for reason in Reject}
    # Added to the core's own count, should it ever have one.
    reasons['rejected_invalid_stamp'] = reasons.get('rejected_invalid_stamp', 0) + (
        counts.invalid_stamps
    )
    values.update(reasons)
    values.update(
        {
            'clamped_samples': counters.clamped_samples,
            'slew_limited_samples': counters.slew_limited_samples,
            'resyncs': counters.resyncs,
            'out_of_range_samples': counters.out_of_range,
            'out_of_range_action': core.out_of_range_action,
            'fallback_samples': counters.fallback_samples,
            'fallback': core.fallback.source if core.fallback else 'none',
            'stale': core.is_stale,
            'stale_episodes': counters.stale_episodes,
            'history_resets': counters.history_resets,
            'skipped_cycles': skipped,
            'skipped_cycles_in_holes': in_holes,
            'late_samples': counts.late_samples,
            'points_ahead': counts.points_ahead,
            'callback_errors': counts.callback_errors,
        }
    )
    return values


def final_report(core: FeedForwardPredictor, counts: NodeCounts, latency: StatsSummary) -> str:
    """The line the node logs when it closes."""
    counters = core.counters
    rejects = {r.value: c for r, c in counters.rejects.items() if c}
    if counts.invalid_stamps:
        rejects['invalid_stamp'] = rejects.get('invalid_stamp', 0) + counts.invalid_stamps
    skipped, in_holes = skipped_cycles(core)
    return (
        f'{counters.received + counts.invalid_stamps} samples received, {counters.published} '
        f'published ({counters.held_samples} held), '
        f'{counters.rejected + counts.invalid_stamps} without a model torque {rejects}, '
        f'{counters.clamped_samples} clamped, {counters.slew_limited_samples} slew-limited, '
        f'{counters.resyncs} time base resyncs, {counters.out_of_range} out of range, '
        f'{counters.fallback_samples} with the physics prior, '
        f'{counters.stale_episodes} stale episodes, {skipped} cycles skipped, '
        f'{counts.late_samples} late ({in_holes} of the skipped cycles in gaps longer than the '
        f'stale threshold); receive-to-publish latency median {latency.median * 1e3:.3f} ms, '
        f'p99 {latency.p99 * 1e3:.3f} ms'
    )


def setup_warnings(core: FeedForwardPredictor, config: PredictorNodeConfig) -> list[str]:
    """What in the artifact's setup will cost accuracy or cycles, to be said once at start."""
    warnings = []
    threads = oversubscription(config.torch_threads)
    if threads is not None:
        warnings.append(threads)
    fallback = core.fallback
    if core.out_of_range_action == 'fallback' and fallback and 'nominal' in fallback.source:
        warnings.append(
            'outside the training range the fallback is the nominal model, without friction '
            'or any identified term: give fallback_artifact an rnea_id artifact (train writes '
            'one beside the model with --models including rnea_id)'
        )
    if config.fallback_artifact and fallback is None:
        warnings.append(f'fallback_artifact ignored: a {core.model.kind} model is physics itself')
    run_problem = incomplete_run(config.artifact)  # a model of a run: is the run whole
    if run_problem is not None:
        warnings.append(
            f'the model is complete but its run is not: {run_problem}; its report and the '
            'physics prior beside it may be missing'
        )
    if core.fitting_inputs is None or core.fitting_inputs.name == 'study':
        warnings.append(
            "the model was fitted on inputs low-passed like the labels (the study's "
            "preprocessing), not on a controller's reference: expect larger errors where "
            'the reference changes faster than the label filter (retrain with the default '
            'preprocessing)'
        )
    return warnings


def ahead_text(topic: str, ahead_ns: int) -> str:
    """The one warning about a trajectory point whose time_from_start is not 0."""
    ahead_s = ahead_ns * 1e-9
    return (
        f'{topic}: points[0].time_from_start is {ahead_s:.9g} s, not 0: the predictor takes the '
        'first point as the reference of the cycle in header.stamp, so a point meant for '
        f"{ahead_s:.9g} s later gives tau_u for the wrong moment; send the current cycle's "
        'reference with time_from_start 0 (said once; counted as points_ahead on /diagnostics)'
    )


def foreign_text(
    item: Foreign, publishers: ForeignPublishers, input_topic: str, input_type: str
) -> str:
    """A publisher of another type on the input (or measured) topic, in words."""
    text = (
        f'node {item.node} publishes {item.msg_type} on {item.topic}, which takes '
        f'{publishers.expected[item.topic]}: none of it arrives'
    )
    if item.topic != input_topic:
        return f'{text} (measured_topic)'
    accepting = INPUT_TYPES.get(item.msg_type)
    return text + (
        f'; input_type {accepting} would take it (now {input_type})'
        if accepting
        else f'; no input_type takes it (now {input_type})'
    )
