"""BagWriter when a write fails for real (a file size limit, as a full disk): it stops, says why,
and every message it counted as in the file comes back with recover_bag."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from support import REPO

from id_learning.bag import iter_raw
from id_learning.bag.recover import recover_bag

#: A file size limit well below what the script writes [bytes].
LIMIT_BYTES = 48 * 1024

WRITER = textwrap.dedent(
    """
    import json, resource, signal, sys
    import numpy as np
    from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
    from id_learning.errors import BagError

    path, limit = sys.argv[1], int(sys.argv[2])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failed write, not a killed process
    rng = np.random.default_rng(3)
    writer = BagWriter(path, chunk_bytes=2048).open()
    for topic in ('/a', '/b'):
        writer.add_topic(topic, JOINT_STATE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    counted, said, after = [], None, None
    for k in range(20000):
        try:
            for topic in ('/a', '/b'):
                q = rng.normal(size=6)  # incompressible: the chunks grow
                writer.write(topic, k, encode_joint_state(k, ('j',) * 6, q, q, q))
            if k % 7 == 0:
                writer.flush()
        except BagError as err:
            said = str(err)
            break
        counted.append(dict(writer.on_disk))
    try:
        writer.write('/a', 0, b'')
    except BagError as err:
        after = str(err)
    writer.close()
    print(json.dumps({'on_disk': writer.on_disk, 'said': said, 'after': after, 'k': k}))
    """
)


def test_a_writer_whose_write_fails_stops_and_what_it_counted_comes_back(tmp_path):
    path = tmp_path / 'full'
    done = subprocess.run(
        [sys.executable, '-c', WRITER, str(path), str(LIMIT_BYTES)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    said = result['said']
    assert said is not None, 'the limit was never reached'  # the precondition
    assert str(path) in said
    assert 'File too large' in said
    assert result['after'] == said  # stopped for good: later calls say the same
    on_disk = result['on_disk']
    assert min(on_disk.values()) > 50  # several chunks reached the file before the failure
    assert sum(on_disk.values()) < 2 * result['k'] + 2  # and not all that was written
    assert not (path / 'metadata.yaml').exists()  # left for recover, not finished on a full disk

    report = recover_bag(path)
    recovered = {topic.name: topic.count for topic in report.topics}
    for topic, count in on_disk.items():
        assert recovered[topic] >= count, topic
        stamps = [log_ns for _, log_ns, _ in iter_raw(path, [topic])]
        assert stamps == list(range(len(stamps)))  # a prefix, in order, nothing invented
