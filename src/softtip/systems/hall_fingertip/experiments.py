"""The published experiments (S1), run on the twin: one function per protocol, each a dataset.

Every trial starts in the air (its first sample is the baseline that is subtracted, as on the
bench), then follows the protocol's motion; readings come from a fabricated unit of the design
(:mod:`softtip.systems.hall_fingertip.realism`), forces from the contact mechanics (:mod:`softtip.systems.hall_fingertip.engine`) made
viscoelastic by the material's Prony series where a force sensor would measure them.

Forces in labels are what a reference sensor under the fingertip measures: ``fz_N`` the normal
(compressive) force, ``fx_N``/``fy_N`` the tangential force applied to the fingertip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from softtip.data import Dataset, DatasetMetadata, TrialWriter, channel_columns
from softtip.data.splits import CALIBRATION, VALIDATION
from softtip._core.signals import hysteresis_percent
from softtip.lab.bench import SeededBench
from softtip.lab.trials import run_trials
from softtip._core.units import MM
from softtip.design.model import Design
from softtip.systems.hall_fingertip.engine import HeldPart, interpolate_path, path_table
from softtip.systems.hall_fingertip.realism import FabricatedUnit, Realism
from softtip.mechanics.contact import LoadCase
from softtip.mechanics.indenters import Board, CornerPlate, TiltedPlate
from softtip.mechanics.poses import MagnetPoses
from softtip.mechanics.viscoelastic import PronySeries, prony_for_hysteresis, qlv_response
from softtip.twin import Readout
from softtip.twin.influence import InfluenceEngine

Parameters = Any  # a protocol's [parameters]: its schema's object (softtip.systems.hall_fingertip.protocols)



@dataclass
class Bench(SeededBench):
    """What every fingertip protocol needs: the fingertip's mechanics, its material's viscoelasticity,
    the realism settings and a seeded random stream."""

    realism: Realism
    fingertip: InfluenceEngine

    @property
    def design(self) -> Design:
        return self.fingertip.design

    def unit(self) -> FabricatedUnit:
        return FabricatedUnit(self.design, self.realism, self.rng)

    def times(self, duration: float) -> np.ndarray:
        return np.arange(0.0, duration + 1e-9, 1.0 / self.rate_hz)


def centred_cycle(fingertip: InfluenceEngine, depth: float, speed: float,
                  rest: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One noise-free load/unload cycle of a centred board: ``depth`` at ``speed`` (m, m/s), ``rest`` s at
    the bottom, released at ``speed``: times (s), the first chip's z field change (T) and the elastic
    normal force (N), 400 samples."""
    table = path_table(fingertip.press(LoadCase(Board(), depth, friction="stick"), normal_steps=8))
    times = np.linspace(0, 2 * depth / speed + rest, 400)
    profile = np.minimum(times * speed, depth)
    profile = np.where(times > depth / speed + rest, depth - (times - depth / speed - rest) * speed, profile)
    poses, force = interpolate_path(table, profile, np.zeros((len(times), 2)))
    return times, Readout(fingertip.design).field_change(poses)[:, 0, 2], force[:, 2]


def material_prony(fingertip: InfluenceEngine, hysteresis_percent: float, depth: float, speed: float,
                   rest: float) -> PronySeries:
    """The material's relaxation, set once per design so that a centred board load/unload cycle
    (``depth`` at ``speed`` with ``rest`` s at the bottom) shows ``hysteresis_percent`` between
    sensor z and normal force. One cycle fixes one weight for one time constant (the cycle's time to
    its peak); every other cycle, speed and protocol is then a prediction."""
    return prony_for_hysteresis(hysteresis_percent, *centred_cycle(fingertip, depth, speed, rest))


def cycle_hysteresis(fingertip: InfluenceEngine, prony: PronySeries, depth: float, speed: float,
                     rest: float) -> float:
    """The S1 hysteresis (%) of a centred cycle (:func:`centred_cycle`) with the material relaxing as
    ``prony``: the force a reference sensor reads (it never pulls) against the chip's z."""
    times, z, force = centred_cycle(fingertip, depth, speed, rest)
    return hysteresis_percent(z, np.maximum(qlv_response(times, force, prony), 0.0))


def _metadata(bench: Bench, record: dict, seed: int, description: str, designs: dict | None = None) -> DatasetMetadata:
    return DatasetMetadata(description=description, design=designs or {"name": bench.design.name, **bench.design.spec},
                           sensor_settings=bench.design.chip_settings.to_dict(), protocol=record, seed=seed)


def _roles(calibration: int, validation: int) -> list[str]:
    return [CALIBRATION] * calibration + [VALIDATION] * validation


def out_and_back(rate_hz: float, rest_s: float, travel_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample times of a rest, a motion of ``travel_s`` seconds and its way back, and the time
    travelled along the motion at each (0 at rest, ``travel_s`` at the far end)."""
    times = np.arange(0.0, rest_s + 2 * travel_s, 1 / rate_hz)
    return times, np.clip(np.minimum(times - rest_s, rest_s + 2 * travel_s - times), 0, travel_s)


def _push_profile(times: np.ndarray, start: float, depth: float, speed: float, hold: float = 0.0,
                  release_speed: float | None = None) -> np.ndarray:
    """Depth (m) over time: in the air until ``start``, down to ``depth`` at ``speed``, ``hold`` s, and
    back up at ``release_speed`` (if given)."""
    down = np.clip((times - start) * speed, 0, depth)
    if release_speed is None:
        return down
    up_start = start + depth / speed + hold
    return np.where(times > up_start, np.maximum(depth - (times - up_start) * release_speed, 0.0), down)


def _force_labels(force: np.ndarray, times: np.ndarray, prony: PronySeries) -> dict[str, np.ndarray]:
    """Reference-sensor labels from the fingertip's reaction on the indenter (elastic, (N, 3))."""
    measured = qlv_response(times, force, prony)
    measured[:, 2] = np.maximum(measured[:, 2], 0.0)  # a contact does not pull
    return {"fx_N": -measured[:, 0], "fy_N": -measured[:, 1], "fz_N": measured[:, 2]}


# ---------------------------------------------------------------------------------------------- generation 1

def stage_position(realism: Realism, angle_deg: float) -> np.ndarray:
    """Where (x, y in m) the mid-plane of a board turned to ``angle_deg`` on the rotary stage passes the
    fingertip's axis: the stage's axis ``stage_axis_offset_mm`` off it along x, the board's mid-plane
    ``board_edge_offset_mm`` off the stage's axis across the board."""
    angle = math.radians(angle_deg)
    across = np.array([-math.sin(angle), math.cos(angle)])
    return (np.array([realism.stage_axis_offset_mm, 0.0]) + realism.board_edge_offset_mm * across) * MM


def pushing(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §1 pushing test: a board at each angle pushed ``depth_mm`` at ``speed_mm_s``."""
    writer = TrialWriter(1, labels={"angle_deg": "deg", "depth_mm": "mm", "fx_N": "N", "fy_N": "N", "fz_N": "N"},
                         conditions={"board_angle_deg": "deg", "role": "1"},
                         metadata=_metadata(bench, record, seed, "pushing test"))
    unit, realism = bench.unit(), bench.realism
    depth, speed = p.depth_mm * MM, p.speed_mm_s * MM
    for angle in p.angles_deg:
        for role in _roles(int(p.calibration_trials), int(p.validation_trials)):
            true_angle = angle + bench.scatter(realism.angle_sd_deg)
            position = tuple(stage_position(realism, true_angle) + bench.scatter(realism.position_sd_mm * MM, 2))
            trial_speed = speed * (1 + bench.scatter(realism.speed_sd))
            table = path_table(bench.fingertip.press(
                LoadCase(Board(thickness=p.board_thickness_mm * MM, angle=math.radians(true_angle)), depth,
                         position=position, friction="stick"), normal_steps=6))
            times = bench.times(p.pre_contact_s + depth / trial_speed)
            profile = _push_profile(times, p.pre_contact_s, depth, trial_speed)
            poses, force = interpolate_path(table, profile, np.zeros((len(times), 2)))
            readings = unit.record(poses, times, bench.rng)
            writer.add({"time_s": times, **channel_columns(readings), "angle_deg": np.full(len(times), float(angle)),
                        "depth_mm": profile / MM, **_force_labels(force, times, bench.prony)},
                       {"board_angle_deg": float(angle), "role": role})
    return writer.to_dataset()


def _force_motions(p: Parameters) -> dict[str, tuple[float, np.ndarray]]:
    """The three-axis force calibration's motions: each one's depth (m) and shear (x, y in m)."""
    return {"normal": (p.normal_depth_mm * MM, np.zeros(2)),
            "shear-x": (p.shear_depth_mm * MM, np.array([p.shear_mm, 0.0]) * MM),
            "shear-y": (p.shear_depth_mm * MM, np.array([0.0, p.shear_mm]) * MM)}


def _force_trial(bench: Bench, p: Parameters, speed_mm_s: float, depth: float,
                 shear: np.ndarray) -> tuple[float, np.ndarray]:
    """One trial of a force motion with the bench's scatter: its speed (m/s) and its contact path's table."""
    realism = bench.realism
    trial_speed = speed_mm_s * MM * (1 + bench.scatter(realism.speed_sd))
    load = LoadCase(Board(thickness=p.board_thickness_mm * MM,
                          angle=math.radians(bench.scatter(realism.angle_sd_deg))), depth,
                    tangential=tuple(shear), position=tuple(bench.scatter(realism.position_sd_mm * MM, 2)),
                    friction="stick")
    return trial_speed, path_table(bench.fingertip.press(load, normal_steps=4, tangential_steps=8))


def force3(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §1 three-axis force calibration: normal push; normal then shear along x; along y."""
    writer = TrialWriter(1, labels={"fx_N": "N", "fy_N": "N", "fz_N": "N"},
                         conditions={"motion": "1", "role": "1"},
                         metadata=_metadata(bench, record, seed, "3-axis force calibration"))
    unit = bench.unit()
    for name, (depth, shear) in _force_motions(p).items():
        for role in _roles(int(p.calibration_trials), int(p.validation_trials)):
            trial_speed, table = _force_trial(bench, p, p.speed_mm_s, depth, shear)
            start = p.pre_contact_s
            shear_time = np.linalg.norm(shear) / trial_speed
            times = bench.times(start + depth / trial_speed + shear_time)
            profile = _push_profile(times, start, depth, trial_speed)
            progress = np.clip((times - start - depth / trial_speed) * trial_speed, 0, np.linalg.norm(shear))
            direction = shear / max(np.linalg.norm(shear), 1e-12)
            poses, force = interpolate_path(table, profile, progress[:, None] * direction[None])
            readings = unit.record(poses, times, bench.rng)
            writer.add({"time_s": times, **channel_columns(readings), **_force_labels(force, times, bench.prony)},
                       {"motion": name, "role": role})
    return writer.to_dataset()


def force_cycles(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """The three-axis force calibration's motions as a live use plays them: at each speed, repetitions of
    the three motions in turn from a rested pad, each trial ``pre_contact_s`` in the air, the normal push
    (or the push then the shear) and back along the same path (the release). The readings are taken from
    the mean of the ones in the air, as the live pipeline's baseline is; the force from the repetition's
    whole history, as a stream's is: the material still relaxes from the previous press (its time
    constant is longer than the rest in the air)."""
    writer = TrialWriter(1, labels={"fx_N": "N", "fy_N": "N", "fz_N": "N"},
                         conditions={"motion": "1", "speed_mm_s": "mm/s", "role": "1"},
                         metadata=_metadata(bench, record, seed, "3-axis force load/unload cycles"))
    unit = bench.unit()
    for speed_mm_s in p.speeds_mm_s:
        for role in _roles(int(p.calibration_trials), int(p.validation_trials)):
            trials = []  # each motion's times, readings and elastic force, in turn
            for name, (depth, shear) in _force_motions(p).items():
                trial_speed, table = _force_trial(bench, p, speed_mm_s, depth, shear)
                reach = float(np.linalg.norm(shear))
                times, travelled_s = out_and_back(bench.rate_hz, p.pre_contact_s, (depth + reach) / trial_speed)
                along = travelled_s * trial_speed
                direction = shear / max(reach, 1e-12)
                poses, force = interpolate_path(table, np.minimum(along, depth),
                                                np.clip(along - depth, 0, reach)[:, None] * direction[None])
                readings = unit.record(poses, times, bench.rng)
                trials.append((name, times, readings - readings[times < p.pre_contact_s].mean(axis=0), force))
            starts = np.cumsum([0.0] + [times[-1] + 1 / bench.rate_hz for _, times, *_ in trials[:-1]])
            labels = _force_labels(np.concatenate([force for *_, force in trials]),
                                   np.concatenate([start + times for start, (_, times, *_) in zip(starts, trials)]),
                                   bench.prony)
            bounds = np.cumsum([0] + [len(times) for _, times, *_ in trials])
            for (name, times, readings, _), first, last in zip(trials, bounds[:-1], bounds[1:]):
                writer.add({"time_s": times, **channel_columns(readings),
                            **{k: v[first:last] for k, v in labels.items()}},
                           {"motion": name, "speed_mm_s": float(speed_mm_s), "role": role})
    return writer.to_dataset()


def hysteresis(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §1-2 load/unload cycles at each speed, with a rest at the bottom."""
    writer = TrialWriter(len(bench.design.sensor_positions), labels={"depth_mm": "mm", "fz_N": "N"},
                         conditions={"speed_mm_s": "mm/s", "role": "1"},
                         metadata=_metadata(bench, record, seed, "load/unload hysteresis"))
    unit, realism = bench.unit(), bench.realism
    depth = p.depth_mm * MM
    for speed_mm_s in p.speeds_mm_s:
        for _ in range(int(p.trials)):
            speed = speed_mm_s * MM * (1 + bench.scatter(realism.speed_sd))
            table = path_table(bench.fingertip.press(
                LoadCase(Board(thickness=p.board_thickness_mm * MM), depth,
                         position=tuple(bench.scatter(realism.position_sd_mm * MM, 2)), friction="stick"),
                normal_steps=8))
            start = p.pre_contact_s
            times = bench.times(start + 2 * depth / speed + p.rest_s + p.pre_contact_s)
            profile = _push_profile(times, start, depth, speed, p.rest_s, speed)
            poses, force = interpolate_path(table, profile, np.zeros((len(times), 2)))
            readings = unit.record(poses, times, bench.rng)
            labels = _force_labels(force, times, bench.prony)
            writer.add({"time_s": times, **channel_columns(readings), "depth_mm": profile / MM, "fz_N": labels["fz_N"]},
                       {"speed_mm_s": float(speed_mm_s), "role": CALIBRATION})
    return writer.to_dataset()


def grasp_two(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §1 two-fingertip grasp of a tilted board: each pad meets a face tilted by the board's
    orientation; the second pad faces the first, so it sees the tilt mirrored."""
    writer = TrialWriter(2, labels={"angle_deg": "deg", "grip_force_N": "N"},
                         conditions={"board_angle_deg": "deg", "trained": "1", "role": "1"},
                         metadata=_metadata(bench, record, seed, "two-fingertip grasp"))
    units = (bench.unit(), bench.unit())
    realism = bench.realism
    depth = p.grasp_displacement_mm / 2 * MM  # each pad takes half of the gripper's travel
    speed = p.grasp_speed_mm_s / 2 * MM
    plan = [(a, True, role) for a in p.trained_angles_deg
            for role in _roles(int(p.calibration_trials), int(p.validation_trials))]
    plan += [(a, False, VALIDATION) for a in p.untrained_angles_deg for _ in range(int(p.untrained_trials))]

    def trial(angle: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        trial_bench = replace(bench, rng=rng)
        true_angle = angle + trial_bench.scatter(realism.angle_sd_deg)
        trial_speed = speed * (1 + trial_bench.scatter(realism.speed_sd))
        times = bench.times(p.pre_contact_s + depth / trial_speed + p.hold_s)
        profile = _push_profile(times, p.pre_contact_s, depth, trial_speed)
        readings, normal = [], []
        for pad, mirror in enumerate((0.0, 180.0)):
            load = LoadCase(TiltedPlate(tilt=math.radians(true_angle), angle=math.radians(mirror)), depth,
                            position=tuple(trial_bench.scatter(realism.position_sd_mm * MM, 2)), friction="stick")
            table = path_table(bench.fingertip.press(load, normal_steps=4))
            poses, force = interpolate_path(table, profile, np.zeros((len(times), 2)))
            readings.append(units[pad].record(poses, times, rng))
            normal.append(force)
        return times, np.concatenate(readings, axis=1), _force_labels(normal[0], times, bench.prony)["fz_N"]

    done = run_trials(trial, [(angle, rng) for (angle, _, _), rng in zip(plan, bench.rng.spawn(len(plan)))])
    for (angle, trained, role), (times, readings, grip) in zip(plan, done):
        writer.add({"time_s": times, **channel_columns(readings), "angle_deg": np.full(len(times), float(angle)),
                    "grip_force_N": grip}, {"board_angle_deg": float(angle), "trained": trained, "role": role})
    return writer.to_dataset()


# ---------------------------------------------------------------------------------------------- generation 2

def grasp_positions(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §2 orientation and grip force: a board held face-on whose corner lies at each of a grid
    of contact positions on the pad, at each orientation; grip force from the opposite pad's load
    cell (equal and opposite). Validation sets: trained positions and orientations, untrained
    positions (the grid's midpoints), untrained positions and orientations, other boards."""
    writer = TrialWriter(len(bench.design.sensor_positions), labels={"angle_deg": "deg", "grip_force_N": "N"},
                         conditions={"board_angle_deg": "deg", "position_x_mm": "mm", "position_y_mm": "mm",
                                     "thickness_mm": "mm", "set": "1", "role": "1"},
                         metadata=_metadata(bench, record, seed, "orientation and grip force over contact positions"))
    unit, realism = bench.unit(), bench.realism
    grid = np.array(p.positions_mm)
    middle = (grid[:-1] + grid[1:]) / 2
    plan = [("trained", x, y, a, p.board_thickness_mm, role) for x in grid for y in grid for a in p.angles_deg
            for role in _roles(int(p.calibration_trials), int(p.validation_trials))]
    plan += [("untrained-position", x, y, a, p.board_thickness_mm, VALIDATION)
             for x in middle[::2] for y in middle[::2] for a in p.angles_deg]
    plan += [("untrained-position-orientation", x, y, a, p.board_thickness_mm, VALIDATION)
             for x in middle[::2] for y in middle[::2] for a in p.untrained_angles_deg]
    plan += [("thickness", x, y, a, t, VALIDATION) for t in p.other_thicknesses_mm
             for x in grid[1::2] for y in grid[1::2] for a in p.angles_deg]
    depth = p.grasp_displacement_mm / 2 * MM
    speed = p.grasp_speed_mm_s / 2 * MM

    def trial(x: float, y: float, angle: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        trial_bench = replace(bench, rng=rng)
        # the corner points into the pad: the board covers the quadrant beyond it
        true_angle = angle + trial_bench.scatter(realism.angle_sd_deg)
        position = (x * MM + trial_bench.scatter(realism.position_sd_mm * MM),
                    y * MM + trial_bench.scatter(realism.position_sd_mm * MM))
        load = LoadCase(CornerPlate(angle=math.radians(true_angle)), depth, position=position, friction="stick")
        solution = bench.fingertip.press(load, normal_steps=1)
        trial_speed = speed * (1 + trial_bench.scatter(realism.speed_sd))
        times = bench.times(p.pre_contact_s + depth / trial_speed + p.hold_s)
        profile = _push_profile(times, p.pre_contact_s, depth, trial_speed)
        # a flat face on a flat pad keeps its contact patch: the response grows in proportion to depth
        scale = (profile / depth)[:, None, None]
        poses = MagnetPoses.from_rigid(scale * solution.magnet_poses.rigid[None])
        force = scale[:, 0] * solution.force[None]
        return times, unit.record(poses, times, rng), _force_labels(force, times, bench.prony)["fz_N"]

    done = run_trials(trial, [(x, y, angle, rng) for (_, x, y, angle, _, _), rng
                              in zip(plan, bench.rng.spawn(len(plan)))])
    for (name, x, y, angle, thickness, role), (times, readings, grip) in zip(plan, done):
        writer.add({"time_s": times, **channel_columns(readings), "angle_deg": np.full(len(times), float(angle)),
                    "grip_force_N": grip},
                   {"board_angle_deg": float(angle), "position_x_mm": float(x), "position_y_mm": float(y),
                    "thickness_mm": float(thickness), "set": name, "role": role})
    return writer.to_dataset()


def _plane_normal(phi: float, psi: float) -> np.ndarray:
    """Unit normal of the plane in the part's frame: the board's side (-y) meets the plane at phi,
    its end (x) at psi (radians)."""
    n = np.array([math.cos(phi) * math.sin(psi), math.sin(phi), math.cos(phi) * math.cos(psi)])
    return n / np.linalg.norm(n)


def _collision_trials(bench: Bench, parts: dict, plan: list, points_for: Callable, p: Parameters,
                      writer: TrialWriter, labels_for: Callable) -> None:
    """Trials of a held part driven into a plane; ``plan`` rows are (conditions, offset, normal,
    approach, state); ``points_for(state)`` gives the touching points (or None) and the seat's
    compliance (m/N); the two units' 2 x S chips give 6 S channels."""
    units = (bench.unit(), bench.unit())
    for conditions, offset, normal, approach, state in plan:
        part = parts[offset]
        speed = p.speed_mm_s * MM * (1 + bench.scatter(bench.realism.speed_sd))
        times = bench.times(p.pre_contact_s + p.travel_mm * MM / speed)
        travel = np.clip((times - p.pre_contact_s) * speed, 0, None)
        shift = np.append(bench.scatter(bench.realism.position_sd_mm * MM, 2), 0.0)
        points, seat = points_for(state)
        if points is None:
            poses = [MagnetPoses.at_rest(len(bench.design.magnets), (len(times),))] * 2
            contact = np.zeros(len(times))
        else:
            out = part.collide(points - shift, normal, approach, travel, seat)
            poses = [out["magnets_0"], out["magnets_1"]]
            contact = out["contact_forces"].sum(axis=1)
        readings = np.concatenate([units[k].record(poses[k], times, bench.rng) for k in range(2)], axis=1)
        writer.add({"time_s": times, **channel_columns(readings), **labels_for(state, contact, times)}, conditions)


def contact_states(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §2 contact states of a grasped board pushed into a plane: Point A (right corner), Point B
    (left corner), Edge; both pads sensorised."""
    writer = TrialWriter(2 * len(bench.design.sensor_positions), labels={"state": "1", "normal_force_N": "N"},
                         conditions={"phi_deg": "deg", "psi_deg": "deg", "position_x_mm": "mm", "position_y_mm": "mm",
                                     "approach_deg": "deg", "set": "1", "role": "1"},
                         metadata=_metadata(bench, record, seed, "contact states of a grasped board"))
    grip = p.grip_depth_mm * MM
    offsets = [tuple(o) for o in p.positions_mm]
    parts = {o: HeldPart.grasp(bench.fingertip, grip, p.board_thickness_mm * MM, (o[0] * MM, o[1] * MM))
             for o in offsets}
    half, reach = p.board_width_mm / 2 * MM, p.stick_out_mm * MM
    corners = {"point-a": np.array([[half, -reach, 0.0]]), "point-b": np.array([[-half, -reach, 0.0]]),
               "edge": np.array([[half, -reach, 0.0], [-half, -reach, 0.0]])}
    sd = bench.realism.angle_sd_deg

    def rows(phis, psis_by_state, approach_deg, name, trials, roles):
        out = []
        for phi in phis:
            for state, psis in psis_by_state.items():
                for psi in psis:
                    for offset in offsets:
                        for role in roles(trials):
                            signed = {"point-a": -psi, "point-b": psi, "edge": 0.0}[state]
                            normal = _plane_normal(math.radians(phi + bench.scatter(sd)),
                                                   math.radians(signed + bench.scatter(sd)))
                            incline = math.radians(approach_deg)
                            along = np.array([0.0, 1.0, 0.0]) - normal[1] * normal
                            approach = -(math.sin(incline) * normal + math.cos(incline) * along / np.linalg.norm(along))
                            out.append(({"phi_deg": float(phi), "psi_deg": float(psi), "position_x_mm": float(offset[0]),
                                         "position_y_mm": float(offset[1]), "approach_deg": float(approach_deg),
                                         "set": name, "role": role}, offset, normal, approach, state))
        return out

    trained = lambda n: _roles(int(p.calibration_trials), int(p.validation_trials))  # noqa: E731
    untrained = lambda n: [VALIDATION] * n  # noqa: E731
    plan = rows(p.phi_deg, {"edge": [0.0], "point-a": p.psi_deg, "point-b": p.psi_deg}, 90.0, "trained",
                None, trained)
    plan += rows(p.untrained_phi_deg, {"edge": [0.0], "point-a": p.untrained_psi_deg,
                                          "point-b": p.untrained_psi_deg}, 90.0, "untrained-angles",
                 int(p.untrained_trials), untrained)
    for incline in p.approach_inclines_deg:
        plan += rows([p.approach_phi_deg], {"edge": [0.0], "point-a": p.psi_deg, "point-b": p.psi_deg},
                     incline, "untrained-approach", int(p.untrained_trials), untrained)

    def labels(state, contact, times):
        return {"state": np.full(len(times), state), "normal_force_N": contact}

    _collision_trials(bench, parts, plan, lambda state: (corners[state], 0.0), p, writer, labels)
    return writer.to_dataset()


def inverter_contacts(p: Parameters) -> dict[int, tuple[np.ndarray | None, float]]:
    """For each insertion state, where part A touches part B (points in the part's frame, m; None in
    the air) and the compliance (m/N) it meets: the clips flex as the lid seats through its centre,
    a clip on the rim meets hard plastic."""
    clip_x, depth = p.clip_spacing_mm / 2 * MM, p.part_depth_mm * MM
    seat, rim = p.seat_compliance_mm_per_N * MM, p.rim_compliance_mm_per_N * MM
    return {0: (None, 0.0), 1: (np.array([[0.0, -depth, 0.0]]), seat),
            2: (np.array([[-clip_x, -depth, 0.0]]), rim), 3: (np.array([[clip_x, -depth, 0.0]]), rim)}


def world_up(tilt_y_deg: float, tilt_x_deg: float) -> np.ndarray:
    """World up seen from a part that hangs from a flange tilted about y and x, its -y pointing down."""
    ty, tx = math.radians(tilt_y_deg), math.radians(tilt_x_deg)
    up = np.array([math.sin(tx), math.cos(ty) * math.cos(tx), math.sin(ty) * math.cos(tx)])
    return up / np.linalg.norm(up)


def inverter(bench: Bench, p: Parameters, seed: int, record: dict) -> Dataset:
    """S1 §2 insertion of an inverter lid (part A, held by its top edge) into its body (part B):
    state 0 in the air, 1 inserted (the lid seats through its centre), 2 left clip on part B's rim,
    3 right clip. The flange is tilted about y; part A moves down along the world vertical."""
    writer = TrialWriter(2 * len(bench.design.sensor_positions), labels={"state": "1", "normal_force_N": "N"},
                         conditions={"state_nominal": "1", "tilt_y_deg": "deg", "tilt_x_deg": "deg",
                                     "offset_mm": "mm", "set": "1", "role": "1"},
                         metadata=_metadata(bench, record, seed, "inverter insertion states"))
    grip = p.grip_depth_mm * MM
    offsets = sorted({0.0, *p.untrained_offsets_mm})
    parts = {o: HeldPart.grasp(bench.fingertip, grip, p.part_thickness_mm * MM, (o * MM, 0.0)) for o in offsets}
    contacts = inverter_contacts(p)

    def normal_for(tilt_y: float, tilt_x: float) -> np.ndarray:
        sd = bench.realism.angle_sd_deg
        return world_up(tilt_y + bench.scatter(sd), tilt_x + bench.scatter(sd))

    plan = []
    for state in (0, 1, 2, 3):
        for role in _roles(int(p.calibration_trials), int(p.validation_trials)):
            plan.append(({"state_nominal": state, "tilt_y_deg": p.tilt_y_deg, "tilt_x_deg": 0.0, "offset_mm": 0.0,
                          "set": "trained", "role": role}, 0.0, p.tilt_y_deg, 0.0, state))
        tilt_x = p.untrained_tilt_x_deg if state in (2, 3) else 0.0
        for _ in range(int(p.untrained_trials)):
            plan.append(({"state_nominal": state, "tilt_y_deg": p.untrained_tilt_y_deg, "tilt_x_deg": tilt_x,
                          "offset_mm": 0.0, "set": "untrained-tilt", "role": VALIDATION}, 0.0,
                         p.untrained_tilt_y_deg, tilt_x, state))
        for offset in p.untrained_offsets_mm:
            for _ in range(int(p.untrained_trials)):
                plan.append(({"state_nominal": state, "tilt_y_deg": p.tilt_y_deg, "tilt_x_deg": 0.0,
                              "offset_mm": float(offset), "set": "untrained-offset", "role": VALIDATION}, offset,
                             p.tilt_y_deg, 0.0, state))
    rows = []
    for conditions, offset, tilt_y, tilt_x, state in plan:
        normal = normal_for(tilt_y, tilt_x)
        rows.append((conditions, offset, normal, -normal, state))

    def labels(state, contact, times):
        # before part A touches part B the lid is in the air, whatever the trial's outcome
        return {"state": np.where(contact > 0, state, 0).astype(np.int64), "normal_force_N": contact}

    _collision_trials(bench, parts, rows, lambda state: contacts[state], p, writer, labels)
    return writer.to_dataset()
