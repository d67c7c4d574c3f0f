"""Re-zeroing the live baseline: at rest by the stated rule, and by a key on the dashboard.

References: the rest rule worked out by hand on frames at an exactly representable period (which
frame re-zeroes, and the mean of which frames becomes the baseline, computed with numpy); a terminal
emulated on a pseudo-terminal; a board whose offsets step by a known amount mid-stream.
"""

from __future__ import annotations

import io
import json
import os
import termios
import threading
import time

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.hardware import ReSkinBoard
from softtip.realtime import Baseline, DashboardSink, Estimator, Pipeline, StreamInfo, convert

DT_S = 1 / 64  # exact in binary: the rest period's length is summed without rounding
CHIPS = 2
HANG_GUARD_S = 30.0


def frames(rng, rest_uT, count, noise_uT=0.3):
    return rest_uT + rng.normal(0, noise_uT, (count, CHIPS, 3))


def test_rest_rezeroes_to_the_mean_of_the_still_frames_and_never_absorbs_a_held_press():
    rng = np.random.default_rng(5)
    rest = rng.uniform(-300, 300, (CHIPS, 3))
    offset = np.array([[8.0, -6.0, 5.0], [-3.0, 7.0, 9.0]])  # a temperature step: below the 20 µT threshold
    held_press = rest + offset + np.array([[0.0, 0.0, 150.0], [0.0, 40.0, 0.0]])
    stream = np.concatenate([frames(rng, rest, 10),  # the first baseline
                             frames(rng, rest + offset, 100),  # rests after the offsets moved
                             frames(rng, held_press, 200),  # a press held still, for longer than the rest
                             frames(rng, rest + offset, 30)])  # released, rests for less than the rest
    baseline = Baseline(10, rest_s=1.0, rest_band=3.0)
    changed_at = [k for k, reading in enumerate(stream) if baseline.update(reading, True, DT_S, True)]
    # The first baseline at frame 9; the rest period starts with the first frame at the new offsets
    # (10) and is 1 s long 64 frames later: the mean of frames 10..74 becomes the baseline.
    assert changed_at == [9, 74]
    np.testing.assert_allclose(baseline.value, stream[10:75].mean(axis=0), rtol=1e-13)
    # The rest goes on for 35 frames only before the press, which is held still for 200 frames but
    # is beyond the threshold; after it the stream ends before a whole second of rest.
    assert baseline.rezeroed_at_rest == 1 and baseline.taken == 2 and baseline.version == 2


def test_a_faulty_frame_or_a_contact_state_restarts_the_rest_period():
    rng = np.random.default_rng(6)
    rest = rng.uniform(-300, 300, (CHIPS, 3))
    stream = np.concatenate([frames(rng, rest, 10), frames(rng, rest + 5.0, 120)])
    baseline = Baseline(10, rest_s=1.0, rest_band=3.0)
    changed_at = [k for k, reading in enumerate(stream)
                  if baseline.update(reading, k != 40, DT_S, free=k != 80)]
    # Periods: 10..39 (cut by the faulty 40), 41..79 (cut by the contact at 80), 81..145: past the end.
    assert changed_at == [9] and baseline.rezeroed_at_rest == 0
    baseline = Baseline(10, rest_s=1.0, rest_band=3.0)
    changed_at = [k for k, reading in enumerate(stream) if baseline.update(reading, k != 40, DT_S, True)]
    assert changed_at == [9, 41 + 64]
    np.testing.assert_allclose(baseline.value, stream[41:106].mean(axis=0), rtol=1e-13)


def test_the_dashboard_rezeroes_on_its_key_and_gives_the_terminal_back():
    requests = []
    stream = StreamInfo(chips=1, target_names=(), target_units=(), classes=None, settings=None, rate_hz=50.0,
                        take_baseline=lambda: requests.append(time.monotonic()))
    master, slave = os.openpty()
    try:
        mode = termios.tcgetattr(slave)
        console = Console(file=io.StringIO(), width=120, color_system=None)
        dashboard = DashboardSink(console, keys=slave)
        dashboard.open(stream)
        assert not termios.tcgetattr(slave)[3] & termios.ICANON  # keys arrive one at a time
        os.write(master, b"xZz")
        deadline = time.monotonic() + HANG_GUARD_S
        while len(requests) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        console.print(dashboard.render())
        dashboard.close()
        assert len(requests) == 2 and dashboard.rezero_requests == 2
        assert termios.tcgetattr(slave) == mode
        assert "z: re-zero" in console.file.getvalue()
    finally:
        os.close(master)
        os.close(slave)


STEP_S = 2.0  # the board's offsets step by OFFSET_UT at this time (a warmer room, a magnet that settled)
OFFSET_UT = np.array([[6.0, -4.0, 9.0]] * 5)


def stepping_field(t_s: float) -> np.ndarray:
    return np.full((5, 3), 120.0) + (OFFSET_UT if t_s >= STEP_S else 0.0)


@pytest.mark.realtime
@pytest.mark.parametrize("rezero", [False, True])
def test_live_rezero_at_rest_takes_out_an_offset_step(tmp_path, rezero):
    recording = tmp_path / "board.mcap"
    with ReSkinBoard(stepping_field, 100.0) as board:
        args = ["live", "--port", board.port, "--format", "anyskin", "--baseline-frames", "20",
                "--record", str(recording), "--duration", "4", "--json"]
        result = CliRunner().invoke(app, args + (["--rezero-at-rest", "0.5", "--rest-band", "5"] if rezero else []))
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    changes = convert(recording).dataset.X()
    last = changes[-20:]
    if rezero:
        # The rest is exact (nothing to re-zero before the step) and the 9 µT step is beyond the
        # 5 µT band, so no rest period spans it: one re-zero, at the new offsets.
        assert summary["baseline_rezeroed_at_rest"] == 1
        np.testing.assert_array_equal(last, 0.0)
    else:
        assert summary["baseline_rezeroed_at_rest"] == 0
        np.testing.assert_allclose(last, np.broadcast_to(OFFSET_UT.ravel(), last.shape))


def test_rest_options_are_checked():
    result = CliRunner().invoke(app, ["live", "--emulate", "--rest-band", "5"])
    assert result.exit_code == 2 and "--rest-band = 5: only with --rezero-at-rest" in result.output


class PressedAbove50:
    """A contact-state classifier on one input: 'pressed' above 50 µT, else 'free'."""

    classes_ = np.array(["free", "pressed"])

    def predict(self, X):
        return np.where(np.asarray(X)[:, 0] > 50.0, "pressed", "free")


def test_rezeroing_at_rest_with_a_contact_state_classifier_needs_its_free_states_named():
    state = Estimator(PressedAbove50(), ["s0_bz_uT"], name="state")
    with pytest.raises(ValueError, match="re-zeroing at rest with a contact-state classifier"):
        Pipeline(CHIPS, [state], baseline=Baseline(5, rest_s=1.0))
    Pipeline(CHIPS, [state], baseline=Baseline(5, rest_s=1.0), free_states=["free"])
