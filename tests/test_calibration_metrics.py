"""Calibration metrics against scikit-learn, scipy and hand-computed cases."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import stats
from sklearn import metrics as skm

from softtip.metrics import (
    confusion,
    first_detection,
    hysteresis_percent,
    mae_percent_fs,
    max_abs_error,
    mean_abs_error,
    mean_probability_of_true_class,
    pearson_r,
    per_condition,
    r2,
    rmse,
    rmse_percent_fs,
    sensitivity,
)


@pytest.fixture(scope="module")
def estimates():
    rng = np.random.default_rng(0)
    y = rng.normal(0, [2.0, 5.0, 0.5], (200, 3))
    return y, y + rng.normal(0, [0.1, 0.7, 0.2], (200, 3))


def test_error_metrics_equal_scikit_learn_per_output(estimates):
    y, yhat = estimates
    np.testing.assert_allclose(mean_abs_error(y, yhat), skm.mean_absolute_error(y, yhat, multioutput="raw_values"))
    np.testing.assert_allclose(rmse(y, yhat), skm.root_mean_squared_error(y, yhat, multioutput="raw_values"))
    np.testing.assert_allclose(r2(y, yhat), skm.r2_score(y, yhat, multioutput="raw_values"))
    np.testing.assert_allclose(max_abs_error(y, yhat), [skm.max_error(y[:, k], yhat[:, k]) for k in range(3)])
    # one output gives a plain float
    assert isinstance(rmse(y[:, 0], yhat[:, 0]), float)
    assert mean_abs_error(y[:, 1], yhat[:, 1]) == pytest.approx(skm.mean_absolute_error(y[:, 1], yhat[:, 1]))


def test_pearson_r_equals_scipy(estimates):
    y, yhat = estimates
    np.testing.assert_allclose(pearson_r(y, yhat), [stats.pearsonr(y[:, k], yhat[:, k]).statistic for k in range(3)])
    assert np.isnan(pearson_r(np.ones(5), np.arange(5.0)))
    assert np.isnan(r2(np.ones(5), np.arange(5.0)))


def test_percent_of_full_scale_by_hand():
    y = np.zeros((4, 2))
    yhat = np.array([[1, 2], [-1, -2], [1, 2], [-1, 6]], dtype=float)
    # output 0: RMSE 1, MAE 1 on a 20 N range; output 1: RMSE sqrt(12) = 3.464, MAE 3 on a 60 deg range
    np.testing.assert_allclose(rmse_percent_fs(y, yhat, [20, 60]), [5.0, 100 * np.sqrt(12) / 60])
    np.testing.assert_allclose(mae_percent_fs(y, yhat, [20, 60]), [5.0, 5.0])
    assert rmse_percent_fs(y[:, 0], yhat[:, 0], 10) == pytest.approx(10.0)
    with pytest.raises(ValueError, match="full_scale"):
        mae_percent_fs(y, yhat, 0)


def test_mean_probability_of_the_true_class_by_hand():
    proba = np.array([[0.7, 0.2, 0.1], [0.1, 0.6, 0.3], [0.5, 0.25, 0.25]])
    expected = (0.2 + 0.3 + 0.5) / 3
    assert mean_probability_of_true_class(proba, ["B", "C", "A"], ["A", "B", "C"]) == pytest.approx(expected)
    # the column order follows `classes`, not the sorted labels
    assert mean_probability_of_true_class(proba, [2, 0, 1], [1, 2, 0]) == pytest.approx(expected)
    with pytest.raises(ValueError, match="not in the given classes"):
        mean_probability_of_true_class(proba, ["B", "C", "D"], ["A", "B", "C"])


def test_confusion_equals_scikit_learn_with_explicit_label_order():
    rng = np.random.default_rng(1)
    states = np.array(["air", "inserted", "left-clip", "right-clip"])
    y_true, y_pred = states[rng.integers(0, 4, 300)], states[rng.integers(0, 4, 300)]
    order = ["right-clip", "air", "inserted", "left-clip"]
    np.testing.assert_array_equal(confusion(y_true, y_pred, order), skm.confusion_matrix(y_true, y_pred, labels=order))
    with pytest.raises(ValueError, match="y_pred holds labels"):
        confusion(y_true, np.where(y_pred == "air", "flying", y_pred), order)


def test_per_condition_reports_each_condition_and_overall(estimates):
    y, yhat = estimates
    angles = np.tile([20, 0, 10, 30], 50)
    table = per_condition(mean_abs_error, y[:, 0], yhat[:, 0], angles)
    assert list(table) == [20, 0, 10, 30, "overall"]  # first-appearance order, then overall
    for angle in (0, 10, 20, 30):
        mask = angles == angle
        assert table[angle] == pytest.approx(np.mean(np.abs(yhat[mask, 0] - y[mask, 0])))
    assert table["overall"] == pytest.approx(skm.mean_absolute_error(y[:, 0], yhat[:, 0]))
    assert all(type(key) in (int, str) for key in table)  # JSON-friendly keys


def test_hysteresis_of_a_hand_built_cycle():
    # loading: Z = 3F from 0 to 10 N in 0.3 N steps (5 N is not a sample); 1 s rest with the force
    # relaxing to 9.8 N; unloading: Z = 2F + 10 back to 0 N in 0.7 N steps
    loading = np.append(np.arange(0, 10, 0.3), 10.0)
    rest = np.linspace(10.0, 9.8, 6)[1:]
    unloading = np.arange(9.8, -0.01, -0.7)
    force = np.concatenate([loading, rest, unloading])
    z = np.concatenate([3 * loading, np.full(len(rest), 30.0), 2 * unloading + 10])
    # mid force 5 N: Z_up = 15, Z_down = 20; Z spans 0..30
    assert hysteresis_percent(force, z) == pytest.approx(100 * 5 / 30)
    with pytest.raises(ValueError, match="unloading branch never reaches"):
        hysteresis_percent(force[: len(loading) + 3], z[: len(loading) + 3])


def test_sensitivity_is_the_least_squares_slope_of_the_ascending_branch_in_mt_per_n():
    rng = np.random.default_rng(2)
    force = np.concatenate([np.linspace(0, 6, 40), np.linspace(6, 0, 40)])
    mfd = np.column_stack([120 * force, -40 * force, 900 * force]) + rng.normal(0, 5, (80, 3))  # µT
    mfd[40:] += 300  # a different unloading branch must not count
    expected = [stats.linregress(force[:40], mfd[:40, k]).slope / 1000 for k in range(3)]
    np.testing.assert_allclose(sensitivity(force, mfd), expected, rtol=1e-12)
    assert sensitivity(force, mfd[:, 2]) == pytest.approx(0.9, rel=0.01)


def test_first_detection_by_hand():
    force = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    predicted = np.array([0, 2, 0, 2, 2, 2])
    assert first_detection(force, predicted, 2) == 0.1
    assert first_detection(force, predicted, 2, persistence=2) == 0.4  # samples 3 and 4 agree
    assert first_detection(force, predicted, 2, persistence=3) == 0.5
    assert np.isnan(first_detection(force, predicted, 2, persistence=4))
    assert first_detection(force, predicted, [1, 1, 0, 0, 2, 2]) == 0.2  # one true state per sample
    with pytest.raises(ValueError, match="persistence"):
        first_detection(force, predicted, 2, persistence=0)


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match="same non-empty"):
        rmse(np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="one label per sample"):
        per_condition(rmse, np.zeros(3), np.zeros(3), [1, 2])


# --------------------------------------------------------------------------
# Edge cases and refusals, worked by hand
# --------------------------------------------------------------------------


def test_one_output_gives_a_plain_float_from_every_metric():
    y, yhat = np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 3.0])
    for value in (mean_abs_error(y, yhat), max_abs_error(y, yhat), rmse(y, yhat), r2(y, yhat),
                  pearson_r(y, yhat), rmse_percent_fs(y, yhat, 10), mae_percent_fs(y, yhat, 10),
                  sensitivity(y, yhat)):
        assert type(value) is float


def test_a_single_sample_is_enough_and_no_sample_is_refused():
    assert mean_abs_error([1.0], [3.0]) == 2.0
    assert rmse([1.0], [-2.0]) == 3.0
    with pytest.raises(ValueError, match="same non-empty"):
        rmse([], [])


def test_a_full_scale_below_one_is_a_valid_range_and_none_is_refused():
    # RMSE 1 on a 0.5 N range is 200 %
    assert rmse_percent_fs([0.0, 0.0], [1.0, -1.0], 0.5) == pytest.approx(200.0)
    with pytest.raises(ValueError, match=r"^full_scale must be positive \(one value or one per output\), got None$"):
        rmse_percent_fs([0.0], [1.0], None)


def test_r2_and_pearson_of_a_small_spread_by_hand():
    # y spreads 0..0.2 (SS_tot = 0.02); SS_res = 0.01 -> R² = 0.5
    y, yhat = np.array([0.0, 0.1, 0.2]), np.array([0.0, 0.1, 0.3])
    assert r2(y, yhat) == pytest.approx(0.5)
    # Σ dy·dŷ = 0.03, Σ dy² = 0.02, Σ dŷ² = 0.14/3 -> r = 0.03 / sqrt(0.02 · 0.14/3)
    assert pearson_r(y, yhat) == pytest.approx(0.03 / np.sqrt(0.02 * 0.14 / 3))


def test_a_constant_series_gives_nan_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(r2(np.ones(5), np.arange(5.0)))  # residual / 0
        assert np.isnan(r2(np.ones(5), np.ones(5)))  # 0 / 0
        assert np.isnan(pearson_r(np.ones(5), np.arange(5.0)))


def test_labels_must_be_distinct_non_empty_and_one_dimensional():
    assert confusion(["a", "a"], ["a", "a"], ["a"]).tolist() == [[2]]  # one label is enough
    for labels in (["a", "a", "b"], [["a", "b"]], []):
        with pytest.raises(ValueError, match="^labels must be a non-empty 1-D sequence of distinct labels, got "):
            confusion(["a"], ["a"], labels)
    with pytest.raises(ValueError, match="^classes must be a non-empty 1-D sequence"):
        mean_probability_of_true_class([[0.5, 0.5]], ["a"], ["a", "a"])


def test_unknown_labels_are_named_up_to_five():
    with pytest.raises(ValueError, match=r"^y holds labels not in the given classes/labels: \['D'\]$"):
        mean_probability_of_true_class([[1.0, 0.0]], ["D"], ["A", "B"])
    with pytest.raises(ValueError, match=r"^y_true holds labels not in the given classes/labels: \[1 2 3 4 5\]$"):
        confusion([6, 5, 4, 3, 2, 1, 0], [0] * 7, [0])


def test_mean_probability_of_one_sample_and_a_proba_of_the_wrong_shape():
    assert mean_probability_of_true_class([[0.25, 0.75]], ["b"], ["a", "b"]) == 0.75
    with pytest.raises(ValueError, match=r"^proba must be \(n_samples=2, n_classes=2\), got \(2, 3\)$"):
        mean_probability_of_true_class(np.full((2, 3), 1 / 3), ["a", "b"], ["a", "b"])


def test_confusion_counts_are_integers_and_lengths_must_agree():
    assert confusion(["a", "b"], ["b", "b"], ["a", "b"]).dtype == np.int64
    with pytest.raises(ValueError, match=r"^y_true and y_pred must be 1-D of the same length, got \(3,\) and \(4,\)$"):
        confusion(["a"] * 3, ["a"] * 4, ["a"])


def test_per_condition_takes_an_object_array_of_labels_and_refuses_overall():
    # an object column (as a data frame holds strings) gives its own str keys
    conditions = np.array(["left", "right", "left"], dtype=object)
    table = per_condition(max_abs_error, [0.0, 0.0, 0.0], [1.0, 2.0, 3.0], conditions)
    assert table == {"left": 3.0, "right": 2.0, "overall": 3.0}
    with pytest.raises(ValueError, match='^conditions must not use the label "overall", which names the all-sample value$'):
        per_condition(rmse, [0.0, 0.0], [1.0, 1.0], ["a", "overall"])


def test_sensitivity_of_two_samples_by_hand_and_refusals():
    # 0 -> 2 N with 0 -> 4000 µT: 2 mT/N
    assert sensitivity([0.0, 2.0], [0.0, 4000.0]) == pytest.approx(2.0)
    with pytest.raises(ValueError, match=r"^force must be 1-D with >= 2 samples and mfd have one row per force sample, "
                                         r"got shapes \(3,\) and \(2,\)$"):
        sensitivity([0.0, 1.0, 2.0], [0.0, 1.0])
    for force, mfd in (([[0.0, 1.0]], [[0.0, 1.0]]), ([0.0, 1.0], np.zeros((2, 3, 1))), ([0.0], [0.0])):
        with pytest.raises(ValueError, match="^force must be 1-D with >= 2 samples"):
            sensitivity(force, mfd)
    with pytest.raises(ValueError, match="^force and mfd must be finite$"):
        sensitivity([0.0, 1.0], [0.0, np.nan])
    with pytest.raises(ValueError, match="^force does not rise on the ascending branch: sensitivity undefined$"):
        sensitivity([3.0, 2.0, 1.0], [0.0, 1.0, 2.0])


def test_first_detection_edges_by_hand():
    force = np.array([0.0, 0.1, 0.2])
    assert first_detection(force, [1, 1, 1], 1, persistence=3) == 0.2  # as many samples as the persistence
    assert np.isnan(first_detection(force[:2], [1, 1], 1, persistence=3))  # fewer samples than the persistence
    for persistence in (True, 2.5):
        with pytest.raises(ValueError, match=rf"^persistence must be an integer >= 1, got {persistence!r}$"):
            first_detection(force, [1, 1, 1], 1, persistence=persistence)
    with pytest.raises(ValueError, match=r"^force and predicted_state must be 1-D of the same length, got \(3,\) and \(2,\)$"):
        first_detection(force, [1, 1], 1)
    with pytest.raises(ValueError, match=r"^true_state must be one state or one per sample \(3\), got shape \(2,\)$"):
        first_detection(force, [1, 1, 1], [1, 1])
