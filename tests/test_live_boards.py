"""Boards other than softtip's firmware in ``softtip live``: a ReSkin / AnySkin board emulated on a
pseudo-terminal, streamed by the command line through the baseline, a saved model and the MCAP
recorder.

References: the board's own field, a known rest field plus a known press times known gains, written
in float32 as the boards send it; the force a hand-made linear model gives for that press.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.calibration import PolynomialFit, save_model
from softtip.cli.main import app
from softtip.data import channel_names
from softtip.hardware import ReSkinBoard
from softtip.realtime import convert

CHIPS = 5
RATE_HZ = 100.0
REST_S = 1.5  # the board rests this long after it starts, then is pressed
RNG = np.random.default_rng(11)
REST_UT = RNG.uniform(-400, 400, (CHIPS, 3))
GAINS_UT_PER_N = RNG.uniform(-60, 60, (CHIPS, 3))
WEIGHTS = RNG.normal(0, 0.01, CHIPS * 3)  # the model: force = WEIGHTS . change


def press_N(t_s: float) -> float:
    return 0.0 if t_s < REST_S else 2.0 * max(0.0, np.sin(2 * np.pi * (t_s - REST_S) / 0.8))


def board_field(t_s: float) -> np.ndarray:
    return REST_UT + press_N(t_s) * GAINS_UT_PER_N


@pytest.fixture
def linear_model(tmp_path):
    X = np.random.default_rng(2).normal(0, 100, (400, CHIPS * 3))
    model = PolynomialFit(1).fit(X, X @ WEIGHTS)
    return save_model(tmp_path / "force.npz", model, input_channels=channel_names(CHIPS), input_units="uT",
                      target_names=["fz_N"], target_units="N")


@pytest.mark.realtime
def test_an_anyskin_board_streams_through_the_baseline_a_model_and_the_recording(tmp_path, linear_model):
    recording = tmp_path / "board.mcap"
    with ReSkinBoard(board_field, RATE_HZ, CHIPS) as board:
        result = CliRunner().invoke(app, ["live", "--port", board.port, "--driver", "anyskin", "--model",
                                          str(linear_model), "--baseline-frames", "20", "--record", str(recording),
                                          "--duration", "3", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["chips"] == CHIPS and summary["rate_hz"] is None and summary["resyncs"] == 0
    assert summary["delivered"] == summary["frames"] > 150 and summary["sink_errors"] == 0

    dataset = convert(recording).dataset
    assert dataset.channels == tuple(channel_names(CHIPS))
    changes, force = dataset.X(), dataset.y(["fz_N"]).ravel()
    estimated = np.isfinite(force)
    assert np.count_nonzero(~estimated) == 20  # the frames of the first baseline
    # Every change is the press times the gains: the records were framed right and the baseline is
    # the rest field (both in float32, as sent).
    gains = GAINS_UT_PER_N.ravel()
    press = changes[estimated] @ gains / (gains @ gains)
    float32_step = np.spacing(np.float32(np.abs(REST_UT).max() + 2 * np.abs(GAINS_UT_PER_N).max()))
    assert np.abs(changes[estimated] - press[:, None] * gains).max() <= 4 * float32_step
    assert press.min() > -1e-5 and press.max() > 1.5  # rest, and presses up to nearly the 2 N peak
    np.testing.assert_allclose(force[estimated], press * (WEIGHTS @ gains), atol=1e-5)


def test_a_board_driver_refuses_what_it_cannot_do(tmp_path):
    runner = CliRunner()
    for args, named in ((["--emulate", "--driver", "anyskin"], "--driver anyskin"),
                        (["--port", str(tmp_path / "tty"), "--driver", "reskin", "--rate", "100"], "--rate = 100"),
                        (["--port", str(tmp_path / "tty"), "--format", "anyskin", "--duration", "1"], "cannot open"),
                        (["--port", str(tmp_path / "tty"), "--driver", "usb-hid"],
                         "driver 'usb-hid': expected one of softtip, reskin, anyskin")):
        result = runner.invoke(app, ["live", *args])
        assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output
        assert named in result.output
