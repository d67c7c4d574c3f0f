"""Identified models as estimators: metrics, fits, prediction, order tables, model files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from softtip._core.archive import write_archive
from softtip.bench.sysid import INPUTS, OUTPUTS, force_like
from softtip.calibration import ModelFileError
from softtip.data import DatasetError
from softtip.sysid import simulation, transfer
from softtip.sysid.files import load_model, save_model
from softtip.sysid.metrics import MEASURED, fit_percent, rated, score_outputs
from softtip.sysid.models import StateSpaceModel, TransferFunctionModel, information_criteria, order_table
from softtip.sysid.recording import Recording
from softtip.sysid.simulation import simulate, state_sequence
from softtip.sysid.splits import split_by_trial
from softtip.sysid.statespace import IdentificationError, StateSpace

TS = 0.1


@pytest.fixture(scope="module")
def split() -> tuple[Recording, Recording]:
    """Eight estimation and two validation trials (15 s at 10 Hz) of a 3 x 3 system of second-order
    entries, outputs with 1 % noise."""
    return force_like(estimation_trials=8, validation_trials=2, noise=0.01, seed=1)


# --------------------------------------------------------------------------------------------- metrics


def test_metrics_against_hand_computed_values_and_matlabs_fit_formula():
    y = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0], [4.0, 40.0]])
    yhat = np.array([[1.0, 12.0], [2.0, 18.0], [3.0, 30.0], [5.0, 40.0]])
    scores = score_outputs(y, yhat, ("a", "b"), ("N", "N"))
    # output a: residuals (0, 0, 0, 1), deviations (-1.5, -0.5, 0.5, 1.5): SS_res 1, SS_tot 5, range 3
    # output b: residuals (2, -2, 0, 0), SS_res 8, SS_tot 500, range 30
    np.testing.assert_allclose(scores.values["r2"], [1 - 1 / 5, 1 - 8 / 500])
    np.testing.assert_allclose(scores.values["rmse"], [0.5, np.sqrt(2.0)])
    np.testing.assert_allclose(scores.values["mae"], [0.25, 1.0])
    np.testing.assert_allclose(scores.values["rmse_fs_percent"], [100 * 0.5 / 3, 100 * np.sqrt(2.0) / 30])
    np.testing.assert_allclose(scores.values["mae_fs_percent"], [100 * 0.25 / 3, 100 * 1 / 30])
    np.testing.assert_allclose(scores.values["fit_percent"], [100 * (1 - 1 / np.sqrt(5)), 100 * (1 - np.sqrt(8 / 500))])
    np.testing.assert_allclose(scores.values["fit_percent"], 100 * (1 - np.sqrt(1 - scores.values["r2"])))
    np.testing.assert_allclose(scores.values["r"][0], np.corrcoef(y[:, 0], yhat[:, 0])[0, 1])
    described = scores.to_dict()
    assert described["full_scale"]["definition"] == "measured" and "max - min" in described["full_scale"]["description"]
    assert described["outputs"]["b"]["full_scale"] == 30.0 and described["samples"] == 4


def test_a_rated_full_scale_is_used_and_said():
    y = np.array([[0.0], [1.0], [2.0]])
    scores = score_outputs(y, y + 0.1, ("Fz",), ("N",), rated(20.0))
    np.testing.assert_allclose(scores.values["rmse_fs_percent"], [0.5])
    assert scores.to_dict()["full_scale"] == {"definition": "rated", "description": "rated range given by the user"}
    with pytest.raises(IdentificationError, match="output 'Fz' is constant in the data scored"):
        score_outputs(np.ones((3, 1)), np.ones((3, 1)), ("Fz",), ("N",), MEASURED)
    with pytest.raises(IdentificationError, match="2 rated ranges for 1 outputs"):
        score_outputs(y, y, ("Fz",), ("N",), rated([1.0, 2.0]))


def test_fit_percent_is_nan_for_a_constant_reference_and_100_for_a_perfect_one():
    assert np.isnan(fit_percent(np.ones((4, 1)), np.zeros((4, 1)))[0])
    assert fit_percent(np.arange(4.0)[:, None], np.arange(4.0)[:, None])[0] == 100.0


def test_information_criteria_follow_matlabs_formulas():
    errors = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 2.0], [0.0, -2.0]])
    # Σ = diag(2/4, 8/4): ln det Σ = ln 1 = 0, so AIC = 2p + N ny (ln 2π + 1) and BIC = p ln N + the same
    aic, bic = information_criteria(errors, 5)
    assert aic == pytest.approx(10 + 8 * (np.log(2 * np.pi) + 1))
    assert bic == pytest.approx(5 * np.log(4) + 8 * (np.log(2 * np.pi) + 1))


# ------------------------------------------------------------------------------------------------ models


def test_a_transfer_function_model_runs_as_state_space_exactly_like_the_transfer_kernel(split):
    estimation, validation = split
    model = TransferFunctionModel(2, 1).fit(estimation)
    assert model.report_.converged and model.system_.n_states == 18
    for trial, simulated in zip(validation.trials, model.simulate(validation), strict=True):
        reference = transfer.simulate(model.tf_, trial.u, TS)
        assert np.max(np.abs(simulated - reference)) < 1e-9 * np.max(np.ptp(reference, axis=0))
    scores = model.evaluate(validation)
    assert np.all(scores.values["r2"] > 0.99) and np.all(scores.values["fit_percent"] > 90)
    # an output-error model predicts by simulation
    np.testing.assert_allclose(np.vstack(model.predict(validation, 3)), np.vstack(model.simulate(validation)))
    stream = model.streaming()
    frames = np.array([stream.step(u) for u in validation.trials[0].u])
    batch = model.simulate(validation.trials[0].u)
    assert np.max(np.abs(frames - batch) / np.ptp(batch, axis=0)) < 1e-9


def test_a_state_space_model_of_enough_order_reproduces_the_validation_trials(split):
    estimation, validation = split
    model = StateSpaceModel(18).fit(estimation)
    assert model.order_ == 18 and model.system_.is_stable() and model.refinement_ is None
    scores = model.evaluate(validation)
    assert np.all(scores.values["r2"] > 0.99)
    assert model.score(validation) == pytest.approx(np.mean(scores.values["r2"]))
    # at the true order the simulation errors come near the output noise (1 % of each trial's spread)
    noise = 0.01 * np.sqrt(np.mean([np.var(trial.y, axis=0) for trial in validation.trials], axis=0))
    assert np.all(scores.values["rmse"] > 0.9 * noise) and np.all(scores.values["rmse"] < 1.5 * noise)
    # and there is nothing for the outputs to add: the Kalman predictor does no worse than simulation
    assert np.all(model.evaluate(validation, k=1).values["rmse"] < 1.2 * scores.values["rmse"])


def test_refinement_lowers_the_one_step_error_of_a_low_order_model(split):
    estimation, _ = split
    subspace = StateSpaceModel(6).fit(estimation)
    refined = StateSpaceModel(6, refine=True).fit(estimation)
    report = refined.refinement_
    assert report.used and report.cost_after < report.cost_before
    assert np.mean(refined.residuals(estimation) ** 2) < np.mean(subspace.residuals(estimation) ** 2)
    summary = refined.summary()
    assert summary["refinement"]["evaluations"] == report.evaluations and summary["order"] == 6


@pytest.fixture(scope="module")
def continuous_recording() -> tuple[Recording, StateSpace]:
    """Two trials of white inputs through a continuous 4-state system (poles -1 ± 2j, -3, -0.5), 1 % noise."""
    rng = np.random.default_rng(7)
    A = np.array([[-1.0, 2.0, 0, 0], [-2.0, -1.0, 0, 0], [0, 0, -3.0, 0], [0, 0, 0, -0.5]])
    true = StateSpace(A, rng.normal(size=(4, 2)), rng.normal(size=(2, 4)), np.zeros((2, 2)))
    us = [rng.normal(size=(800, 2)) for _ in range(2)]
    ys = [simulate(true.to_discrete(TS), u) for u in us]
    ys = [y + 0.01 * np.std(y, axis=0) * rng.normal(size=y.shape) for y in ys]
    return Recording.from_arrays(us, ys, TS), true


def test_a_continuous_state_space_model_is_the_system_whose_hold_equivalent_runs(continuous_recording):
    recording, true = continuous_recording
    model = StateSpaceModel(4, domain="continuous").fit(recording)
    again = model.continuous_.to_discrete(TS)
    for name in "ABCD":
        np.testing.assert_allclose(getattr(again, name), getattr(model.system_, name), atol=1e-9)
    np.testing.assert_allclose(np.sort_complex(model.continuous_.poles()), np.sort_complex(true.poles()), rtol=0.02)
    assert len(model.summary()["continuous_poles"]) == 4


def test_bic_picks_the_true_order_of_a_noisy_state_space_system():
    rng = np.random.default_rng(4)
    modal = np.diag([0.95, 0.85, 0.6, -0.5])
    true = StateSpace(modal, rng.normal(size=(4, 2)), rng.normal(size=(2, 4)), np.zeros((2, 2)), TS)
    us = [rng.normal(size=(600, 2)) for _ in range(2)]
    ys = [simulate(true, u) + 0.1 * rng.normal(size=(600, 2)) for u in us]
    table = order_table(Recording.from_arrays(us, ys, TS), "ss", range(2, 8))
    assert [row["order"] for row in table] == [2, 3, 4, 5, 6, 7]
    assert min(table, key=lambda row: row["bic"])["order"] == 4
    assert all(row["seconds"] > 0 and row["stable"] for row in table)


def test_an_order_table_of_transfer_functions_counts_their_parameters(split):
    estimation, validation = split
    table = order_table(estimation, "tf", [1, 2], validation, refine=False)
    assert [row["parameters"] for row in table] == [9 * (1 + 0 + 1), 9 * (2 + 1 + 1)]
    assert table[1]["fit_percent"] > table[0]["fit_percent"]
    assert set(table[0]["fit_percent_per_output"]) == set(OUTPUTS)


@pytest.mark.parametrize("kind, runs_per_order", [("tf", 1), ("ss", 2)])
def test_an_order_table_reuses_each_fits_simulation_of_the_estimation_data(split, monkeypatch, kind, runs_per_order):
    """Per order and trial: the fit's simulation (its fit % there, and a transfer function's one-step
    prediction, which is its simulation) and, for a state-space model, its Kalman predictor."""
    estimation, _ = split
    runs, original = [], simulation.state_sequence
    monkeypatch.setattr(simulation, "state_sequence", lambda A, drive, x0: runs.append(len(drive)) or original(A, drive, x0))
    table = order_table(estimation, kind, [1, 2], **({"refine": False} if kind == "tf" else {}))
    assert len(runs) == 2 * runs_per_order * len(estimation.trials)
    fitted = (TransferFunctionModel(2, refine=False) if kind == "tf" else StateSpaceModel(2)).fit(estimation)
    aic, _ = information_criteria(fitted.residuals(estimation), fitted.n_parameters)
    assert table[1]["fit_percent"] == pytest.approx(fitted.evaluate(estimation).mean("fit_percent"), abs=1e-9)
    assert table[1]["aic"] == pytest.approx(aic, rel=1e-12)


# ---------------------------------------------------------------------------------------------- mistakes


@pytest.mark.parametrize("model, message", [
    (StateSpaceModel(0), 'order = 0: expected "auto" or a positive integer'),
    (StateSpaceModel(4, "pem"), "method = 'pem': expected one of n4sid, moesp, cva"),
    (StateSpaceModel(4, domain="laplace"), "domain = 'laplace': expected one of discrete, continuous"),
    (TransferFunctionModel(2, 3), r"n_zeros = 3: expected an integer 0..n_poles \(2\)"),
])
def test_bad_settings_are_refused_in_one_line(split, model, message):
    with pytest.raises(IdentificationError, match=message):
        model.fit(split[0])


def test_too_few_samples_for_the_order_are_refused_with_the_numbers():
    rng = np.random.default_rng(5)
    short = Recording.from_arrays([rng.normal(size=(30, 3))], [rng.normal(size=(30, 3))], TS)
    with pytest.raises(IdentificationError, match=r"30 samples, too few samples for order 8: it needs at least 54"):
        StateSpaceModel(8).fit(short)  # 8 (3 + 2 x 3) / 3 + 3 = 27 parameters per output
    # one input and output: 25 parameters, 55 samples; but the shortest horizon for 8 states, 10 block
    # rows, needs 2 x 10 x 2 = 40 windows of 20 samples
    longer = Recording.from_arrays(rng.normal(size=55), rng.normal(size=55), TS)
    with pytest.raises(IdentificationError, match=r"too few samples for order 8: a horizon of 10 needs trials longer "
                                                   r"than 20 samples .* the recording gives 36"):
        StateSpaceModel(8).fit(longer)


def test_a_model_refuses_data_of_other_channels_or_sample_time(split):
    model = StateSpaceModel(4).fit(split[0])
    trial = split[1].trials[0]
    other = Recording.from_arrays(trial.u, trial.y, TS, inputs=("a", "b", "c"),
                                  outputs=OUTPUTS)
    with pytest.raises(IdentificationError, match=r"inputs \['a', 'b', 'c'\], the model takes"):
        model.simulate(other)
    slower = Recording.from_arrays(trial.u, trial.y, 0.2, inputs=INPUTS, outputs=OUTPUTS)
    with pytest.raises(IdentificationError, match="sample time 0.2 s, the model runs at 0.1 s"):
        model.evaluate(slower)


# -------------------------------------------------------------------------------------------- model files


@pytest.mark.parametrize("make, data", [(lambda: StateSpaceModel(4, domain="continuous", refine=True), "continuous"),
                                        (lambda: TransferFunctionModel(2, 1, refine=False), "transfer")])
def test_a_saved_model_loads_as_the_same_model(tmp_path, split, continuous_recording, make, data):
    estimation, validation = split if data == "transfer" else split_by_trial(continuous_recording[0], 1)
    model = make().fit(estimation)
    path = save_model(tmp_path / "model.npz", model)
    loaded = load_model(path)
    assert type(loaded) is type(model) and loaded.get_params() == model.get_params()
    np.testing.assert_array_equal(np.vstack(loaded.simulate(validation)), np.vstack(model.simulate(validation)))
    np.testing.assert_array_equal(np.vstack(loaded.predict(validation, 2)), np.vstack(model.predict(validation, 2)))
    assert json.dumps(loaded.summary(), sort_keys=True) == json.dumps(model.summary(), sort_keys=True)
    if data == "transfer":
        np.testing.assert_array_equal(loaded.report_.per_output_fit_percent, model.report_.per_output_fit_percent)
        assert loaded.report_.to_dict() == model.report_.to_dict()
    with np.load(path, allow_pickle=False) as archive:
        metadata = json.loads(str(archive["metadata"]))
    assert metadata["fitted"]["data"]["sha256"] == estimation.sha256
    assert metadata["params"] == model.get_params() and metadata["softtip_version"]


def _rewritten(path, edit):
    """The file with its metadata and arrays edited, and a fresh checksum."""
    with np.load(path, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    metadata = json.loads(str(arrays.pop("metadata")))
    edit(metadata, arrays)
    metadata.pop("sha256")
    write_archive(path, metadata, arrays)


@pytest.mark.parametrize("damage, message", [
    (lambda path: path.write_bytes(path.read_bytes()[:-300]), "truncated or unreadable"),
    (lambda path: path.write_bytes(b"not a zip"), "not a softtip system model file"),
    (lambda path: _rewritten(path, lambda m, a: m.__setitem__("kind", "ARXModel")), "unknown model kind 'ARXModel'"),
    (lambda path: _rewritten(path, lambda m, a: m["params"].__setitem__("method", "pem")),
     "inconsistent model: method = 'pem'"),
    (lambda path: _rewritten(path, lambda m, a: a.pop("system/K")), "needs its Kalman gain K"),
    (lambda path: _rewritten(path, lambda m, a: m["fitted"].__setitem__("outputs", ["Fx", "Fy"])),
     "3 inputs and 2 outputs named, the system has 3 and 3"),
])
def test_a_damaged_or_inconsistent_model_file_is_refused_in_one_line(tmp_path, split, damage, message):
    path = save_model(tmp_path / "model.npz", StateSpaceModel(4).fit(split[0]))
    damage(path)
    with pytest.raises(ModelFileError, match=message) as refusal:
        load_model(path)
    assert "\n" not in str(refusal.value)


def test_an_altered_file_fails_its_checksum(tmp_path, split):
    path = save_model(tmp_path / "model.npz", StateSpaceModel(4).fit(split[0]))
    with np.load(path, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    arrays["system/D"] = arrays["system/D"] + 1.0
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
    with pytest.raises(ModelFileError, match="checksum mismatch"):
        load_model(path)


def test_recording_checks_reach_the_user_before_identification():
    u = np.column_stack([np.sin(np.arange(100.0)), np.zeros(100)])
    with pytest.raises(DatasetError, match="input 'u1' is constant"):
        StateSpaceModel(2).fit(Recording.from_arrays(u, np.cos(np.arange(100.0)), TS))


def test_kalman_predictor_of_a_fitted_model_beats_simulation_on_coloured_noise():
    rng = np.random.default_rng(6)
    true = StateSpace(np.diag([0.9, 0.5]), [[1.0], [0.5]], [[1.0, 1.0]], [[0.0]], TS)
    K = np.array([[0.6], [0.1]])
    us, ys = [], []
    for _ in range(2):
        u, e = rng.normal(size=(1500, 1)), 0.5 * rng.normal(size=(1500, 1))
        ys.append(state_sequence(true.A, u @ true.B.T + e @ K.T, np.zeros(2)) @ true.C.T + e)
        us.append(u)
    recording = Recording.from_arrays(us, ys, TS)
    model = StateSpaceModel(2).fit(recording)
    one_step = model.evaluate(recording, k=1).values["rmse"][0]
    simulated = model.evaluate(recording).values["rmse"][0]
    assert one_step == pytest.approx(0.5, rel=0.05)  # the innovations' standard deviation
    assert simulated > 1.3 * one_step


def test_fit_warnings_name_a_fit_from_rest_and_a_validation_fit_far_below_the_others():
    """Fits of 90, 75 and 65 % made exactly (ŷ = y - a (y - ȳ) fits 100 (1 - a) %): a gap of 20 points
    or more is warned of, naming the record, the output and both figures; 15 points is not."""
    from softtip.sysid.metrics import MEASURED, score_outputs
    from softtip.sysid.verdicts import fit_warnings

    y = np.sin(np.linspace(0, 20, 500))[:, None]

    def scores(fit):
        return score_outputs(y, y - (1 - fit / 100) * (y - y.mean()), ("temperature",), ("degC",), MEASURED)

    assert scores(75.0).values["fit_percent"][0] == pytest.approx(75.0)
    assert fit_warnings(("temperature",), scores(75.0), scores(90.0), "run.dat") == []
    [rest] = fit_warnings(("temperature",), scores(65.0), scores(90.0), "run.dat")
    assert rest.startswith("run.dat: temperature: the fit from rest, 65 %, is 25 points below the fit from each "
                           "trial's estimated initial state (90 %)")
    assert fit_warnings(("temperature",), scores(75.0), scores(75.0), "val.dat", scores(90.0)) == []
    [validation] = fit_warnings(("temperature",), scores(65.0), scores(65.0), "val.dat", scores(90.0))
    assert validation.startswith("val.dat: temperature: the validation fit, 65 %, is 25 points below the "
                                 "estimation fit (90 %")


def test_the_zero_order_hold_equals_scipys_cont2discrete():
    """StateSpace.to_discrete (one matrix exponential) against scipy.signal.cont2discrete on a random
    3-state, 2-input, 2-output system: the same matrices to rounding."""
    import scipy.signal

    from softtip.sysid.statespace import StateSpace

    rng = np.random.default_rng(11)
    A, B, C, D = rng.normal(size=(3, 3)) - 2 * np.eye(3), rng.normal(size=(3, 2)), rng.normal(size=(2, 3)), \
        rng.normal(size=(2, 2))
    ours = StateSpace(A, B, C, D).to_discrete(0.05)
    theirs = scipy.signal.cont2discrete((A, B, C, D), 0.05, method="zoh")
    for mine, reference in zip((ours.A, ours.B, ours.C, ours.D), theirs[:4], strict=True):
        np.testing.assert_allclose(mine, reference, rtol=1e-12, atol=1e-14)


def test_the_estimators_keep_scikit_learns_convention_without_importing_it():
    """sklearn.base.clone copies them with their parameters; set_params refuses an unknown name; and a
    fresh interpreter importing the package, the models and the command line loads neither scikit-learn
    nor scipy's signal, stats or optimize modules (seconds of start-up; a fit loads optimize when it
    refines)."""
    import subprocess
    import sys
    from pathlib import Path

    from sklearn.base import clone

    model = TransferFunctionModel(3, 1, detrend="mean", intervals="white")
    copy = clone(model)
    assert copy is not model and copy.get_params() == model.get_params()
    assert repr(model) == "TransferFunctionModel(detrend='mean', intervals='white', n_poles=3, n_zeros=1)"
    assert StateSpaceModel().set_params(order=4).order == 4
    with pytest.raises(IdentificationError, match="poles: not a parameter of StateSpaceModel"):
        StateSpaceModel().set_params(poles=4)
    source = Path(__file__).parents[1] / "src"
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys, softtip.sysid, softtip.sysid.models, softtip.cli.main; print(sorted({m for m "
         "in sys.modules if m.split('.')[0] == 'sklearn' or m in ('scipy.signal', 'scipy.stats', 'scipy.optimize')}))"],
        env={"PYTHONPATH": str(source), "PATH": ""}, capture_output=True, text=True, timeout=120)
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.strip() == "[]"
