"""The fault-injection suite (benchmarks/faults.py) in the test suite: no fault slips through."""

from __future__ import annotations

import sys

from support import REPO

sys.path.insert(0, str(REPO / 'benchmarks'))

import faults  # the benchmark folder is not a package: found through sys.path


def test_every_fault_is_refused_clearly_or_handled(tmp_path):
    fixtures = faults.build_fixtures(tmp_path, train=True)
    results = faults.run_cases(faults.all_cases(fixtures))
    document = faults.summary(results)
    assert document['cases'] >= 100
    assert document['not_clear'] == []
    assert document['clear_error'] + document['handled'] == document['cases']
    doors = {case.door for case, _ in results}
    assert {'train', 'import', 'predictor', 'evaluate', 'bag recover', 'replay'} <= doors
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return
    assert {'recorder', 'online check'} <= doors  # the nodes as processes


def test_the_classifier_tells_a_silent_acceptance_and_a_traceback_from_a_clear_error():
    assert faults.cli(['train', '--help'], expect=()).kind == 'silently_accepted'
    assert faults.cli(['train', '--models', 'x'], expect=('--bag',)).kind == 'clear_error'
    assert faults.cli(['train', '--models', 'x'], expect=('unrelated',)).kind != 'clear_error'

    def broken() -> None:
        raise KeyError('deep inside')

    assert faults.raises(broken, ValueError, ()).kind == 'traceback'
    assert faults.raises(lambda: None, ValueError, ()).kind == 'silently_accepted'
