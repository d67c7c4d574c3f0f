"""The emulated Hall fingertip live: the force-calibration pushes on one fingertip, and the inverter lid
on two, each with the models trained on its protocol - computed once and kept in the cache."""

from __future__ import annotations

import functools

from softtip._core.cache import EntryPieces, read_entry, write_entry
from softtip._core.progress import SILENT, Progress
from softtip.lab import Protocol, load_protocol
from softtip.lab.protocols import protocol_key, trained_model_path
from softtip.realtime.scenario import LiveScenario, StreamCheck, accept_any_stream
from softtip.systems.hall_fingertip.scenarios import TwinScenario, insertion_scenario as compute_insertion
from softtip.systems.hall_fingertip.force_model import calibrate_force_model
from softtip.systems.hall_fingertip.scenarios import pushing_scenario


def cached_scenario(protocol: Protocol, name: str, compute, progress: Progress = SILENT) -> TwinScenario:
    """The twin's scenario ``name`` of ``protocol``, from the cache or computed (``compute(protocol, seed,
    progress=progress, pieces=pieces)``) and cached; a computation stopped part way (Ctrl-C, SIGTERM) keeps
    the pieces it finished, and the next one computes only the rest."""
    path, key, kind = trained_model_path(protocol, f"scenario-{name}"), protocol_key(protocol), f"{name} scenario"
    entry = read_entry(path, key, kind)
    if entry is not None:
        arrays = entry[1]
        return TwinScenario(times_s=arrays["times_s"], field_uT=arrays["field_uT"], force_N=arrays["force_N"])
    pieces = EntryPieces(path, key, kind)  # its finished motions, kept if it is stopped part way
    with progress.task(f"computing the twin's {name} scenario (kept in the cache)"):
        scenario = compute(protocol, protocol.seed, progress=progress, pieces=pieces)
    if write_entry(path, key, kind, {},
                   {"times_s": scenario.times_s, "field_uT": scenario.field_uT, "force_N": scenario.force_N}):
        pieces.clear()
    return scenario


PUSH_SPEED_MM_S = 2.0  # the three motions loop in about 17 s; the force calibration pushes at this speed too


def live_pushes(protocol: Protocol, progress: Progress = SILENT) -> TwinScenario:
    """The force-calibration motions of ``protocol`` at :data:`PUSH_SPEED_MM_S`, in a loop: what the main
    demo streams and the ``push`` scenario plays, one cache entry for both."""
    return cached_scenario(protocol, "push", functools.partial(pushing_scenario, speed_mm_s=PUSH_SPEED_MM_S),
                           progress)


def push_scenario(progress: Progress = SILENT, check: StreamCheck = accept_any_stream) -> LiveScenario:
    """One fingertip (design D): a normal push, a push then shear along x, along y, in a loop (the main
    demo's), with the 3-axis force network trained on the force-calibration cycles."""
    protocol = load_protocol("force-cycles")
    check(len(protocol.design.sensor_positions), None)
    scenario = live_pushes(protocol, progress)
    with progress.task("the force network trained on the twin (kept in the cache)"):
        model = calibrate_force_model(protocol.seed, progress, reuse=True)[0]
    return LiveScenario("the twin's pushes and shears on one fingertip", "emulator", (model,),
                        chips=scenario.field_uT.shape[1], emulator_source=scenario,
                        settings=protocol.design.chip_settings)


def insertion_scenario(progress: Progress = SILENT, check: StreamCheck = accept_any_stream) -> LiveScenario:
    """Two fingertips holding the inverter lid, lowered into its body once per case, with the
    contact-state and force networks trained on the inverter protocol."""
    from softtip.systems.hall_fingertip.insertion import trained_model_files

    protocol = load_protocol("inverter")
    check(2 * len(protocol.design.sensor_positions), None)  # both fingertips' chips
    scenario = cached_scenario(protocol, "insertion", compute_insertion, progress)
    with progress.task("the contact-state and force networks trained on the twin (kept in the cache)"):
        models = tuple(trained_model_files(protocol, progress))
    return LiveScenario("the inverter lid between two fingertips, seated and on either clip", "emulator", models,
                        chips=scenario.field_uT.shape[1], emulator_source=scenario,
                        settings=protocol.design.chip_settings)
