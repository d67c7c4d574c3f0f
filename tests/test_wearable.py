"""The wearable protocol (S2) on its twin: the dataset it writes against the protocol's specification
(counts, durations, rates, which axis each trial loads), its reproducibility, the ring's re-seating,
its refusals, and whether the side sensor's readings carry the table force at all (least squares)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from softtip._core.config import ConfigError
from softtip.data import Dataset
from softtip._core.systems import load, owner
from softtip.lab import load_protocol, protocol_from_dict, run_protocol
from softtip.systems.wearable.human_force import MOTIONS
from softtip.systems.wearable.realism import WearableRealism

FORCES = ["fx_N", "fy_N", "fz_N"]


def run(seed: int = 1, realism: WearableRealism | None = None, **parameters) -> Dataset:
    protocol = load_protocol("wearable").changed(seed=seed, **parameters)
    if realism is not None:
        protocol = dataclasses.replace(protocol, realism=realism)
    return run_protocol(protocol)[0]


@pytest.fixture(scope="module")
def shipped() -> Dataset:
    return run()


def trials_of(dataset: Dataset, motion: str) -> list[Dataset]:
    kinds = dataset.trial_conditions["motion"]
    return [dataset.select(trials=[trial]) for trial, kind in zip(dataset.trials, kinds) if kind == motion]


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def test_the_protocol_writes_three_participants_three_runs_seven_trials_of_15_s_at_10_hz(shipped, tmp_path):
    assert len(shipped.trials) == 3 * 3 * 7
    conditions = shipped.trial_conditions
    assert sorted(set(conditions["participant"])) == [0, 1, 2] and sorted(set(conditions["run"])) == [0, 1, 2]
    for participant in range(3):
        for run_ in range(3):
            mine = (conditions["participant"] == participant) & (conditions["run"] == run_)
            assert sorted(conditions["motion"][mine]) == sorted(MOTIONS)
    assert set(conditions["contact"]) == {"flat"}
    assert (shipped.trial_lengths == 150).all()
    for trial in shipped.trials[:3]:
        np.testing.assert_allclose(shipped.select(trials=[trial]).column("time_s"), np.arange(150) / 10.0)
    assert shipped.channel_units == {"side_fx_N": "N", "side_fy_N": "N", "side_fz_N": "N"}
    assert {name: shipped.labels[name] for name in FORCES} == dict.fromkeys(FORCES, "N")
    assert shipped.labels["cop_x_mm"] == "mm" and shipped.metadata.seed == 1
    assert shipped.metadata.design["name"] == "nail-ring-radial"
    back = Dataset.read(shipped.write(tmp_path / "wearable.parquet"))
    for name, values in shipped.columns.items():
        np.testing.assert_array_equal(back.columns[name], values)


def test_each_trial_loads_its_own_axis_with_a_normal_force_while_shearing(shipped):
    axis = {"palmar": (2, 1), "dorsal": (2, -1), "radial": (0, 1), "ulnar": (0, -1), "distal": (1, 1),
            "proximal": (1, -1)}
    for motion, (main, sign) in axis.items():
        for trial in trials_of(shipped, motion):
            force = trial.y(FORCES)
            others = [k for k in (0, 1) if k != main]  # the other tangential axes
            assert sign * force[:, main].mean() > 0, motion
            assert all(rms(force[:, main]) > 2.5 * rms(force[:, k]) for k in others), motion
            if main < 2:  # shearing: the pad presses on the table the whole time it pushes sideways
                absolute = force[:, 2] + trial.trial_conditions["table_tare_fz_N"][0]
                pushing = np.abs(force[:, main]) > 0.2
                assert pushing.any() and (absolute[pushing] > 0.5).all(), motion
    for trial in trials_of(shipped, "combined"):
        force = trial.y(FORCES)
        assert min(rms(force[:, 0]), rms(force[:, 1])) > 0.1 and rms(force[:, 2]) > 0.5


def test_the_dorsal_trial_unloads_a_held_press_down_to_lift_off(shipped):
    lifted = 0
    for trial in trials_of(shipped, "dorsal"):
        tare = trial.trial_conditions["table_tare_fz_N"][0]
        fz = trial.column("fz_N")
        assert tare > 1.5 and fz.min() > -tare - 0.02  # the table is never pulled
        off = fz < -tare + 0.02
        lifted += off.sum()
        assert np.isnan(trial.column("cop_x_mm")[off & (fz < -tare + 0.005)]).all()
    assert lifted > 0


def test_some_tilts_reach_the_friction_limit_and_slide(shipped):
    sliding = {motion: sum(trial.column("sliding").sum() for trial in trials_of(shipped, motion))
               for motion in ("radial", "ulnar", "distal", "proximal", "palmar")}
    assert sum(sliding[m] for m in ("radial", "ulnar", "distal", "proximal")) > 0 and sliding["palmar"] == 0


def test_the_same_seed_repeats_the_dataset_and_each_run_reseats_the_ring(shipped):
    again = run()
    for name, values in shipped.columns.items():
        np.testing.assert_array_equal(again.columns[name], values)
    other = run(seed=2)
    assert not np.array_equal(other.column("side_fz_N"), shipped.column("side_fz_N"))
    conditions = shipped.trial_conditions
    for participant in range(3):
        offsets = []
        for run_ in range(3):
            mine = (conditions["participant"] == participant) & (conditions["run"] == run_)
            in_air = conditions["side_air_fz_N"][mine]
            assert (in_air == in_air[0]).all()  # one seating per run
            offsets.append(in_air[0])
        assert len(set(offsets)) == 3  # re-seated: another preload every run
    # the clamp is the only thing that reads in the air: without re-seating scatter nor noise, it is the preload
    steady = run(realism=dataclasses.replace(WearableRealism(), noise=False, ring_preload_sd=0.0), participants=1,
                 runs=2, motions=["palmar"])
    assert set(steady.trial_conditions["side_air_fz_N"]) == {0.5}


def test_a_point_contact_bulges_less_than_a_flat_one_for_the_same_force():
    dataset = run(realism=WearableRealism.off(), participants=1, runs=1, motions=["palmar"],
                  contacts=["flat", "point"])
    slopes = {}
    for trial in dataset.trials:
        one = dataset.select(trials=[trial])
        slopes[one.trial_conditions["contact"][0]] = np.polyfit(one.column("fz_N"), one.column("side_fz_N"), 1)[0]
        cop = np.column_stack([one.column("cop_x_mm"), one.column("cop_y_mm")])
        assert np.abs(cop).max() < 1.0  # no tangential load, no placement scatter: at the nominal point
    assert 0 < slopes["point"] < 0.6 * slopes["flat"]


def r_squared(dataset: Dataset, participant: int) -> np.ndarray:
    """R² of the linear least-squares map (with offset) from the chip's three readings to the table's
    three forces, on one participant's trials."""
    rows = dataset.column("participant") == participant
    inputs = np.column_stack([dataset.X()[rows], np.ones(rows.sum())])
    forces = dataset.y(FORCES)[rows]
    fitted = inputs @ np.linalg.lstsq(inputs, forces, rcond=None)[0]
    return 1 - ((forces - fitted) ** 2).sum(axis=0) / ((forces - forces.mean(axis=0)) ** 2).sum(axis=0)


def test_the_side_sensor_carries_every_axis_of_the_table_force(shipped):
    # the physics alone (exact sensors, one posture, one seating): every axis is clearly identifiable
    ideal = run(realism=WearableRealism.off())
    assert (r_squared(ideal, 0) > 0.5).all()
    # with people and re-seating, shear along the finger (y) and the normal force stay identifiable
    # by a linear map; radial/ulnar shear (x) does not: a lateral force moves the displaced volume
    # sideways just as placing the finger a millimetre off does (see the README, S2)
    realistic = r_squared(shipped, 0)
    assert realistic[1] > 0.5 and realistic[2] > 0.5


def test_switching_the_placement_scatter_off_keeps_every_other_draw_and_shows_where_x_is_lost(shipped):
    centred = run(realism=dataclasses.replace(WearableRealism(), placement_sd_mm=0.0))
    # the same people, seatings and presses: the table reads what it read, the runs' preloads are identical
    conditions, again = shipped.trial_conditions, centred.trial_conditions
    np.testing.assert_array_equal(again["side_air_fz_N"], conditions["side_air_fz_N"])
    for force in FORCES:
        np.testing.assert_array_equal(centred.column(force), shipped.column(force))
    # a linear map from the chip to Fx, in sample: measured 0.18 with the 1 mm placement scatter, 0.73 without
    assert r_squared(shipped, 0)[0] < 0.2 and r_squared(centred, 0)[0] > 0.7


def test_the_last_joint_carries_radial_force_to_the_chip_past_the_placement(shipped):
    # the same people, seatings and presses with a rigid last joint: a linear map from the chip keeps 0.05 of Fx's
    # variance (0.18 with the joint), and y and z as much as with it
    rigid = run(dip_joint=False)
    for force in FORCES:
        np.testing.assert_array_equal(rigid.column(force), shipped.column(force))
    with_joint, without = r_squared(shipped, 0), r_squared(rigid, 0)
    assert without[0] < 0.06 and with_joint[0] > 0.17
    np.testing.assert_allclose(with_joint[1:], without[1:], atol=0.005)


@pytest.mark.parametrize("change, message", [
    ({"parameters": {"participants": 0}}, r"parameters.participants = 0: expected a positive integer"),
    ({"parameters": {"motions": ["palmar", "jumping"]}}, r"parameters.motions"),
    ({"parameters": {"motions": ["palmar", "palmar"]}}, r"parameters.motions = \['palmar', 'palmar'\]: expected each"),
    ({"parameters": {"contacts": []}}, r"parameters.contacts = \[\]: expected a non-empty list of: flat"),
    ({"parameters": {"sensor_side": "left"}}, r"parameters.sensor_side = 'left': expected one of radial, ulnar"),
    ({"parameters": {"simulation_rate_hz": 15.0}}, r"parameters.simulation_rate_hz = 15.0: expected at least twice"),
    ({"parameters": {"trial_s": 4.0}}, r"parameters.trial_s = 4.0: expected at least 5 s"),
    ({"parameters": {"rate_hz": 0.1}}, r"parameters.trial_s: expected at least two samples at rate_hz = 0.1"),
    ({"parameters": {"rate": 10.0}}, r"parameters.rate: unknown key"),
    ({"parameters": {"lateral_drag": 1}}, r"parameters.lateral_drag = 1: expected true or false"),
    ({"parameters": {"dip_joint": "no"}}, r"parameters.dip_joint = 'no': expected true or false"),
    ({"parameters": {"dip_lateral_stiffness_Nm_per_rad": 0.0}},
     r"parameters.dip_lateral_stiffness_Nm_per_rad = 0.0: expected a positive number"),
    ({"realism": {"noise": 1}}, r"realism.noise = 1: expected true or false"),
    ({"realism": {"magnetisation_sd": 0.1}}, r"realism.magnetisation_sd: unknown key"),
    ({"viscoelastic": {"g": [0.6, 0.6], "tau_s": [1.0, 2.0]}}, r"viscoelastic.g = \[0.6, 0.6\]: the weights sum"),
    ({"viscoelastic": {"g": [0.1], "tau_s": [0.0]}}, r"viscoelastic.tau_s = \[0.0\]: expected positive time"),
    ({"viscoelastic": {"tangential_g": [0.5, 0.5]}}, r"viscoelastic.tangential_g = \[0.5, 0.5\]: the weights sum"),
    ({"viscoelastic": {"nail_fold_g": [0.1, 0.1]}}, r"viscoelastic.nail_fold_g = \[0.1, 0.1\]: .*one time constant"),
    ({"viscoelastic": {"nail_fold_tau_s": [-1.0]}}, r"viscoelastic.nail_fold_tau_s = \[-1.0\]: expected positive"),
    ({"viscoelastic": {"tangential_creep": "yes"}}, r"viscoelastic.tangential_creep = 'yes': expected true or false"),
    ({"design": "cylindrical-A"}, r"design: unknown key"),
])
def test_mistakes_in_a_wearable_protocol_are_one_line_errors_naming_the_key(change, message):
    table = {"protocol": "wearable", "seed": 1, **change}
    with pytest.raises(ConfigError, match=f"^bad.toml: {message}") as error:
        protocol_from_dict(table, "bad.toml")
    assert "\n" not in str(error.value)


def test_a_wearable_protocol_names_its_bench_and_device():
    protocol = protocol_from_dict({"protocol": "wearable", "parameters": {"sensor_side": "ulnar"}}, "w.toml")
    assert protocol.bench is load(owner("protocol", "wearable").benches["wearable"]) and protocol.design.name == "nail-ring-ulnar"
    assert protocol.to_dict()["design"] == "nail-ring-ulnar" and protocol.to_dict()["realism"]["noise"] is True
    assert load_protocol("pushing").bench is not protocol.bench
