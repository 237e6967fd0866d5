"""The online check: a bag's test part replayed through the predictor node, against offline.

``online_check`` starts the ``replay`` and ``predictor`` nodes as processes, listens to what they
publish and compares the predictor's tau_u with the offline prediction of the same artifact
(``check`` holds the whole story). The ``demo`` command runs it on the run's best model. It is
the one place that joins the offline side (dataset, training, evaluation) and the nodes, so it
sits above both; the nodes stay thin shells over the predictor core.
"""

from __future__ import annotations

from id_learning.online_check.check import has_ros, online_check
from id_learning.online_check.result import OnlineCheckError, OnlineCheckResult

__all__ = ['OnlineCheckError', 'OnlineCheckResult', 'has_ros', 'online_check']
