"""Scripted scenarios for the emulated fingertip: what its chips read over time, from the twin.

A scenario is computed once (exact contact mechanics along each motion, the exact field of the
fabricated unit's magnets) and then replayed as a picklable ``source(t_s) -> (chips, 3)`` µT -
absolute field, no noise: the emulator adds the sensor's noise and quantisation like a chip.
It loops, and keeps the true force so live estimates can be scored against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from softtip._core.progress import SILENT, Progress
from softtip._core.units import MM, UT_PER_T

if TYPE_CHECKING:
    from softtip._core.cache import EntryPieces
    from softtip.lab.protocols import Protocol


@dataclass(frozen=True)
class TwinScenario:
    times_s: np.ndarray  # (N,)
    field_uT: np.ndarray  # (N, chips, 3) absolute
    force_N: np.ndarray  # (N, 3): fx, fy (on the fingertip), fz (compressive)

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    def _index(self, t_s: float) -> tuple[int, float]:
        t = t_s % self.duration_s
        k = min(int(np.searchsorted(self.times_s, t, side="right")) - 1, len(self.times_s) - 2)
        return k, (t - self.times_s[k]) / (self.times_s[k + 1] - self.times_s[k])

    def __call__(self, t_s: float) -> np.ndarray:
        k, w = self._index(t_s)
        return (1 - w) * self.field_uT[k] + w * self.field_uT[k + 1]

    def force(self, t_s: np.ndarray) -> np.ndarray:
        """True force (N, 3) at device times ``t_s``."""
        t = np.asarray(t_s, float) % self.duration_s
        return np.column_stack([np.interp(t, self.times_s, self.force_N[:, k]) for k in range(3)])


def pushing_scenario(protocol: Protocol, seed: int, speed_mm_s: float | None = None, rate_hz: float = 200.0,
                     rest_s: float = 2.0, progress: Progress = SILENT, pieces: EntryPieces | None = None) -> TwinScenario:
    """The force-calibration motions in a loop - a normal push, a push then shear along x, along y -
    each followed by a release and a rest, on one fabricated unit of the protocol's design, at the
    protocol's speed unless ``speed_mm_s`` is given; the force is what a reference sensor reads
    (the material's relaxation included). The motions are computed side by side, one process per core;
    ``pieces``: where each finished motion is kept, and read back instead of computed again (a run stopped
    part way resumes)."""
    # the twin's mechanics are imported here, not with the module: a cached scenario is replayed (and
    # unpickled in the emulator's process) without them, which takes seconds off a warm start
    from softtip._core.forked import shared_zeros, solve_in_processes
    from softtip.mechanics.contact import LoadCase
    from softtip.mechanics.indenters import Board
    from softtip.mechanics.poses import MagnetPoses
    from softtip.mechanics.viscoelastic import qlv_response
    from softtip.systems.hall_fingertip.engine import interpolate_path, path_table
    from softtip.systems.hall_fingertip.experiments import material_prony, out_and_back
    from softtip.systems.hall_fingertip.protocols import fingertip_for
    from softtip.systems.hall_fingertip.realism import FabricatedUnit

    p = protocol.parameters
    fingertip = fingertip_for(protocol.design, p, progress)
    rng = np.random.default_rng(seed)
    unit = FabricatedUnit(protocol.design, protocol.realism, rng)  # its exact field: the emulator adds the noise
    speed = (p.speed_mm_s if speed_mm_s is None else speed_mm_s) * MM
    motions = [(depth_mm * MM, np.array(shear_mm) * MM) for depth_mm, shear_mm in (
        (p.normal_depth_mm, (0.0, 0.0)), (p.shear_depth_mm, (p.shear_mm, 0.0)), (p.shear_depth_mm, (0.0, p.shear_mm)))]
    # air, down, shear, back along the same path, air
    paths = [out_and_back(rate_hz, rest_s, (depth + float(np.linalg.norm(shear))) / speed) for depth, shear in motions]
    magnets = len(fingertip.influence.magnet_centers)
    # in memory the processes that compute the motions side by side share with this one
    segments = [{"times_s": times, "rigid": shared_zeros((len(times), magnets, 6)),
                 "force_N": shared_zeros((len(times), 3))} for times, _ in paths]

    def push(index: int) -> None:  # in this process or a forked one
        (depth, shear), (_, travelled_s) = motions[index], paths[index]
        load = LoadCase(Board(thickness=p.board_thickness_mm * MM, angle=0.0), depth, tangential=tuple(shear),
                        friction="stick")
        table = path_table(fingertip.press(load, normal_steps=4, tangential_steps=8))
        reach = float(np.linalg.norm(shear))
        along = travelled_s * speed
        sheared = np.clip(along - depth, 0, reach)
        poses, force = interpolate_path(table, np.minimum(along, depth),
                                        sheared[:, None] * (shear / max(reach, 1e-12))[None])
        segments[index]["rigid"][:] = poses.rigid
        segments[index]["force_N"][:] = np.column_stack([-force[:, 0], -force[:, 1], force[:, 2]])
        if pieces is not None:
            pieces.write(index, segments[index])

    with progress.task("the pushes: normal, then shear along x, along y", total=len(motions)) as task:
        to_compute = []
        for index in range(len(motions)):
            kept = pieces.read(index) if pieces is not None else None
            if kept is None:
                to_compute.append(index)
            else:
                segments[index] = kept
                task.advance()
        solve_in_processes(push, to_compute, lambda index: task.advance())
    starts = np.cumsum([0.0] + [segment["times_s"][-1] + 1 / rate_hz for segment in segments[:-1]])
    times = np.concatenate([start + segment["times_s"] for start, segment in zip(starts, segments)])
    poses = MagnetPoses.from_rigid(np.concatenate([segment["rigid"] for segment in segments]))
    v = protocol.viscoelastic
    prony = material_prony(fingertip, v.hysteresis_percent, v.depth_mm * MM, v.speed_mm_s * MM, v.rest_s)
    force = qlv_response(times, np.concatenate([segment["force_N"] for segment in segments]), prony)
    force[:, 2] = np.maximum(force[:, 2], 0.0)  # a contact does not pull
    return TwinScenario(times_s=times, field_uT=unit.field(poses) * UT_PER_T, force_N=force)


def insertion_scenario(protocol: Protocol, seed: int, rate_hz: float = 100.0, speed_mm_s: float = 2.0,
                       rest_s: float = 1.0, progress: Progress = SILENT, pieces: EntryPieces | None = None) -> TwinScenario:
    """The inverter lid lowered into its body and lifted again, once per case - seated, left clip on
    the rim, right clip on the rim - read by the two fingertips' four chips (the inverter protocol's
    world). ``force_N`` holds the contact force on part B along its normal in the z column. ``pieces``:
    where each finished case is kept, and read back instead of computed again."""
    from dataclasses import replace

    from softtip.systems.hall_fingertip.experiments import out_and_back
    from softtip.systems.hall_fingertip.insertion_world import CASES, InsertionWorld

    quiet = replace(protocol, realism=replace(protocol.realism, noise=False))
    speed, top, bottom = speed_mm_s * MM, 2.0 * MM, -0.6 * MM
    times, travelled_s = out_and_back(rate_hz, rest_s, (top - bottom) / speed)
    pose = top - travelled_s * speed
    segments_t, fields, forces = [], [], []
    clock = 0.0
    with progress.task("the lid lowered and lifted in each case", total=len(CASES)) as task:
        for index, case in enumerate(CASES):
            kept = pieces.read(index) if pieces is not None else None
            if kept is None:
                world = InsertionWorld(quiet, case, np.random.default_rng(seed))
                case_fields, case_forces = [], []
                for height in pose:
                    case_fields.append(world.absolute_uT(float(height)).reshape(-1, 3))
                    case_forces.append([0.0, 0.0, world.force])  # the force of the pose just solved
                kept = {"field_uT": np.array(case_fields), "force_N": np.array(case_forces)}
                if pieces is not None:
                    pieces.write(index, kept)
            fields.append(kept["field_uT"])
            forces.append(kept["force_N"])
            segments_t.append(clock + times)
            clock += times[-1] + 1 / rate_hz
            task.advance(note=case)
    return TwinScenario(times_s=np.concatenate(segments_t), field_uT=np.concatenate(fields),
                        force_N=np.concatenate(forces))
