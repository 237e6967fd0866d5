"""Fixtures of the predictor core tests: tiny artifacts of every model kind."""

from __future__ import annotations

import pytest
import torch


@pytest.fixture(scope='session')
def tiny_artifacts(tmp_path_factory, mabi):
    """Folder per kind of a tiny fitted model (see tiny_artifacts.py)."""
    from predictor.tiny_artifacts import build_tiny_artifacts

    return build_tiny_artifacts(tmp_path_factory.mktemp('artifacts'), mabi)


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One intra-op thread, as the predictor node runs; restored afterwards."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
