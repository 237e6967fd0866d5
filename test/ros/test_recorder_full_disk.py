"""recorder, in its own process, on a disk that fills up (a file size limit, RLIMIT_FSIZE): it
stops writing, says why once, exits non-zero, and what it says is written comes back."""

from __future__ import annotations

import re
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.ros_helpers import node_environment

from id_learning.bag import read_joint_states
from id_learning.bag.recover import recover_bag

pytestmark = pytest.mark.ros

TOPICS = ('/joint_states', '/motor_currents')
#: The largest file the recorder may write [bytes]: a few chunks of the stream below.
LIMIT_BYTES = 40 * 1024
#: Deadline for the recorder to fail and exit once it streams [s].
FAIL_S = 60.0


#: Runs ``python ARGS`` with a file size limit (argv[1], bytes); exec keeps it. CPython ignores
#: SIGXFSZ, so a write past the limit fails with EFBIG, as on a full disk. (Not preexec_fn: this
#: process runs the listener's thread.)
LIMITED = (
    'import os, resource, sys; n = int(sys.argv[1]); '
    'resource.setrlimit(resource.RLIMIT_FSIZE, (n, n)); '
    'os.execv(sys.executable, [sys.executable, *sys.argv[2:]])'
)


def test_a_recorder_on_a_full_disk_stops_says_what_reached_it_and_exits_non_zero(
    tmp_path, domain_id, listener
):
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import sensor_qos

    path = tmp_path / 'full'
    env = node_environment(domain_id)
    env['ROS_LOG_DIR'] = str(tmp_path / 'ros_log')
    env['PYTHONDONTWRITEBYTECODE'] = '1'
    command = [sys.executable, '-c', LIMITED, str(LIMIT_BYTES), '-m', 'id_learning.nodes.recorder',
               '--ros-args', '-p', f'output:={path}', '-p', 'chunk_kib:=4', '-p',
               'flush_period_s:=0.1']  # fmt: skip
    log_path = tmp_path / 'recorder.log'
    with log_path.open('wb') as log:
        recorder = subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=tmp_path
        )
        try:
            publishers = listener.publishers_subscribed(JointState, TOPICS, sensor_qos(200))
            rng = np.random.default_rng(5)
            names = [f'joint_{i}' for i in range(1, 7)]
            start, period, k = time.monotonic(), 0.004, 0
            while recorder.poll() is None and time.monotonic() < start + FAIL_S:
                # Paced on absolute deadlines: this is the stream under test.
                delay = start + k * period - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                msg = JointState(name=names, position=rng.normal(size=6).tolist(),
                                 velocity=rng.normal(size=6).tolist())  # fmt: skip
                msg.header.stamp.sec = k
                for publisher in publishers.values():
                    publisher.publish(msg)
                k += 1
            status = recorder.wait(30)
        finally:
            if recorder.poll() is None:
                recorder.kill()
                recorder.wait()
    said = log_path.read_text(errors='replace')
    assert status == 1, said
    assert 'Traceback' not in said
    assert said.count('recording stopped') == 1, said  # one error, not one per message
    assert f'{path}: writing failed: File too large' in said
    counts = {
        topic: tuple(map(int, found))
        for topic, *found in re.findall(
            r'^\s+(/\w+): received (\d+), written (\d+), dropped \d+, lost (\d+)', said, re.M
        )
    }
    assert set(counts) == set(TOPICS), said
    for received, written, lost in counts.values():
        assert written > 20  # the precondition: chunks reached the file before it filled
        assert lost > 0
        assert received == written + lost

    report = recover_bag(path)
    recovered = {topic.name: topic.count for topic in report.topics}
    for topic, (received, written, _) in counts.items():
        # Every message the recorder said is written comes back, in order, nothing invented.
        assert written <= recovered[topic] <= received, topic
        seconds = (read_joint_states(path, topic).stamps_ns // 1_000_000_000).tolist()
        assert seconds == list(range(len(seconds))), topic
