"""S2's calibration protocol on the wearable twin: participants press a table force sensor while the
chip on the side of their nail and the table are recorded together, unfiltered.

Per participant (a finger of their own: breadth, pad stiffness, friction), per run (the ring
re-seated: its preload and the chip's place along the nail change), the seven trials of
:mod:`softtip.systems.wearable.human_force` on every contact shape of the protocol. The history of each trial is
simulated on a fine grid from the finger's placement ``lead_in_s`` before the recording, so the
pad's creep from placing it carries into the trial; both sensors then sample it at ``rate_hz``.
Every trial's first sample is its tare: subtracted from its readings and kept as a condition. After
each seating, the chip's pressure with the finger in the air (its static offset: the ring's preload)
is read once and kept as the run's condition ``side_air_fz_N``.

One dataset holds the whole protocol, with participant, run, motion and contact as conditions: the
study fits per participant (select a participant), splits by trial (a motion, a run) or by time
block within trials (``time_s``), and compares contact shapes, from one file with one provenance.

Channels: ``side_fx_N`` (the chip's distal shear), ``side_fy_N`` (dorsal shear), ``side_fz_N``
(pressure). Labels: ``fx_N``, ``fy_N``, ``fz_N`` (the table sensor, in its own axes), ``cop_x_mm``,
``cop_y_mm`` (the twin's true centre of force on the pad, from the pad's nominal contact point,
radial and distal; NaN when the pad is off the object: a 3-axis table sensor could not measure it),
``sliding`` (the finger slides on the object).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field

from softtip._core.channels import AXES
from softtip.systems.wearable.reading import FORCE
from softtip._core.config import (Flag, Fraction, NonNegativeNumber, Numbers, PositiveInteger, PositiveNumber, Real,
                                  Refusal, choice, expect, schema)
from softtip._core.progress import Progress
from softtip._core.units import MM
from softtip.data import Dataset, DatasetMetadata, TrialWriter
from softtip.lab.bench import SeededBench
from softtip.lab.protocols import BenchKind, Protocol, Size, protocol_file_schema
from softtip.systems.wearable.human_force import MINIMUM_TRIAL_S, MOTIONS, Effort, intended_force
from softtip.systems.wearable.realism import REALISM_SOURCES, WearableRealism
from softtip.systems.wearable.fingerpad import (CONTACT_SHAPES, DIP_LATERAL_STIFFNESS, NAIL_FOLD_RELAXATION,
                                                PAD_RELAXATION, SIDES, TANGENTIAL_RELAXATION, ChipMount, FingerPad,
                                                scaled, shape_radii)
from softtip.mechanics.viscoelastic import PronySeries
from softtip.systems.wearable.chip import CHIP, TABLE_SENSOR
from softtip.systems.wearable.twin import WearableTwin

CHANNELS = dict.fromkeys(FORCE.channel_names(1), FORCE.unit)  # the side chip
LABELS = {**{f"f{axis}_N": "N" for axis in AXES}, "cop_x_mm": "mm", "cop_y_mm": "mm", "sliding": "1"}
CONDITIONS = {"participant": "1", "run": "1", "motion": "1", "contact": "1", "side_air_fz_N": "N",
              **{f"side_tare_f{axis}_N": "N" for axis in AXES}, **{f"table_tare_f{axis}_N": "N" for axis in AXES}}

Motions = Annotated[list[choice(*MOTIONS)], Field(min_length=1), expect(f"a non-empty list of: {', '.join(MOTIONS)}")]
Contacts = Annotated[list[choice(*CONTACT_SHAPES)], Field(min_length=1),
                     expect(f"a non-empty list of: {', '.join(CONTACT_SHAPES)}")]
# the finger's and the ring's defaults are the mechanics' (softtip.systems.wearable.fingerpad, SI units)
_PAD, _MOUNT = FingerPad(), ChipMount()


@schema(section="parameters")
class WearableParameters:
    """The ``[parameters]`` table of the wearable protocol (S2; units in the names). The finger's and the
    ring's defaults are those of :class:`~softtip.systems.wearable.fingerpad.FingerPad` and
    :class:`~softtip.systems.wearable.fingerpad.ChipMount`."""

    rate_hz: PositiveNumber = 10.0  # both sensors, unfiltered
    simulation_rate_hz: PositiveNumber = 100.0  # the grid the continuous history is simulated on
    participants: PositiveInteger = 3
    runs: PositiveInteger = 3
    motions: Motions = field(default_factory=lambda: list(MOTIONS))
    trial_s: PositiveNumber = 15.0
    lead_in_s: NonNegativeNumber = 5.0  # from placing the finger to the start of the recording
    contacts: Contacts = field(default_factory=lambda: ["flat"])
    curved_radius_mm: PositiveNumber = 20.0  # a sphere
    edge_radius_mm: PositiveNumber = 1.0  # a straight edge across the finger, rounded
    point_radius_mm: PositiveNumber = 1.0  # a hemispherical tip
    press_peak_N: PositiveNumber = 4.0
    rest_N: PositiveNumber = 0.5
    dorsal_hold_N: PositiveNumber = 2.5
    tilt_normal_N: PositiveNumber = 3.0
    tangential_effort: PositiveNumber = 1.0  # tilts reach up to 1.1 x this share of the friction limit
    normal_coupling: NonNegativeNumber = 0.3
    lean_share: Fraction = 0.5
    finger_width_mm: PositiveNumber = _PAD.width / MM
    pad_stiffness_N_per_mm: PositiveNumber = _PAD.stiffness * MM
    pad_stiffening_per_mm: PositiveNumber = _PAD.stiffening * MM
    friction: PositiveNumber = _PAD.friction
    nail_fold_transmission: Fraction = _PAD.transmission
    lateral_drag: Flag = _PAD.lateral_drag  # the pad's lateral displacement presses the chip too
    dip_joint: Flag = True  # the last joint turns sideways under radial force, moving the nail against the chip
    dip_lateral_stiffness_Nm_per_rad: PositiveNumber = DIP_LATERAL_STIFFNESS
    sensor_side: choice(*SIDES) = _MOUNT.side
    sensor_offset_mm: Real = _MOUNT.position_y / MM  # along the finger from the pad's contact point, distal > 0
    ring_preload_N: NonNegativeNumber = _MOUNT.preload

    def __post_init__(self) -> None:
        if self.simulation_rate_hz < 2 * self.rate_hz:
            raise Refusal("simulation_rate_hz", f"expected at least twice rate_hz = {self.rate_hz:g}")
        if self.trial_s < MINIMUM_TRIAL_S:
            raise Refusal("trial_s", f"expected at least {MINIMUM_TRIAL_S:g} s: a quiet tare, a press and a quiet end")
        if self.trial_s * self.rate_hz < 2:
            raise Refusal("trial_s", f"expected at least two samples at rate_hz = {self.rate_hz:g}")
        for key in ("motions", "contacts"):
            values = getattr(self, key)
            if len(set(values)) != len(values):
                raise Refusal(key, "expected each entry once")


def _prony(g: list[float], tau_s: list[float], keys: tuple[str, str]) -> PronySeries:
    """The Prony series of weights ``g`` and times ``tau_s``, or a refusal naming the key (``keys``) at fault."""
    try:
        return PronySeries(tuple(g), tuple(tau_s))
    except ValueError as error:
        raise Refusal(keys[0] if "prony.g" in str(error) else keys[1], str(error).split(": ", 1)[-1]) from None


@schema(section="viscoelastic")
class PadViscoelastic:
    """The finger tissue's reduced relaxation functions, each Prony weights ``g`` and times ``tau_s``: the
    pad's (default :data:`~softtip.systems.wearable.fingerpad.PAD_RELAXATION`: Pawluk & Howe 1999's time
    constants, assumed weights); with ``tangential_creep`` the pad's under tangential load (``tangential_*``,
    default :data:`~softtip.systems.wearable.fingerpad.TANGENTIAL_RELAXATION`), with ``nail_fold`` the
    tissue's under the chip (``nail_fold_*``, default
    :data:`~softtip.systems.wearable.fingerpad.NAIL_FOLD_RELAXATION`); either switched off is the pad's."""

    g: Numbers = field(default_factory=lambda: list(PAD_RELAXATION.g))
    tau_s: Numbers = field(default_factory=lambda: list(PAD_RELAXATION.tau))
    tangential_creep: Flag = True
    tangential_g: Numbers = field(default_factory=lambda: list(TANGENTIAL_RELAXATION.g))
    tangential_tau_s: Numbers = field(default_factory=lambda: list(TANGENTIAL_RELAXATION.tau))
    nail_fold: Flag = True
    nail_fold_g: Numbers = field(default_factory=lambda: list(NAIL_FOLD_RELAXATION.g))
    nail_fold_tau_s: Numbers = field(default_factory=lambda: list(NAIL_FOLD_RELAXATION.tau))

    def __post_init__(self) -> None:  # each series checked, switched on or not
        self.prony()
        self.tangential()
        self.nail_fold_prony()

    def prony(self) -> PronySeries:
        return _prony(self.g, self.tau_s, ("g", "tau_s"))

    def tangential(self) -> PronySeries | None:
        """The pad's relaxation under tangential load; None when switched off (the pad's own)."""
        prony = _prony(self.tangential_g, self.tangential_tau_s, ("tangential_g", "tangential_tau_s"))
        return prony if self.tangential_creep else None

    def nail_fold_prony(self) -> PronySeries | None:
        """The relaxation of the tissue under the chip; None when switched off (the pad's own)."""
        prony = _prony(self.nail_fold_g, self.nail_fold_tau_s, ("nail_fold_g", "nail_fold_tau_s"))
        return prony if self.nail_fold else None


@dataclass(frozen=True)
class WearableDevice:
    """What the wearable protocol records with: the ring holding the chip, and the table sensor."""

    name: str
    side: str
    offset_mm: float
    preload_N: float

    @classmethod
    def from_parameters(cls, p: WearableParameters) -> "WearableDevice":
        return cls(name=f"nail-ring-{p.sensor_side}", side=p.sensor_side, offset_mm=p.sensor_offset_mm,
                   preload_N=p.ring_preload_N)

    @property
    def spec(self) -> dict:
        return {"name": self.name, "side": self.side, "sensor_offset_mm": self.offset_mm,
                "ring_preload_N": self.preload_N}


@dataclass
class WearableBench(SeededBench):
    """What the wearable protocol needs: the tissue's relaxations, the realism and a seeded stream."""

    realism: WearableRealism
    tangential: PronySeries | None = None  # the pad's under tangential load (None: ``prony``)
    nail_fold: PronySeries | None = None  # the tissue's under the chip (None: ``prony``)


def wearable(bench: WearableBench, p: WearableParameters, seed: int, record: dict) -> Dataset:
    """S2's calibration protocol: participants x runs x (contacts x motions) trials, one dataset."""
    realism, rng = bench.realism, bench.rng
    device = WearableDevice.from_parameters(p)
    writer = TrialWriter(CHANNELS, LABELS, CONDITIONS, DatasetMetadata(
        description="wearable fingertip force: side-of-nail chip and table force sensor", design=device.spec,
        sensor_settings={"chip": CHIP.to_dict(), "table": TABLE_SENSOR.to_dict()}, protocol=record, seed=seed))
    times = np.arange(-p.lead_in_s * p.simulation_rate_hz, p.trial_s * p.simulation_rate_hz + 1) \
        / p.simulation_rate_hz
    instants = np.arange(round(p.trial_s * p.rate_hz)) / p.rate_hz
    trials = [(motion, contact) for contact in p.contacts for motion in p.motions]
    radii = np.array([shape_radii(contact, p.curved_radius_mm * MM, p.edge_radius_mm * MM,
                                   p.point_radius_mm * MM) for _, contact in trials])
    nominal = FingerPad(width=p.finger_width_mm * MM, stiffness=p.pad_stiffness_N_per_mm / MM,
                        stiffening=p.pad_stiffening_per_mm / MM, friction=p.friction,
                        transmission=p.nail_fold_transmission, lateral_drag=p.lateral_drag,
                        joint_stiffness=p.dip_lateral_stiffness_Nm_per_rad if p.dip_joint else None, prony=bench.prony,
                        shear_prony=bench.tangential)
    effort = Effort(press_peak=p.press_peak_N, rest=p.rest_N, dorsal_hold=p.dorsal_hold_N,
                    tilt_normal=p.tilt_normal_N, tangential_effort=p.tangential_effort,
                    friction_sense=p.friction, normal_coupling=p.normal_coupling,
                    cross_talk=realism.cross_talk, tremor=realism.force_tremor)
    for participant in range(p.participants):
        finger = scaled(nominal, (p.finger_width_mm + bench.scatter(realism.finger_width_sd_mm)) * MM,
                        math.exp(bench.scatter(realism.pad_stiffness_sd)),
                        max(p.friction + bench.scatter(realism.friction_sd), 0.3))
        for run in range(p.runs):
            mount = ChipMount(side=p.sensor_side,
                              position_y=(p.sensor_offset_mm + bench.scatter(realism.sensor_position_sd_mm)) * MM,
                              # drawn even at 0, as the placement below
                              preload=max(p.ring_preload_N * (1 + rng.normal() * realism.ring_preload_sd), 0.0),
                              tissue_prony=bench.nail_fold)
            noise = rng if realism.noise else None
            air = CHIP.acquire(np.array([0.0, 0.0, mount.preload]), noise).values[2]
            skew = rng.uniform(-1, 1) * realism.stream_skew_ms / 1000  # s
            intended = np.stack([intended_force(motion, times, p.trial_s, rng, effort) for motion, _ in trials],
                                axis=1)
            # drawn even at 0 so that switching the placement scatter off leaves every other draw as it was
            rest = rng.normal(0.0, 1.0, (len(trials), 2)) * realism.placement_sd_mm * MM
            yaw = np.radians(bench.scatter(realism.finger_yaw_sd_deg, len(trials)))
            twin = WearableTwin(finger, mount)
            response = twin.respond(times, intended, radii, rest, p.lean_share)
            read = twin.read(times, response, instants, noise, skew, yaw)
            for k, (motion, contact) in enumerate(trials):
                chip, table = read.chip[:, k], read.table[:, k]
                writer.add({"time_s": instants,
                            **FORCE.columns(chip[:, None, :] - chip[0]),
                            **{f"f{axis}_N": table[:, a] - table[0, a] for a, axis in enumerate(AXES)},
                            "cop_x_mm": read.centre[:, k, 0] / MM, "cop_y_mm": read.centre[:, k, 1] / MM,
                            "sliding": read.sliding[:, k]},
                           {"participant": participant, "run": run, "motion": motion, "contact": contact,
                            "side_air_fz_N": air,
                            **{f"side_tare_f{axis}_N": chip[0, a] for a, axis in enumerate(AXES)},
                            **{f"table_tare_f{axis}_N": table[0, a] for a, axis in enumerate(AXES)}})
    return writer.to_dataset()


_WearableProtocolFile = protocol_file_schema(WearableRealism, PadViscoelastic)


def _device(file: _WearableProtocolFile, parameters: WearableParameters, source: str,
            base: Path | None) -> WearableDevice:
    return WearableDevice.from_parameters(parameters)


def _bench(protocol: Protocol, progress: Progress, timings: dict) -> tuple[WearableBench, dict, str]:
    """The finger tissue's relaxations, given by the ``[viscoelastic]`` table."""
    p, tissue = protocol.parameters, protocol.viscoelastic
    bench = WearableBench(prony=tissue.prony(), realism=protocol.realism, rng=np.random.default_rng(protocol.seed),
                          rate_hz=p.rate_hz, tangential=tissue.tangential(), nail_fold=tissue.nail_fold_prony())
    return bench, {}, f"{protocol.name}: {p.participants} participants x {p.runs} runs on {protocol.design.name}"


# about ten minutes of trials on a 2-core machine (13 µs a simulated sample), 400 x the shipped protocol
SIMULATED_SAMPLES_LIMIT = 5e7


def _size(protocol: str, p: WearableParameters) -> Size:
    trials = p.participants * p.runs * len(p.motions) * len(p.contacts)
    return Size(trials * (p.lead_in_s + p.trial_s) * p.simulation_rate_hz, SIMULATED_SAMPLES_LIMIT,
                "simulated samples",
                "participants x runs x motions x contacts x (lead_in_s + trial_s) x simulation_rate_hz")


BENCH = BenchKind(
    protocol_file=_WearableProtocolFile, parameters={"wearable": WearableParameters}, runners={"wearable": wearable},
    device=_device, setup=_bench, realism_sources=REALISM_SOURCES,
    viscoelastic_sources={
        "g": "assumed weights (softtip.systems.wearable.fingerpad)",
        "tau_s": "time constants of Pawluk & Howe 1999 (softtip.systems.wearable.fingerpad)",
        "tangential_creep": "the pad relaxes under tangential load on its own time scale (Pataky et al. 2005); "
                            "off: as pressed",
        "tangential_g": "assumed: half of the tangential force relaxes",
        "tangential_tau_s": "a decade apart up to the 11.8 s of Pataky, Latash & Zatsiorsky, J. Biomech. 38, 2005",
        "nail_fold": "the chip presses skin over the nail's edge, which relaxes faster than the pulp; off: as the "
                     "pulp",
        "nail_fold_g": "skin in compression relaxes to 0.28-0.47 (Wang et al., PLoS ONE 10, 2015, mouse skin): "
                       "0.4 kept",
        "nail_fold_tau_s": "skin's relaxation time in compression, about 0.2 s (Wang et al. 2015)"},
    size=_size)
