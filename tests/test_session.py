"""A saved model carried over to a new session: gains re-fitted from a few presses.

References: gains put into a known linear sensor by hand (recovered to round-off from one press); a
press count worked out by hand; the real eFlesh recordings (MIT licence, V. Pattabiraman et al.,
"eFlesh: Highly customizable Magnetic Touch Sensing using Cut-Cell Microstructures",
arXiv:2506.09994; examples/data/eflesh-normal), their scale's force as the truth, each recording a
session.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.calibration import PolynomialFit, load_model, save_model
from softtip.calibration.session import SessionAffine, SessionGains, gain_groups, press_ends, session_curve
from softtip.cli.main import app
from softtip.data import DatasetMetadata, TrialWriter, channel_columns, channel_names

EFLESH = Path(__file__).parents[1] / "examples" / "data" / "eflesh-normal"
RECORDINGS = ("20250401_014340_probe", "20250401_015037_probe", "20250401_015717_probe")
CHIPS = 5
GRAM_FORCE_N = 9.80665e-3
JOIN_TOLERANCE_S = 0.05  # the two logs' rows are some 35 ms apart: the nearest scale row within this
REST_ROWS = 20  # the recordings start at rest: their mean is the session's zero


def test_press_ends_by_hand():
    load = np.array([0, 1, 5, 6, 1, 0, 7, 8, 9, 9, 0, 6])
    trials = np.array([0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1])
    # Runs above 2: rows 2-3, rows 6-7 (trial 0 ends), rows 8-9 (trial 1), row 11 (to the end).
    np.testing.assert_array_equal(press_ends(load, trials, 2.0), [4, 8, 10, 12])


def test_gains_put_into_a_known_sensor_are_recovered_from_four_presses():
    rng = np.random.default_rng(3)
    weights = rng.normal(0, 0.02, 12)
    model = PolynomialFit(1).fit(X := rng.normal(0, 80, (300, 12)), X @ weights)
    channels = channel_names(4)
    groups = gain_groups(channels)
    np.testing.assert_array_equal(groups, np.repeat(np.arange(4), 3))
    chip_gains = np.array([0.5, 2.0, 1.3, 0.8])  # the model reads each chip this much stronger than the new session
    force = np.r_[np.zeros(5), np.linspace(0, 3, 40), np.linspace(3, 0, 40), np.zeros(5)]
    # A linear sensor with one output: a press along one direction of the readings fixes one
    # combination of the gains, so four gains take four presses along different directions.
    directions = rng.normal(0, 60, (4, 12))
    session = np.concatenate([force[:, None] * d / chip_gains[groups] for d in directions])
    truth = np.concatenate([force * (d @ weights) for d in directions])
    fitted = SessionGains(model, groups).fit(session, truth)
    np.testing.assert_allclose(fitted.group_gains_, chip_gains, rtol=1e-6)
    assert fitted.cost_ < 1e-12 and not len(fitted.at_bound_)
    np.testing.assert_allclose(fitted.predict(session), truth, atol=1e-6)
    np.testing.assert_allclose(fitted.corrected_model().predict(session), truth, atol=1e-6)



def test_an_affine_map_put_into_a_known_sensor_is_recovered_and_alpha_holds_it_to_the_identity():
    rng = np.random.default_rng(4)
    channels = channel_names(2)
    weights = rng.normal(0, 0.02, (6, 6))  # a linear sensor of two chips, as many outputs as inputs: invertible
    model = PolynomialFit(1).fit(X := rng.normal(0, 80, (300, 6)), X @ weights)
    groups = gain_groups(channels)
    # the new session reads each chip through a matrix and an offset the model does not know
    maps = [np.eye(3) + rng.normal(0, 0.2, (3, 3)) for _ in range(2)]
    offsets = rng.normal(0, 10, 6)
    session = rng.normal(0, 80, (60, 6))
    truth = np.column_stack([session[:, :3] @ maps[0].T, session[:, 3:] @ maps[1].T]) + offsets
    truth = truth @ weights
    fitted = SessionAffine(model, groups, alpha=1e-12).fit(session, truth)
    for found, made in zip(fitted.matrices_, maps, strict=True):
        np.testing.assert_allclose(found, made, atol=1e-6)
    np.testing.assert_allclose(fitted.offsets_, offsets, atol=1e-4)
    np.testing.assert_allclose(fitted.predict(session), truth, atol=1e-6)
    held = SessionAffine(model, groups, alpha=1e8).fit(session, truth)  # the penalty outweighs the data
    np.testing.assert_allclose(held.map_, np.eye(6), atol=1e-3)
    np.testing.assert_allclose(held.offsets_, 0, atol=1e-3 * np.sqrt(np.mean(session**2)))
    with pytest.raises(ValueError, match="alpha = 0"):
        SessionAffine(model, groups, alpha=0).fit(session, truth)

def eflesh_session(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times s, changes (rows, chips, 3) µT, force N) of one recording: every magnetometer row with a
    scale reading within the tolerance, the scale's -1 rows ("no reading") left out."""
    sensor = np.loadtxt(EFLESH / name / "sensor.csv", delimiter=",")
    states = np.loadtxt(EFLESH / name / "states.csv", delimiter=",")
    states = states[states[:, 4] != -1]
    after = np.searchsorted(states[:, 0], sensor[:, 0]).clip(1, len(states) - 1)
    nearest = np.where(sensor[:, 0] - states[after - 1, 0] < states[after, 0] - sensor[:, 0], after - 1, after)
    joined = np.abs(states[nearest, 0] - sensor[:, 0]) <= JOIN_TOLERANCE_S
    field = sensor[joined, 1:].reshape(-1, CHIPS, 3)
    return sensor[joined, 0] - sensor[0, 0], field - field[:REST_ROWS].mean(axis=0), states[nearest[joined], 4] * GRAM_FORCE_N


def write_session(path: Path, name: str, role: str) -> Path:
    times, changes, force = eflesh_session(name)
    writer = TrialWriter(CHIPS, labels={"fz_N": "N"}, conditions={"role": "1"}, metadata=DatasetMetadata(seed=0))
    writer.add({"time_s": times, **channel_columns(changes), "fz_N": force}, {"role": role})
    writer.write(path)
    return path


@pytest.fixture(scope="module")
def eflesh(tmp_path_factory):
    folder = tmp_path_factory.mktemp("eflesh")
    return {name: write_session(folder / f"{name}.parquet", name, "calibration") for name in RECORDINGS}


# Measured (polynomial of degree 3, gains per chip): the model of the second recording on the first,
# scored on the first's last five presses: 2.09 N as it is, 0.75 N after its first five presses. Two
# chips' gains reach the lower bound (their response changed by more than a gain): the command warns.
@pytest.mark.parametrize("trained, new, before, after", [(1, 0, 2.09, 0.75)])
def test_the_cli_recalibrates_a_real_session_from_five_presses(tmp_path, eflesh, trained, new, before, after):
    runner = CliRunner()
    model = tmp_path / "model.npz"
    made = runner.invoke(app, ["calibrate", str(eflesh[RECORDINGS[trained]]), "-t", "fz_N", "--model", "polynomial",
                               "-o", str(model), "--json"])
    assert made.exit_code == 0, made.output
    corrected, plot = tmp_path / "session.npz", tmp_path / "session.png"
    result = runner.invoke(app, ["recalibrate", str(model), str(eflesh[RECORDINGS[new]]), "--presses", "5",
                                 "--press-above", "0.5", "-o", str(corrected), "--plot", str(plot), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    rmse = [row["rmse"][0] for row in summary["rmse_by_presses"]]
    assert summary["presses_found"] == 10 and len(rmse) == 6
    assert rmse[0] == pytest.approx(before, abs=0.01) and rmse[5] == pytest.approx(after, abs=0.01)
    assert rmse[5] < summary["zero_rmse"][0] / 20  # the scored presses reach some 34 N
    assert "gain group(s) [2, 3] reached the bound" in result.stderr
    # The saved model is the corrected one: it scores the same on the scored rows.
    estimator, meta = load_model(corrected)
    times, changes, force = eflesh_session(RECORDINGS[new])
    scored = slice(int(np.flatnonzero(np.diff((force > 0.5).astype(int)) == -1)[4]) + 1, None)
    error = estimator.predict(changes.reshape(len(force), -1)[scored]) - force[scored]
    assert np.sqrt(np.mean(error**2)) == pytest.approx(rmse[5], rel=1e-9)
    assert meta.extra["session"]["presses"] == 5 and plot.stat().st_size > 10_000



@pytest.mark.slow
def test_the_cli_recalibrates_a_network_as_it_does_the_polynomial(tmp_path, eflesh):
    runner = CliRunner()
    curves = {}
    for kind in ("network", "polynomial"):
        model = tmp_path / f"{kind}.npz"
        made = runner.invoke(app, ["calibrate", str(eflesh[RECORDINGS[1]]), "-t", "fz_N", "--model", kind,
                                   "-o", str(model), "--json"])
        assert made.exit_code == 0, made.output
        result = runner.invoke(app, ["recalibrate", str(model), str(eflesh[RECORDINGS[0]]), "--presses", "5",
                                     "--press-above", "0.5", "-o", str(tmp_path / f"{kind}-session.npz"), "--json"])
        assert result.exit_code == 0, result.output
        summary = json.loads(result.stdout)
        curves[kind] = np.array([row["rmse"][0] for row in summary["rmse_by_presses"]])
    network, polynomial = curves["network"], curves["polynomial"]
    # measured (1 -> 0, network seed 0): 2.02 N as it is, 0.76 N after five presses; the polynomial 2.09 and
    # 0.75 N. The gains fitted through the network correct it as they do the polynomial: to within 10 %.
    assert network[5] < 0.6 * network[0] and network[5] < summary["zero_rmse"][0] / 20
    assert abs(network[5] - polynomial[5]) < 0.1 * polynomial[5]
    # the saved network carries its gains: it scores the same on the scored rows
    estimator, meta = load_model(tmp_path / "network-session.npz")
    times, changes, force = eflesh_session(RECORDINGS[0])
    scored = slice(int(np.flatnonzero(np.diff((force > 0.5).astype(int)) == -1)[4]) + 1, None)
    error = estimator.predict(changes.reshape(len(force), -1)[scored]) - force[scored]
    assert np.sqrt(np.mean(error**2)) == pytest.approx(network[5], rel=1e-9)

def test_too_few_presses_is_one_line(tmp_path, eflesh):
    model = tmp_path / "model.npz"
    rng = np.random.default_rng(0)
    X = rng.normal(0, 100, (50, 15))
    save_model(model, PolynomialFit(1).fit(X, X[:, 2] * 0.01), input_channels=channel_names(CHIPS),
               input_units="uT", target_names=["fz_N"], target_units="N")
    result = CliRunner().invoke(app, ["recalibrate", str(model), str(eflesh[RECORDINGS[0]]), "--presses", "12"])
    assert result.exit_code == 2 and "has 10 presses above 3.4" in result.output
    assert len(result.output.strip().splitlines()) == 1
