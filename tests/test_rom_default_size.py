"""The reduced twin of the default size meets its 2 % of full scale. A file of its own: the longest
single test, it starts first on one worker while the other workers take the other files, those of
test_rom.py among them, instead of waiting behind it."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.design.model import load_design
from softtip.twin.reduced import IndenterFamily, ReducedTwin


@pytest.mark.slow
def test_a_twin_of_the_default_size_is_within_two_percent_of_full_scale():
    # the README's reduced twin, as `softtip bench rom` builds it: cylindrical-D, a board, sticking,
    # 8,000 samples, two 128-128 networks; its held-out errors on FE and on exact solves
    twin = ReducedTwin.build(load_design("cylindrical-D"), IndenterFamily(friction="stick"))
    for name in ("holdout", "exact_holdout"):
        report = twin.report[name]
        assert np.max(report["sensor_error_percent_fs"]) < 2.0, name
        assert np.max(report["magnet_displacement_error_percent_range"]) < 2.0, name
