"""Calibration models against independent references (numpy lstsq, finite differences,
scikit-learn estimators and scalers, hand-derived initialisation), and their model files."""

from __future__ import annotations

import json
import warnings
import zipfile

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import r2_score
from sklearn.model_selection import GroupKFold, cross_val_score, train_test_split
from sklearn.neural_network import MLPClassifier, MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import MinMaxScaler, StandardScaler
from sklearn.utils.estimator_checks import parametrize_with_checks

from softtip._core.archive import write_archive
from softtip._core.threads import single_threaded_blas
from softtip.calibration import (
    LMNetwork,
    ModelFileError,
    PolynomialFit,
    SoftmaxClassifier,
    load_model,
    save_model,
)
from softtip.calibration import feedforward as ff
from softtip.calibration.classifier import cross_entropy_and_gradient


def smooth_targets(x: np.ndarray) -> np.ndarray:
    """A smooth nonlinear 6 -> 2 map, like field changes -> (force, angle)."""
    return np.column_stack([np.sin(1.5 * x[:, 0]) + x[:, 1] * x[:, 2] + 0.5 * np.tanh(2 * x[:, 3]),
                            np.cos(x[:, 4] + x[:, 5]) + 0.3 * x[:, 0] ** 2 - x[:, 2]])


@pytest.fixture(scope="module")
def smooth_problem():
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, (1500, 6))
    y = smooth_targets(x) + 0.01 * rng.standard_normal((1500, 2))
    return train_test_split(x, y, test_size=0.3, random_state=0)


@pytest.fixture(scope="module")
def blobs():
    rng = np.random.default_rng(1)
    centres = np.array([[0, 0, 0, 0], [2, 0, 1, 0], [0, 2, 0, 1]], dtype=float)
    labels = rng.integers(0, 3, 1500)
    x = centres[labels] + rng.standard_normal((1500, 4))  # overlapping: Bayes accuracy below 1
    names = np.array(["edge", "point-A", "point-B"])[labels]
    return train_test_split(x, names, test_size=0.4, random_state=0)


# --------------------------------------------------------------------------
# Polynomial fit
# --------------------------------------------------------------------------


def test_polynomial_coefficients_equal_lstsq_on_the_published_design_matrix():
    rng = np.random.default_rng(2)
    readings = rng.uniform(-1500, 1500, (200, 3))  # µT, as the sensor reports them
    forces = np.column_stack([np.tanh(readings[:, 0] / 800) + 1e-3 * readings[:, 2], readings[:, 1] ** 2 / 1e6])
    design = np.column_stack([readings[:, 0] ** 3, readings[:, 0] ** 2, readings[:, 0],
                              readings[:, 1] ** 3, readings[:, 1] ** 2, readings[:, 1],
                              readings[:, 2] ** 3, readings[:, 2] ** 2, readings[:, 2], np.ones(200)])
    expected, *_ = np.linalg.lstsq(design, forces, rcond=None)
    fit = PolynomialFit().fit(readings, forces)
    np.testing.assert_allclose(fit.coef_, expected, rtol=1e-7, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(fit.predict(readings), design @ expected, atol=1e-8)


def test_polynomial_recovers_a_known_polynomial_exactly():
    rng = np.random.default_rng(3)
    x = rng.uniform(-2, 2, (50, 2))
    # y = 0.5 x1³ − x1² + 2 x1 − 0.25 x2³ + 3 x2 + 7 and a second output of degree 2
    y = np.column_stack([0.5 * x[:, 0] ** 3 - x[:, 0] ** 2 + 2 * x[:, 0] - 0.25 * x[:, 1] ** 3 + 3 * x[:, 1] + 7,
                         x[:, 1] ** 2 - x[:, 0]])
    fit = PolynomialFit(degree=3).fit(x, y)
    expected = np.array([[0.5, -1, 2, -0.25, 0, 3, 7], [0, 0, -1, 0, 1, 0, 0]]).T
    np.testing.assert_allclose(fit.coef_, expected, atol=1e-10)
    assert PolynomialFit(degree=2).fit(x, y[:, 1]).predict(x[:3]).shape == (3,)
    np.testing.assert_allclose(fit.predict_one(x[4]), fit.predict(x[4:5])[0], rtol=1e-12)


# --------------------------------------------------------------------------
# Network kernels
# --------------------------------------------------------------------------


def _finite_difference_jacobian(layers, x):
    shapes = [w.shape for w in layers]
    theta = ff.pack(layers)
    step = 1e-6
    columns = []
    for p in range(len(theta)):
        shift = np.zeros_like(theta)
        shift[p] = step
        plus = ff.forward(ff.unpack(theta + shift, shapes), x)[-1]
        minus = ff.forward(ff.unpack(theta - shift, shapes), x)[-1]
        columns.append(((plus - minus) / (2 * step)).ravel())
    return np.column_stack(columns)


@pytest.mark.parametrize("sizes", [[3, 5, 2], [4, 6, 1], [3, 4, 5, 3]])
def test_gauss_newton_matrix_and_gradient_match_finite_differences(sizes):
    rng = np.random.default_rng(4)
    layers = ff.initial_layers(sizes, rng)
    x = rng.uniform(-1, 1, (9, sizes[0]))
    residuals = rng.standard_normal((9, sizes[-1]))
    jacobian = _finite_difference_jacobian(layers, x)
    activations = ff.forward(layers, x)
    np.testing.assert_allclose(ff.gauss_newton_matrix(layers, activations), jacobian.T @ jacobian, atol=1e-7)
    np.testing.assert_allclose(ff.backprop_gradient(layers, activations, residuals),
                               jacobian.T @ residuals.ravel(), atol=1e-7)


def test_cross_entropy_gradient_matches_finite_differences():
    rng = np.random.default_rng(5)
    sizes = [3, 4, 4, 3]
    layers = ff.initial_layers(sizes, rng)
    shapes = [w.shape for w in layers]
    x = rng.uniform(-1, 1, (11, 3))
    one_hot = np.eye(3)[rng.integers(0, 3, 11)]
    _, gradient = cross_entropy_and_gradient(layers, x, one_hot)
    theta = ff.pack(layers)
    numeric = np.empty_like(theta)
    for p in range(len(theta)):
        shift = np.zeros_like(theta)
        shift[p] = 1e-6
        numeric[p] = (cross_entropy_and_gradient(ff.unpack(theta + shift, shapes), x, one_hot)[0]
                      - cross_entropy_and_gradient(ff.unpack(theta - shift, shapes), x, one_hot)[0]) / 2e-6
    np.testing.assert_allclose(gradient, numeric, atol=1e-8)


def test_mapminmax_equals_minmax_scaler_to_minus_one_one():
    rng = np.random.default_rng(6)
    x = rng.normal(50, 20, (40, 3))
    reference = MinMaxScaler(feature_range=(-1, 1)).fit(x)
    low, high = x.min(axis=0), x.max(axis=0)
    np.testing.assert_allclose(ff.to_unit_range(x, low, high), reference.transform(x), atol=1e-13)


def test_nguyen_widrow_rows_have_the_published_magnitude_and_spread_biases():
    n_out, n_in = 8, 3
    weights = ff.nguyen_widrow(n_out, n_in, np.random.default_rng(7))
    magnitude = 2 * 0.7 * n_out ** (1 / n_in)  # 0.7 S^(1/R), stretched to tanh's [-2, 2]
    np.testing.assert_allclose(np.linalg.norm(weights[:, :-1], axis=1), magnitude)
    np.testing.assert_allclose(np.abs(weights[:, -1]), magnitude * np.abs(np.linspace(-1, 1, n_out)))


def test_division_keeps_groups_whole_in_the_toolbox_fractions():
    groups = np.repeat(np.arange(20), 7)  # 20 trials of 7 samples
    train, validation, test = ff.divide(len(groups), (0.70, 0.15, 0.15), np.random.default_rng(8), groups)
    assert [len(np.unique(groups[part])) for part in (train, validation, test)] == [14, 3, 3]
    assert not set(groups[train]) & set(groups[validation]) and not set(groups[train]) & set(groups[test])
    assert sorted(np.concatenate([train, validation, test])) == list(range(len(groups)))


# --------------------------------------------------------------------------
# Levenberg–Marquardt network
# --------------------------------------------------------------------------


def test_lm_network_beats_mlp_regressor_on_held_out_data(smooth_problem):
    # either learner lands in a poor local minimum from some initial weights: compare medians over seeds
    x_train, x_test, y_train, y_test = smooth_problem
    network_scores, mlp_scores = [], []
    for seed in range(3):
        network = LMNetwork((10,), random_state=seed).fit(x_train, y_train)
        with single_threaded_blas():  # a second BLAS thread on these thin products only thrashes
            mlp = MLPRegressor(hidden_layer_sizes=(10,), activation="tanh", solver="lbfgs", max_iter=1000,
                               random_state=seed).fit(x_train, y_train)
        network_scores.append(r2_score(y_test, network.predict(x_test)))
        mlp_scores.append(r2_score(y_test, mlp.predict(x_test)))
    assert np.median(network_scores) >= np.median(mlp_scores)
    assert np.median(network_scores) > 0.999


def test_lm_semantics_error_never_rises_and_mu_moves_by_decades(smooth_problem):
    x_train, _, y_train, _ = smooth_problem
    network = LMNetwork((10,), max_epochs=40, random_state=1).fit(x_train, y_train)
    assert network.stop_reason_ == "max_epochs" and len(network.history_["train"]) == 41
    assert np.all(np.diff(network.history_["train"]) < 0)  # a step is only taken when it lowers the error
    decades = np.log10(network.history_["mu"] / 1e-3)
    np.testing.assert_allclose(decades, np.round(decades), atol=1e-9)


def test_early_stopping_fires_on_noise_and_returns_the_best_validation_weights():
    rng = np.random.default_rng(9)
    x, noise = rng.uniform(-1, 1, (300, 6)), rng.standard_normal(300)
    x_val, noise_val = rng.uniform(-1, 1, (100, 6)), rng.standard_normal(100)
    network = LMNetwork((20,), random_state=0).fit(x, noise, validation_data=(x_val, noise_val))
    assert network.stop_reason_ == "validation"
    history = network.history_["validation"]
    assert len(history) - 1 == network.best_epoch_ + 6  # six failures after the best epoch
    assert network.best_epoch_ == int(np.argmin(history))
    scaled = ff.to_unit_range(noise_val[:, None], network.target_min_, network.target_max_)
    scaled_prediction = ff.to_unit_range(network.predict(x_val)[:, None], network.target_min_, network.target_max_)
    assert np.mean((scaled - scaled_prediction) ** 2) == pytest.approx(history[network.best_epoch_], rel=1e-9)



@pytest.mark.parametrize("min_progress", [None, 0.01, 0.003])
def test_failures_stop_training_only_once_it_has_stopped_learning_by_min_progress(min_progress):
    rng = np.random.default_rng(5)
    x, x_val = rng.uniform(-1, 1, (200, 6)), rng.uniform(-1, 1, (200, 6))
    noisy = lambda points: smooth_targets(points)[:, 0] + 0.1 * rng.standard_normal(len(points))  # noqa: E731
    y, y_val = noisy(x), noisy(x_val)
    network = LMNetwork((10,), min_progress=min_progress, random_state=0).fit(x, y, validation_data=(x_val, y_val))
    train, validation = network.history_["train"], network.history_["validation"]
    # the rule by hand: an epoch above the lowest validation error so far is a failure, a new lowest
    # resets the count; stop at 6 failures, once the training error fell by less than min_progress of
    # itself over the last 6 epochs (always, without min_progress)
    lowest, failures = validation[0], 0
    for epoch in range(len(validation)):
        if validation[epoch] < lowest:
            lowest, failures = validation[epoch], 0
        elif validation[epoch] > lowest:
            failures += 1
        stalled = min_progress is None or (epoch >= 6 and train[epoch - 6] - train[epoch] < min_progress * train[epoch])
        if failures >= 6 and stalled:
            break
    assert network.stop_reason_ == "validation" and len(validation) - 1 == epoch >= network.best_epoch_ + 6
    assert network.best_epoch_ == int(np.argmin(validation))


def test_deep_four_by_ten_network_trains_with_lm():
    rng = np.random.default_rng(10)
    x = rng.uniform(-1, 1, (500, 3))
    y = np.sin(2 * x[:, 0]) * x[:, 1] + x[:, 2] ** 2
    # all data for training: this checks the optimiser, not the luck of an early validation stop
    network = LMNetwork((10, 10, 10, 10), division=(1.0, 0.0, 0.0), max_epochs=100, random_state=0).fit(x, y)
    assert [w.shape for w in network.weights_] == [(10, 4), (10, 11), (10, 11), (10, 11), (1, 11)]
    assert np.isnan(network.history_["validation"]).all() and network.history_["train"][-1] < 1e-5
    x_new = rng.uniform(-1, 1, (200, 3))
    assert network.score(x_new, np.sin(2 * x_new[:, 0]) * x_new[:, 1] + x_new[:, 2] ** 2) > 0.99


def test_predict_paths_equal_the_network_written_out_by_hand(smooth_problem):
    x_train, x_test, y_train, _ = smooth_problem
    network = LMNetwork((7, 5), max_epochs=15, random_state=2).fit(x_train, y_train)
    scaled = 2 * (x_test - network.input_min_) / (network.input_max_ - network.input_min_) - 1
    (w1, w2, w3) = network.weights_
    h = np.tanh(np.tanh(scaled @ w1[:, :-1].T + w1[:, -1]) @ w2[:, :-1].T + w2[:, -1])
    span = network.target_max_ - network.target_min_
    expected = (h @ w3[:, :-1].T + w3[:, -1] + 1) / 2 * span + network.target_min_
    np.testing.assert_allclose(network.predict(x_test), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(network.predict_one(x_test[0]), expected[0], rtol=1e-12, atol=1e-12)


def test_fit_with_groups_and_in_cross_validation_by_trial(smooth_problem):
    x_train, _, y_train, _ = smooth_problem
    trials = np.arange(len(x_train)) // 35
    network = LMNetwork((5,), max_epochs=30, random_state=0)
    network.fit(x_train, y_train, groups=trials)
    scores = cross_val_score(make_pipeline(StandardScaler(), clone(network)), x_train, y_train[:, 0],
                             groups=trials, cv=GroupKFold(3))
    assert scores.shape == (3,) and np.all(scores > 0.9)


@pytest.mark.parametrize("params, message", [
    ({"hidden_layer_sizes": (10, 0)}, "hidden_layer_sizes"),
    ({"division": (0.5, 0.6, 0.1)}, "division"),
    ({"mu_inc": 0.5}, "mu_inc"),
    ({"max_fail": 0}, "max_fail"),
    ({"min_progress": -0.1}, "min_progress"),
])
def test_bad_hyper_parameters_are_named(params, message):
    with pytest.raises(ValueError, match=message):
        LMNetwork(**params).fit(np.zeros((10, 2)), np.zeros(10))


# --------------------------------------------------------------------------
# Softmax classifier
# --------------------------------------------------------------------------


def test_softmax_classifier_matches_logistic_regression_and_mlp_on_blobs(blobs):
    x_train, x_test, y_train, y_test = blobs
    classifier = SoftmaxClassifier((10,), random_state=0).fit(x_train, y_train)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        mlp = MLPClassifier(hidden_layer_sizes=(10,), activation="tanh", max_iter=500, random_state=0)
        mlp.fit(x_train, y_train)
    logistic = LogisticRegression().fit(x_train, y_train)
    accuracy = classifier.score(x_test, y_test)
    # the classes overlap: all three sit near the Bayes rate; allow one test sample of luck
    assert accuracy >= logistic.score(x_test, y_test) - 1 / len(y_test)
    assert accuracy >= mlp.score(x_test, y_test) - 1 / len(y_test)
    assert list(classifier.classes_) == ["edge", "point-A", "point-B"]


def test_classifier_probabilities_and_single_sample_paths(blobs):
    x_train, x_test, y_train, _ = blobs
    classifier = SoftmaxClassifier((6, 6), max_epochs=50, random_state=1).fit(x_train, y_train)
    proba = classifier.predict_proba(x_test)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0, rtol=1e-12)
    assert np.all(classifier.predict(x_test) == classifier.classes_[proba.argmax(axis=1)])
    np.testing.assert_allclose(classifier.predict_proba_one(x_test[3]), proba[3], rtol=1e-12)
    assert classifier.predict_one(x_test[3]) == classifier.predict(x_test[3:4])[0]
    train_loss = classifier.history_["train"]
    assert np.all(np.diff(train_loss) <= 0)  # SCG only takes steps that lower the error


def test_classifier_refuses_a_single_class():
    with pytest.raises(ValueError, match="2 classes"):
        SoftmaxClassifier().fit(np.zeros((5, 2)), np.ones(5))


# --------------------------------------------------------------------------
# scikit-learn conformance
# --------------------------------------------------------------------------


@parametrize_with_checks([PolynomialFit(), LMNetwork((5,), max_epochs=50, random_state=0),
                          SoftmaxClassifier((5,), max_epochs=100, random_state=0)])
def test_scikit_learn_estimator_checks(estimator, check):
    check(estimator)


# --------------------------------------------------------------------------
# Model files
# --------------------------------------------------------------------------

LABELS = {"input_channels": ["Sx", "Sy", "Sz", "Sx2", "Sy2", "Sz2"], "input_units": "uT"}


@pytest.fixture(scope="module")
def fitted(smooth_problem, blobs):
    x_train, _, y_train, _ = smooth_problem
    bx_train, _, by_train, _ = blobs
    return {
        "network": LMNetwork((6,), max_epochs=20, random_state=0).fit(x_train, y_train),
        "polynomial": PolynomialFit().fit(x_train, y_train),
        "pipeline": make_pipeline(StandardScaler(), MinMaxScaler(), LMNetwork((4,), max_epochs=10, random_state=0))
        .fit(x_train, y_train[:, 0]),
        "classifier": SoftmaxClassifier((5,), max_epochs=30, random_state=0).fit(np.hstack([bx_train, bx_train[:, :2]]),
                                                                                by_train),
    }


@pytest.mark.parametrize("name", ["network", "polynomial", "pipeline", "classifier"])
def test_model_file_round_trip_gives_identical_predictions(tmp_path, fitted, smooth_problem, name):
    model = fitted[name]
    targets = {"classifier": (["contact_state"], ""), "pipeline": (["Fz"], "N")}.get(
        name, (["Fz", "angle"], ["N", "deg"]))
    path = save_model(tmp_path / "model.npz", model, **LABELS, target_names=targets[0], target_units=targets[1],
                      extra={"trials": 70})
    loaded, metadata = load_model(path)
    x = smooth_problem[1]
    np.testing.assert_array_equal(loaded.predict(x), model.predict(x))
    assert metadata.input_channels == tuple(LABELS["input_channels"]) and metadata.input_units == ("uT",) * 6
    assert metadata.target_names == tuple(targets[0]) and metadata.extra == {"trials": 70}
    assert metadata.baseline == "initial-value" and metadata.schema_version == 1
    if name == "classifier":
        np.testing.assert_array_equal(loaded.predict_proba(x), model.predict_proba(x))
        np.testing.assert_array_equal(loaded.classes_, model.classes_)
    if name == "network":
        np.testing.assert_array_equal(loaded.predict_one(x[0]), model.predict_one(x[0]))
        assert loaded.stop_reason_ == model.stop_reason_
        np.testing.assert_array_equal(loaded.history_["train"], model.history_["train"])
    with np.load(path, allow_pickle=False) as archive:  # plain npz + JSON, readable by other tools
        assert json.loads(str(archive["metadata"]))["format"] == "softtip-model"


def _saved(tmp_path, fitted):
    return save_model(tmp_path / "network.npz", fitted["network"], **LABELS, target_names=["Fz", "angle"],
                      target_units=["N", "deg"])


def _rewrite(path, edit_metadata=None, edit_arrays=None, keep_checksum=False):
    """Rewrite a saved file with edited contents, with a fresh checksum unless ``keep_checksum``."""
    with np.load(path, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    metadata = json.loads(str(arrays.pop("metadata")))
    if edit_metadata:
        edit_metadata(metadata)
    if edit_arrays:
        edit_arrays(arrays)
    if keep_checksum:
        with open(path, "wb") as handle:
            np.savez(handle, metadata=np.array(json.dumps(metadata)), **arrays)
    else:
        metadata.pop("sha256")
        write_archive(path, metadata, arrays)


def test_tampered_arrays_fail_the_checksum(tmp_path, fitted):
    path = _saved(tmp_path, fitted)
    _rewrite(path, edit_arrays=lambda a: a["model/weights/0"].__setitem__((0, 0), 0.5), keep_checksum=True)
    with pytest.raises(ModelFileError, match="checksum mismatch"):
        load_model(path)


def test_tampered_metadata_fails_the_checksum(tmp_path, fitted):
    path = _saved(tmp_path, fitted)
    _rewrite(path, edit_metadata=lambda m: m.__setitem__("target_units", ["kN", "deg"]), keep_checksum=True)
    with pytest.raises(ModelFileError, match="checksum mismatch"):
        load_model(path)


@pytest.mark.parametrize("edit_metadata, edit_arrays, message", [
    (lambda m: m.__setitem__("schema_version", 2), None, "unsupported schema version 2"),
    (lambda m: m["model"].__setitem__("class", "RandomForest"), None, "unknown model class 'RandomForest'"),
    (None, lambda a: a.__setitem__("model/weights/0", np.zeros((6, 5))),
     r"inconsistent model: array 'weights/0' has shape \(6, 5\)"),
    (None, lambda a: a["model/weights/1"].__setitem__((0, 0), np.nan), "non-finite"),
    (lambda m: m.__setitem__("input_channels", ["Sx"]), None, "input_channels has 1 entries"),
    (lambda m: m["model"]["params"].__setitem__("hidden_layer_sizes", [6, 6]), None, "inconsistent model"),
])
def test_refusals_name_the_problem(tmp_path, fitted, edit_metadata, edit_arrays, message):
    path = _saved(tmp_path, fitted)
    _rewrite(path, edit_metadata, edit_arrays)
    with pytest.raises(ModelFileError, match=message) as refusal:
        load_model(path)
    assert str(path) in str(refusal.value) and "\n" not in str(refusal.value)


def test_files_that_are_not_models_are_refused(tmp_path, fitted):
    path = _saved(tmp_path, fitted)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(ModelFileError, match="truncated or unreadable"):
        load_model(truncated)
    text = tmp_path / "notes.npz"
    text.write_text("force, angle\n1, 2\n")
    with pytest.raises(ModelFileError, match="not a softtip model file"):
        load_model(text)
    plain = tmp_path / "plain.npz"
    np.savez(plain, weights=np.ones(3))
    with pytest.raises(ModelFileError, match="not a softtip model file"):
        load_model(plain)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, metadata=np.array(json.dumps({"format": "other"})))
    with pytest.raises(ModelFileError, match="not a softtip model file"):
        load_model(foreign)
    with pytest.raises(ModelFileError, match="does not exist"):
        load_model(tmp_path / "missing.npz")
    assert zipfile.is_zipfile(path)


def test_saving_checks_labels_and_models(tmp_path, fitted):
    with pytest.raises(ModelFileError, match="input_channels has 2 entries, the model has 6"):
        save_model(tmp_path / "m.npz", fitted["network"], input_channels=["a", "b"], input_units="uT",
                   target_names=["Fz", "angle"], target_units="N")
    with pytest.raises(ModelFileError, match="not fitted"):
        save_model(tmp_path / "m.npz", LMNetwork(), **LABELS, target_names=["Fz"], target_units="N")
    with pytest.raises(ModelFileError, match="cannot save a MLPRegressor"):
        save_model(tmp_path / "m.npz", MLPRegressor(), **LABELS, target_names=["Fz"], target_units="N")
    assert not list(tmp_path.iterdir())  # nothing half-written
