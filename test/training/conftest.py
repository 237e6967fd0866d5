"""Twin bags and a short training run, shared by the training tests (trained once)."""

from __future__ import annotations

import time

import pytest
from support import FAST_HYPER, twin_config

from id_learning.training import train_run
from id_learning.twin import simulate, write_twin_output


@pytest.fixture(scope='package')
def bags(tmp_path_factory):
    """Two 51.5 s default twin recordings with different seeds (different excitations).

    Long enough to fit through the 0.3 Hz label filter, which reads 11 s on either side.
    """
    folder = tmp_path_factory.mktemp('bags')
    paths = []
    for seed in (11, 12):
        config = twin_config(60.0, seed=seed)
        paths.append(write_twin_output(simulate(config), config, folder / f'twin_{seed}'))
    return paths


def time_each_fit(patch: pytest.MonkeyPatch, seconds: dict[str, float]) -> None:
    """Record in ``seconds`` how long each model's fit() takes, timed inside the call."""
    from id_learning.models import registry

    make_model = registry.make_model

    def make_timed_model(kind, *args, **kwargs):
        model = make_model(kind, *args, **kwargs)
        fit = model.fit

        def timed_fit(*fit_args, **fit_kwargs):
            start = time.perf_counter()
            try:
                return fit(*fit_args, **fit_kwargs)
            finally:
                seconds[kind] = time.perf_counter() - start

        model.fit = timed_fit
        return model

    patch.setattr(registry, 'make_model', make_timed_model)


@pytest.fixture(scope='package')
def timed_run(bags, mabi, tmp_path_factory):
    """The run, the seconds each fit() took and the wall-clock seconds of the whole run."""
    out = tmp_path_factory.mktemp('run') / 'run'
    fit_seconds: dict[str, float] = {}
    with pytest.MonkeyPatch.context() as patch:
        time_each_fit(patch, fit_seconds)
        start = time.perf_counter()
        result = train_run(
            bags,
            mabi,
            'motor',
            ['rnea_lq', 'mlp'],
            out,
            hyper=FAST_HYPER,
            progress=False,
            device='cpu',
        )
        wall_seconds = time.perf_counter() - start
    return result, fit_seconds, wall_seconds


@pytest.fixture(scope='package')
def run(timed_run):
    return timed_run[0]
