"""Fitted models kept in the cache (identified systems, calibration networks): a fit read back is the fit
made afresh to the last bit, another setting or other data is another fit, a run stopped part way keeps
what it finished, and the wearable study's fits made side by side in the trials' pool are the serial run's."""

from __future__ import annotations

import ast
import subprocess
import sys

import numpy as np
import pytest

from softtip import calibration
from softtip.bench.sysid import force_like
from softtip.calibration import LMNetwork, ModelFileError, PolynomialFit, SoftmaxClassifier
from softtip.lab.trials import processes_for_trials
from softtip.sysid import StateSpaceModel, TransferFunctionModel, fitted
from softtip.systems.wearable.study import _identify_side_by_side
from softtip._core.progress import SILENT


@pytest.fixture(scope="module")
def split():
    return force_like(estimation_trials=4, validation_trials=2, noise=0.01, seed=3)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(folder))
    return folder


def _same_fit(first, second, validation) -> None:
    """The two fits' discrete systems, trends and delays, and their simulation and scores of ``validation``, bit for bit."""
    assert type(first) is type(second) and first.get_params() == second.get_params()
    for name in ("A", "B", "C", "D"):
        np.testing.assert_array_equal(getattr(first.system_, name), getattr(second.system_, name))
    np.testing.assert_array_equal(first.trend_.output_offset, second.trend_.output_offset)
    assert first.delays_ == second.delays_ and first.data_ == second.data_
    np.testing.assert_array_equal(np.vstack(first.simulate(validation)), np.vstack(second.simulate(validation)))
    first_scores, second_scores = first.evaluate(validation), second.evaluate(validation)
    for metric in first_scores.METRICS:
        np.testing.assert_array_equal(first_scores.values[metric], second_scores.values[metric])


def _counted_fits(monkeypatch, fail_at: int | None = None) -> list:
    """Counts the fits made in this process (and raises Ctrl-C's exception at fit number ``fail_at``)."""
    made = []
    for kind in (StateSpaceModel, TransferFunctionModel):
        original = kind.fit

        def counting(self, recording, original=original):
            made.append(self)
            if fail_at is not None and len(made) == fail_at:
                raise KeyboardInterrupt
            return original(self, recording)

        monkeypatch.setattr(kind, "fit", counting)
    return made


@pytest.mark.parametrize("model", [TransferFunctionModel(4, estimate_covariance=False),
                                   StateSpaceModel(6, estimate_covariance=False)], ids=["tf4", "ss6"])
def test_a_fit_read_from_the_cache_is_the_fit_made_afresh_bit_for_bit(cache, split, monkeypatch, model):
    estimation, validation = split
    afresh = type(model)(**model.get_params()).fit(estimation)
    first = fitted(model, estimation)
    assert not hasattr(model, "system_")  # the estimator given stays unfitted, as scikit-learn's clone leaves it
    assert len(list((cache / "sysid").glob("*.npz"))) == 1
    made = _counted_fits(monkeypatch)
    again = fitted(model, estimation)
    assert made == []  # read, not fitted
    _same_fit(afresh, first, validation)
    _same_fit(afresh, again, validation)


def test_another_setting_or_other_data_is_another_fit(cache, split, monkeypatch):
    estimation, validation = split
    fitted(StateSpaceModel(3), estimation)
    made = _counted_fits(monkeypatch)
    fitted(StateSpaceModel(4), estimation)
    fitted(StateSpaceModel(3, detrend="mean"), estimation)
    fitted(StateSpaceModel(3), estimation.select(range(3)))  # one trial fewer
    fitted(StateSpaceModel(3), estimation.with_trials(estimation.trials, source="another source"))
    assert len(made) == 4
    assert len(list((cache / "sysid").glob("*.npz"))) == 5


def _order_fits(estimation):
    """Nine small fits, enough for the pool (POOL_FROM_TRIALS): state space of orders 1-7, transfer functions 1-2."""
    return ([(StateSpaceModel(order, estimate_covariance=False), estimation) for order in range(1, 8)]
            + [(TransferFunctionModel(order, estimate_covariance=False), estimation) for order in range(1, 3)])


def test_a_stopped_run_keeps_the_fits_it_finished(cache, split, monkeypatch):
    estimation, _ = split
    fits = _order_fits(estimation)
    with processes_for_trials(1), pytest.raises(KeyboardInterrupt):
        _counted_fits(monkeypatch, fail_at=4)
        _identify_side_by_side(fits, SILENT)
    monkeypatch.undo()
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(cache))
    assert len(list((cache / "sysid").glob("*.npz"))) == 3
    made = _counted_fits(monkeypatch)
    with processes_for_trials(1):
        _identify_side_by_side(fits, SILENT)
    assert len(made) == len(fits) - 3


def test_fits_made_side_by_side_are_the_serial_ones(tmp_path, split, monkeypatch):
    estimation, validation = split
    fits = _order_fits(estimation)
    models = {}
    for processes in (1, 2):
        monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path / f"processes-{processes}"))
        with processes_for_trials(processes):
            _identify_side_by_side(fits + fits[:2], SILENT)  # a fit asked for twice is stored once
        assert len(list((tmp_path / f"processes-{processes}" / "sysid").glob("*.npz"))) == len(fits)
        made = _counted_fits(monkeypatch)
        models[processes] = [fitted(model, recording) for model, recording in fits]
        assert made == []  # every fit was stored by the run
        monkeypatch.undo()
    for serial, pooled in zip(models[1], models[2], strict=True):
        _same_fit(serial, pooled, validation)


def _readings(seed: int = 0):
    """Three channels and a smooth two-output target of them, in six trials; a class label per sample."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, size=(240, 3))
    y = np.column_stack([np.tanh(X[:, 0] + 0.5 * X[:, 1]), X[:, 2] ** 2]) + 0.01 * rng.normal(size=(240, 2))
    labels = np.where(X[:, 0] > 0.3, "edge", np.where(X[:, 1] > 0, "point-a", "point-b")).astype(object)
    return X, y, labels, np.repeat(np.arange(6), 40)


@pytest.mark.parametrize("make, target", [(lambda: LMNetwork((5,), random_state=2, max_epochs=30), "forces"),
                                          (lambda: SoftmaxClassifier((5,), random_state=2, max_epochs=30), "labels"),
                                          (lambda: PolynomialFit(), "forces")], ids=["network", "classifier", "polynomial"])
def test_a_calibration_model_read_from_the_cache_predicts_as_the_fit_made_afresh(cache, monkeypatch, make, target):
    X, y, labels, groups = _readings()
    y = labels if target == "labels" else y
    afresh = make().fit(X, y, groups=groups)
    first = calibration.fitted(make(), X, y, groups=groups)
    made, original = [], type(afresh).fit
    monkeypatch.setattr(type(afresh), "fit", lambda self, *args, **kwargs: made.append(self) or original(self, *args, **kwargs))
    again = calibration.fitted(make(), X, y, groups=groups)
    assert made == [] and len(list((cache / "calibration").glob("*.npz"))) == 1
    probe = np.random.default_rng(5).uniform(-1.2, 1.2, size=(50, 3))
    for model in (first, again):
        np.testing.assert_array_equal(model.predict(probe), afresh.predict(probe))
        if target == "labels":
            np.testing.assert_array_equal(model.predict_proba(probe), afresh.predict_proba(probe))
    if hasattr(afresh, "stop_reason_"):  # what training reported travels with the fit
        assert (again.stop_reason_, again.best_epoch_) == (afresh.stop_reason_, afresh.best_epoch_)
    # another seed (degree) or other groups: another fit
    other = make()
    other.set_params(**({"degree": 2} if isinstance(other, PolynomialFit) else {"random_state": 3}))
    calibration.fitted(other, X, y, groups=groups)
    calibration.fitted(make(), X, y, groups=groups[::-1].copy())
    assert len(made) == 2


def test_a_calibration_model_seeded_by_a_generator_is_fitted_every_time(cache):
    X, y, _, groups = _readings()
    calibration.fitted(LMNetwork((3,), random_state=np.random.default_rng(1), max_epochs=5), X, y, groups=groups)
    assert not (cache / "calibration").exists()
    with pytest.raises(ModelFileError, match="cannot keep a StandardScaler in the cache"):
        from sklearn.preprocessing import StandardScaler
        calibration.fitted(StandardScaler(), X, y)


def test_one_blas_thread_holds_for_scipys_own_openblas_loaded_after_the_first_limit():
    # scipy's OpenBLAS is a library of its own, loaded with scipy.linalg: a limit set before then must reach it
    script = """
import numpy
from threadpoolctl import threadpool_info
from softtip._core.threads import single_threaded_blas
with single_threaded_blas():
    pass
import scipy.linalg
with single_threaded_blas():
    print(sorted((pool["filepath"], pool["num_threads"]) for pool in threadpool_info() if pool["user_api"] == "blas"))
"""
    pools = ast.literal_eval(subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout)
    assert len(pools) >= 2 and {threads for _, threads in pools} == {1}  # numpy's OpenBLAS and scipy's
