"""The one registry of the published studies softtip reproduces: the lab protocol each runs,
the analysis that turns its datasets into the publication's figures, and what it follows.

Light to import (names only), so the command line lists the studies without loading the models;
:func:`softtip.studies.published.run_published_study` resolves the analysis when a study runs.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Study:
    name: str
    protocol: str  # the shipped lab protocol it runs (softtip lab run PROTOCOL)
    analysis: str  # the function of softtip.studies.published that analyses it
    follows: str  # what of the publication it reproduces


STUDIES: dict[str, Study] = {study.name: study for study in (
    Study("pushing", "pushing", "pushing", "S1 §1: board orientation from one sensor, designs A-D, polynomial "
          "vs network"),
    Study("force3", "force3", "force3", "S1 §1: 3-axis force calibration against a reference force sensor"),
    Study("hysteresis", "hysteresis", "hysteresis", "S1 §1: load to 3 mm and unload, hysteresis and sensitivity"),
    Study("grasp-two", "grasp-two", "grasp_two", "S1 §1: board orientation grasped between two fingertips"),
    Study("grasp-positions", "grasp-positions", "grasp_positions",
          "S1 §2: orientation and grip force at 49 contact positions, trained and untrained"),
    Study("contact-states", "contact-states", "contact_states", "S1 §2: contact states of a grasped thin board"),
    Study("inverter", "inverter", "inverter", "S1 §2: contact states of the inverter assembly, detection force"),
)}
