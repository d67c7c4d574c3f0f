"""The one registry of the published studies softtip reproduces: the lab protocol each runs,
the analysis that turns its datasets into the publication's figures, and what it follows.

Light to import (names only), so the command line lists the studies without loading the models;
:func:`softtip.studies.reproduce.reproduce_study` resolves the analysis when a study runs.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Study:
    name: str
    protocol: str  # the shipped lab protocol it runs (softtip lab run PROTOCOL)
    module: str  # the module of softtip.studies that analyses it
    analysis: str  # its function there
    follows: str  # what of the publication it reproduces


STUDIES: dict[str, Study] = {study.name: study for study in (
    Study("pushing", "pushing", "hall_fingertip", "pushing", "S1 §1: board orientation from one sensor, designs A-D, polynomial "
          "vs network"),
    Study("force3", "force3", "hall_fingertip", "force3", "S1 §1: 3-axis force calibration against a reference force sensor"),
    Study("hysteresis", "hysteresis", "hall_fingertip", "hysteresis", "S1 §1: load to 3 mm and unload, hysteresis and sensitivity"),
    Study("grasp-two", "grasp-two", "hall_fingertip", "grasp_two", "S1 §1: board orientation grasped between two fingertips"),
    Study("grasp-positions", "grasp-positions", "hall_fingertip", "grasp_positions",
          "S1 §2: orientation and grip force at 49 contact positions, trained and untrained"),
    Study("contact-states", "contact-states", "hall_fingertip", "contact_states", "S1 §2: contact states of a grasped thin board"),
    Study("inverter", "inverter", "hall_fingertip", "inverter", "S1 §2: contact states of the inverter assembly, detection force"),
)}
