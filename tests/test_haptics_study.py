"""The study's statistics against scipy and hand-computed values, and a small run of the study."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure
from scipy import stats

from softtip.systems.haptics.statistics import friedman, signed_ranks, wilcoxon
from softtip.systems.haptics.study import METHODS, StudySettings, run_study


def test_signed_ranks_by_hand():
    x = np.array([5.0, 3.0, 8.0, 1.0, 4.0, 6.0])
    y = np.array([3.0, 4.0, 4.0, 1.0, 7.0, 1.0])
    # differences 2, -1, 4, 0 (dropped), -3, 5: ranks of |d| 2, 1, 4, 3, 5 -> W+ = 2 + 4 + 5, W- = 1 + 3
    assert signed_ranks(x, y) == (11.0, 4.0)
    result = wilcoxon(x, y, tests=3)
    assert result.w_scipy == 4.0 == stats.wilcoxon(x, y).statistic  # scipy: min(W+, W-)
    assert result.signed_rank_sum == 7.0
    assert result.p_bonferroni == pytest.approx(min(1.0, 3 * stats.wilcoxon(x, y).pvalue))


def test_tied_magnitudes_share_their_mean_rank():
    x, y = np.array([2.0, 0.0, 3.0, 5.0]), np.array([0.0, 2.0, 0.0, 0.0])
    # |d| = 2, 2, 3, 5: the two 2s share rank 1.5
    assert signed_ranks(x, y) == (1.5 + 3 + 4, 1.5)


def test_friedman_matches_the_rank_formula():
    samples = np.array([[1.0, 2.0, 3.0, 4.0, 2.5], [2.0, 3.0, 1.0, 5.0, 3.5], [3.0, 4.0, 2.0, 6.0, 0.5]])
    ranks = stats.rankdata(samples, axis=0)
    n, k = samples.shape[1], samples.shape[0]
    chi_square = 12 / (n * k * (k + 1)) * np.sum(ranks.sum(axis=1) ** 2) - 3 * n * (k + 1)
    result = friedman(samples)
    assert result.chi_square == pytest.approx(chi_square)
    assert result.p_value == pytest.approx(stats.chi2.sf(chi_square, k - 1))


def test_statistics_refuse_what_they_cannot_rank():
    with pytest.raises(ValueError, match="finite"):
        friedman([[1.0, np.nan], [2.0, 3.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="at least 3"):
        friedman([[1.0, 2.0], [2.0, 3.0]])
    with pytest.raises(ValueError, match="equal in every pair"):
        wilcoxon([1.0, 2.0], [1.0, 2.0])


@pytest.fixture(scope="module")
def small_study():
    return run_study(StudySettings(targets=30, fs_levels=9, user_levels=7), seed=4)


def test_study_renders_every_target_for_each_fingertip_and_method(small_study):
    assert small_study.target_wrenches.shape == (30, 6)
    assert np.all(small_study.target_magnitudes >= 5 / 320)
    for outcome in small_study.fingertips:
        assert outcome.errors.shape == (len(METHODS), 30) and np.all(np.isfinite(outcome.errors))
        assert outcome.friedman.methods == 3 and len(outcome.post_hoc) == 3
        assert all(test.tests == 3 * 6 + 1 for test in outcome.post_hoc)
    assert len(small_study.summary_rows()) == 6 * len(METHODS)


def test_standard_method_is_best_on_the_fs_cast_and_degrades_with_size(small_study):
    median = {o.fingertip.name: np.median(o.errors, axis=1) for o in small_study.fingertips}
    fs_cast, large, human_3 = median["FS cast (7.5 mm)"], median["large cast (8.5 mm)"], median["human 3 (10 mm)"]
    assert fs_cast[0] < large[0] < human_3[0]
    # on the FS cast the geometric table is the FS table itself (r_U = r_F), so their errors differ only by noise
    assert abs(fs_cast[2] - fs_cast[0]) < 0.05
    # both personalisations beat the standard table on the largest fingertip
    assert human_3[1] < human_3[0] and human_3[2] < human_3[0]


def test_study_gives_real_collection_times_and_figures(small_study):
    # 9^3 configurations held 1 s each, plus the servos' travels between them
    assert 9**3 < small_study.fs_collection_s < 9**3 * 1.5
    figure = small_study.figures()[0]
    assert isinstance(figure, Figure) and len(figure.axes) == 6


def test_study_refuses_targets_it_cannot_find():
    with pytest.raises(ValueError, match="study.target_draws = 3"):
        run_study(StudySettings(targets=10, fs_levels=3, user_levels=2, target_draws=3), seed=0)
    with pytest.raises(ValueError, match="study.fs_levels = 1"):
        StudySettings(fs_levels=1)
    with pytest.raises(ValueError, match="seed = -1: expected an integer >= 0"):
        run_study(StudySettings(), seed=-1)
