"""The pushing test's rotary stage: where the board passes the fingertip, and the signature of Sx and Sy
over the board's angle that the report compares with the published bench's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from softtip.data import DatasetMetadata, TrialWriter, channel_columns
from softtip.systems.hall_fingertip.experiments import stage_position
from softtip.systems.hall_fingertip.realism import Realism
from softtip.systems.hall_fingertip.studies import _stage_signature


def test_a_board_on_an_offset_stage_passes_the_fingertip_where_the_geometry_says():
    realism = Realism(stage_axis_offset_mm=1.0, board_edge_offset_mm=0.8)
    # board along x: its mid-plane 0.8 mm towards +y from the stage's axis at (1, 0) mm
    assert stage_position(realism, 0.0) == pytest.approx([1.0e-3, 0.8e-3])
    # board along y: across it is -x, so 0.8 mm back towards the fingertip's axis
    assert stage_position(realism, 90.0) == pytest.approx([0.2e-3, 0.0], abs=1e-12)
    # the mid-plane's distance from the fingertip's axis, by hand: |o . n + e| = |-sin(a) * 1.0 + 0.8| mm
    for angle in (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0):
        across = np.array([-math.sin(math.radians(angle)), math.cos(math.radians(angle))])
        assert stage_position(realism, angle) @ across == pytest.approx(
            (0.8 - math.sin(math.radians(angle))) * 1e-3, abs=1e-12)
    # a bench on the fingertip's axis with a centred board: the board through the axis at every angle
    assert stage_position(Realism(stage_axis_offset_mm=0.0, board_edge_offset_mm=0.0), 30.0) == pytest.approx([0, 0])


def _pushes(sx_of_angle, sy_of_angle) -> TrialWriter:
    """Two pushes per angle, 3 mm deep, whose deepest readings are the given functions of the angle."""
    writer = TrialWriter(1, labels={"angle_deg": "deg", "depth_mm": "mm"}, conditions={"role": "1"},
                         metadata=DatasetMetadata(description="stage signature"))
    depth = np.array([0.0, 1.0, 3.0, 2.0])
    for angle in np.arange(0.0, 91.0, 15.0):
        for repeat in range(2):
            deepest = np.array([sx_of_angle(angle) + repeat, sy_of_angle(angle), -4000.0])
            readings = (depth / 3.0)[:, None, None] * deepest[None, None, :]
            writer.add({"time_s": np.arange(4.0), **channel_columns(readings), "angle_deg": np.full(4, angle),
                        "depth_mm": depth}, {"role": "calibration"})
    return writer


def test_the_stage_signature_reads_the_deepest_readings_over_the_angles():
    dataset = _pushes(lambda a: 2e-4 * a ** 3 - 0.03 * a ** 2 + 5.0 * a, lambda a: 0.0).to_dataset()
    signature = _stage_signature(dataset)
    means = [2e-4 * a ** 3 - 0.03 * a ** 2 + 5.0 * a + 0.5 for a in np.arange(0.0, 91.0, 15.0)]
    assert signature["sx_swing_uT"] == pytest.approx(max(means) - min(means))
    # a cubic in the angle plus the repeats' 1 µT split: R² = 1 - 0.25 / variance, by hand
    sx = np.array([[m - 0.5, m + 0.5] for m in means]).ravel()
    assert signature["sx_cubic_r2"] == pytest.approx(1 - 0.25 / np.var(sx), rel=1e-9)
    assert signature["sy_swing_uT"] == 0.0
