"""S4: a millimetre force sensor of magnetised elastic pillars (cilia) over a GMR die.

The chain, stage by stage (each in the shared toolkit where it is generic):

* ``layout`` — the die in a validated TOML file (``die.toml``: the declared layout, each choice
  commented; the published work shows it only in figures);
* ``model`` — force → pillars bent (``softtip.mechanics.rod``) → a chain of 10 tangent dipoles per pillar
  (``softtip.magnetics.dipoles``) → the in-plane field averaged exactly over every spin valve → the
  meander's voltage at 100 µA (``softtip.sensors.gmr``), in paper mode (a tip load perpendicular to the
  axis, as published) and balance mode (the die, tilted or not, lowered onto a balance plate that may
  turn: friction, buckling, lying down, the plate folding the lying pillars);
* ``fit`` — moment and diameter fitted to a force–voltage curve, with intervals, correlation, profile
  likelihoods and what the linear part identifies (only moment / diameter⁴);
* ``resolution`` — the smallest force resolved (3σ over the slope; the smallest distinguishable step)
  and the measurement range; the balance test's minimum force from its causes (balance, plate, meter,
  self-heating drift);
* ``study`` — :func:`~softtip.systems.cilia.study.run_study`, the whole force study as typed results and
  figures; ``roughness`` — brushing the four surfaces, and the roughness study and classifier of a dataset's
  brushings; ``design`` — the design search on the same die (``softtip cilia design``);
* ``bench`` — the lab's protocol ``cilia``: the twin's force–voltage curves (paper and balance modes, X and
  Y) and its brushings as a dataset; ``reproduce`` — ``softtip reproduce cilia``, the study of that dataset beside the
  published figures (``published.toml``); ``commands`` — ``softtip bench cilia``, ``softtip cilia design`` and
  ``softtip cilia roughness``.

Which sensor: the force experiments read X, whose strips sense the direction the pillars bend in and
which has the larger magnetoresistance and sensitivity; Y is reported beside it.

The readout at ~18 V: a 6½-digit meter reads it on its 100 V range, 100 µV per count at 10 power-line
cycles, and its computed noise floor (≈ 33 µV rms, mostly the count) sets a minimum force of ≈ 17 µN on
the declared die under a tip load; the balance test as performed resolves far less (its budget in
``resolution``). Microvolt signals (the published roughness traces) need the constant part taken off
before the meter — a bridge or a matched reference resistor (``offset_V`` in the die file) — which puts
the meter on its 0.1 V range (0.1 µV per count); the floor is then the sensor's own Johnson and 1/f noise.

Importing this package loads only its registration record (:data:`SYSTEM`).
"""

from softtip._core.systems import Study, System

SYSTEM = System(
    name="cilia",
    title="Magnetised elastic pillars over a GMR die: a millimetre force sensor",
    label="S4",
    package=__name__,
    benches={"cilia": "softtip.systems.cilia.bench:BENCH"},
    protocols={"cilia": "cilia"},
    studies=(
        Study("cilia", "cilia", "softtip.systems.cilia.reproduce:cilia",
              "S4: the publication's fit of the pillars' moment and diameter made again on the twin's balance "
              "test, the minimum force from its causes and the measurement range of a GMR cilia sensor",
              # --quick: a coarse protocol (fewer load steps, short brushings on two strips, a coarse design
              # search, the moment gap's causes and the rig's sweep left out) on top of the two trials
              quick={"points": 15, "gap_causes": False, "rig_tilts_deg": (), "rig_plate_stiffnesses_uNm": (), "depths_um": (20.0,), "meander_scales": (1.1,), "brush_length_mm": 6.0,
                     "brush_strips": 2, "brush_rates_hz": (2.0, 20.0, 50.0), "brush_speeds_mm_s": (0.5, 2.0), "design_steps": 3,
                     "design_budget": 6, "design_points": 9}),
    ),
    bench_commands={"cilia": "softtip.systems.cilia.commands:bench_cilia"},
    commands={"cilia": "softtip.systems.cilia.commands:app"},
)
