"""The size of each cause of drift between sessions, on the twin, and what a session correction recovers.

One fabricated unit (one seed) runs the 3-axis force protocol (``force3``) in its calibration session
and again in later sessions, each with one cause of drift on at a stated size (:data:`CAUSES`; the
realism module says where each number comes from). The unit, the trials and the noise are the same
in every session, so two sessions differ by the drift alone. For each cause:

* the change of the readings: the RMS of (later - calibration) over the RMS of the calibration
  session's readings, sample by sample (the re-zero at the start of each trial has taken out every
  offset, so this is what a re-zero cannot correct);
* the force error of the calibration session's network (3-10-3, Levenberg-Marquardt) on the later
  session's validation trials, beside its error in its own session;
* what a session correction leaves of it: the later session re-calibrated from its first 5 presses
  (:func:`softtip.calibration.session.session_curve`, one gain per channel: design D has one chip)
  and scored on the rows after them.

With every cause on at once, the later session is re-calibrated from its first 0..5 presses the same
way, and by an affine map of the chip's readings (:class:`~softtip.calibration.session.SessionAffine`,
a matrix and an offset regularised toward the identity), and scored on its later trials. Its presses
(here and for each cause) are taken in turn from each motion (normal, shear along x, along y,
normal, ...), as a user re-calibrating presses in each direction; the protocol runs them motion by
motion.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from softtip._core.progress import SILENT, Progress
from softtip.calibration import LMNetwork
from softtip.calibration.session import gain_groups, session_curve
from softtip.data.splits import by_role
from softtip.lab import load_protocol, run_protocol

TARGETS = ("fx_N", "fy_N", "fz_N")
# Each cause at a size a lab meets between sessions (the realism module gives the sources).
CAUSES = {
    "magnets 10 K warmer": {"session_temperature_K": 10.0},
    "magnets and chips 10 K warmer": {"session_temperature_K": 10.0, "chip_temperature_drift": True},
    "elastomer 10 % stiffer (aging)": {"modulus_change": 0.10},
    "0.1 mm compression set (creep)": {"compression_set_mm": 0.1},
    "steel plate 3 mm below the chips": {"iron_plate_gap_mm": 3.0},
}
ALL_CAUSES = "all of them"
PRESSES = 5
QUICK = {"calibration_trials": 3, "validation_trials": 1}  # 12 presses: 5 to re-calibrate from, 7 to score


@dataclass(frozen=True)
class CauseSize:
    """One cause's effect: ``reading_change`` (RMS, fraction of the calibration session's RMS), the
    calibration model's force RMSE (N, per axis of :data:`TARGETS`) on the later session, and its RMSE
    after the session correction from :data:`PRESSES` presses (on the rows after them)."""

    name: str
    settings: dict
    reading_change: float
    force_rmse_N: tuple[float, ...]
    corrected_rmse_N: tuple[float, ...]


@dataclass(frozen=True)
class DriftStudy:
    seed: int
    quick: bool
    calibration_rmse_N: tuple[float, ...]
    causes: tuple[CauseSize, ...]
    presses_rmse_N: np.ndarray  # (PRESSES + 1, 3): the session with every cause, after 0..5 presses
    affine_presses_rmse_N: np.ndarray  # the same, corrected by an affine map of the readings
    zero_rmse_N: np.ndarray
    scored_rows: int

    def to_dict(self) -> dict:
        return {"seed": self.seed, "quick": self.quick, "targets": list(TARGETS),
                "calibration_session_rmse_N": list(self.calibration_rmse_N),
                "causes": [{"cause": c.name, "realism": c.settings, "reading_change_percent": 100 * c.reading_change,
                            "force_rmse_N": list(c.force_rmse_N),
                            f"after_{PRESSES}_presses_rmse_N": list(c.corrected_rmse_N)} for c in self.causes],
                "session_correction": {"causes": ALL_CAUSES, "scored_rows": self.scored_rows,
                                       "zero_rmse_N": self.zero_rmse_N.tolist(),
                                       "rmse_N_by_presses": [{"presses": k, "rmse_N": row.tolist()}
                                                             for k, row in enumerate(self.presses_rmse_N)],
                                       "affine_rmse_N_by_presses": [{"presses": k, "rmse_N": row.tolist()} for k, row
                                                                    in enumerate(self.affine_presses_rmse_N)]}}


def in_turn(data) -> np.ndarray:
    """The rows of a dataset with its trials taken in turn from each motion: the first trial of each
    motion, then the second of each, ... (motions in the order they first appear)."""
    trials, first = np.unique(data.groups, return_index=True)
    motion = np.asarray(data.column("motion"))[first]
    motions = list(dict.fromkeys(motion[np.argsort(first)]))
    occurrence = np.array([np.count_nonzero(motion[first < f] == m) for f, m in zip(first, motion, strict=True)])
    order = trials[np.lexsort(([motions.index(m) for m in motion], occurrence))]
    return np.concatenate([np.flatnonzero(data.groups == trial) for trial in order])


def _rmse(model, X: np.ndarray, y: np.ndarray) -> tuple[float, ...]:
    return tuple(np.sqrt(np.mean((model.predict(X) - y) ** 2, axis=0)).tolist())


def drift_study(seed: int = 1, quick: bool = False, progress: Progress = SILENT) -> DriftStudy:
    """The study of the module notes for the fabricated unit of ``seed``; ``quick``: 4 trials per motion."""
    protocol = load_protocol("force3").changed(seed=seed, **(QUICK if quick else {}))
    sessions = {**CAUSES, ALL_CAUSES: {key: value for cause in CAUSES.values() for key, value in cause.items()}}

    def session(settings: dict):
        dataset, _ = run_protocol(replace(protocol, realism=replace(protocol.realism, **settings)), progress)
        return dataset.X(), np.column_stack([dataset.column(t) for t in TARGETS]), dataset

    X0, y0, calibration_data = session({})
    calibration, validation = by_role(calibration_data)
    model = LMNetwork((10,), random_state=seed).fit(X0[calibration], y0[calibration],
                                                    groups=calibration_data.groups[calibration])
    causes = []
    for name, settings in sessions.items():
        X, y, data = session(settings)
        rows = in_turn(data)
        above = 0.1 * np.abs(y).max()
        curve = session_curve(model, X[rows], y[rows], data.groups[rows], presses=PRESSES, above=above,
                              groups=gain_groups(list(data.channels), "channel"))
        if name == ALL_CAUSES:
            affine = session_curve(model, X[rows], y[rows], data.groups[rows], presses=PRESSES, above=above,
                                   groups=gain_groups(list(data.channels), "chip"), affine=True)
            continue
        change = float(np.sqrt(np.mean((X - X0) ** 2) / np.mean(X0**2)))
        causes.append(CauseSize(name, settings, change, _rmse(model, X[validation], y[validation]),
                                tuple(curve.rmse[-1].tolist())))
    return DriftStudy(seed, quick, _rmse(model, X0[validation], y0[validation]), tuple(causes), curve.rmse,
                      affine.rmse, curve.zero_rmse, curve.scored_rows)


def plot_drift(study: DriftStudy, path) -> None:
    """Each cause's change of the readings and force error, and the correction's error against presses."""
    from matplotlib.figure import Figure

    from softtip._core.files import save_figure

    figure = Figure(figsize=(14, 4.2), layout="constrained")
    change, error, curve = figure.subplots(1, 3, width_ratios=(1.2, 1, 1))
    names = [c.name for c in study.causes]
    rows = np.arange(len(names))
    change.barh(rows, [100 * c.reading_change for c in study.causes], color="tab:gray")
    change.set_yticks(rows, names, fontsize="small")
    change.invert_yaxis()
    change.set_xlabel("readings' change, RMS (% of the readings)")
    change.set_title("Each cause alone: a later session of the same unit", fontsize="medium")
    width = 0.8 / len(TARGETS)
    for k, axis in enumerate(TARGETS):
        bars = error.barh(rows + (k - 1) * width, [c.force_rmse_N[k] for c in study.causes], width, label=axis)
        error.axvline(study.calibration_rmse_N[k], color=bars.patches[0].get_facecolor(), ls=":")
    error.set_yticks(rows, [])
    error.invert_yaxis()
    error.set_xlabel("force RMSE (N); dotted: in its own session")
    error.legend(fontsize="small")
    error.set_title("The calibration session's network on it", fontsize="medium")
    presses = np.arange(len(study.presses_rmse_N))
    for k, axis in enumerate(TARGETS):
        line, = curve.plot(presses, study.presses_rmse_N[:, k], "o-", label=f"{axis}: gains")
        curve.plot(presses, study.affine_presses_rmse_N[:, k], "s--", color=line.get_color(), label=f"{axis}: affine")
    curve.axhline(float(np.mean(study.zero_rmse_N)), color="k", ls=":", label="predicting zero (mean of axes)")
    curve.set_xticks(presses)
    curve.set_xlabel("presses of the later session used")
    curve.set_ylabel("force RMSE (N)")
    curve.set_ylim(bottom=0)
    curve.legend(fontsize="small", loc="upper right")
    curve.set_title("Every cause at once, re-calibrated", fontsize="medium")
    save_figure(figure, path, dpi=110)
