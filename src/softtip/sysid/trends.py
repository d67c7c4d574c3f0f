"""Offsets and linear trends of a recording, estimated once and applied unchanged (MATLAB's ``TrendInfo``).

A linear model maps deviations to deviations: y - y0(t) = G (u - u0(t)). :func:`estimate_trend`
fits the levels on the *estimation* record, pooled over its trials: ``"mean"`` one constant per
channel (u0, y0), ``"linear"`` a line per channel, offset + slope t, t the time since the start of
the sample's source trial (what :meth:`Recording.time` gives; a validation piece cut from a trial
keeps its place on that line). The same :class:`Trend` is then removed from validation and live
data and added back to the model's outputs, so a saved model predicts in the recording's own units.
``"estimate"`` starts from the means and leaves the output levels to the model's identification,
which estimates them as parameters (:class:`~softtip.sysid.models.IdentifiedModel`): the input
levels stay the means, since only y0 - G(0) u0 can be told from data. (:meth:`Recording.detrend`,
by contrast, removes each trial's own mean or line: it needs the outputs, so a model cannot run
that way on live data.)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from softtip.sysid.recording import Recording
from softtip.sysid.statespace import IdentificationError

TREND_KINDS = ("none", "mean", "linear", "estimate")


@dataclass(frozen=True, eq=False)
class Trend:
    """Levels of every input and output at time t (s): offset + slope t; ``kind`` says how they were fitted."""

    kind: str
    input_offset: np.ndarray
    output_offset: np.ndarray
    input_slope: np.ndarray
    output_slope: np.ndarray

    def __post_init__(self):
        if self.kind not in TREND_KINDS:
            raise IdentificationError(f"detrend: expected one of {', '.join(TREND_KINDS)}, got {self.kind!r}")
        for name in ("input_offset", "output_offset", "input_slope", "output_slope"):
            values = np.array(getattr(self, name), dtype=np.float64, ndmin=1)
            if values.ndim != 1 or not np.all(np.isfinite(values)):
                raise IdentificationError(f"trend: {name}: expected a 1-D array of finite numbers")
            values.setflags(write=False)
            object.__setattr__(self, name, values)
        if self.input_offset.shape != self.input_slope.shape or self.output_offset.shape != self.output_slope.shape:
            raise IdentificationError("trend: offsets and slopes must have one value per channel")

    @classmethod
    def zero(cls, n_inputs: int, n_outputs: int) -> Trend:
        return cls("none", np.zeros(n_inputs), np.zeros(n_outputs), np.zeros(n_inputs), np.zeros(n_outputs))

    def inputs_at(self, t: np.ndarray) -> np.ndarray:
        """The input levels (len(t), nu) at the times ``t`` (s)."""
        return self.input_offset + np.multiply.outer(t, self.input_slope)

    def outputs_at(self, t: np.ndarray) -> np.ndarray:
        """The output levels (len(t), ny) at the times ``t`` (s)."""
        return self.output_offset + np.multiply.outer(t, self.output_slope)

    def remove(self, recording: Recording) -> Recording:
        """The recording's deviations from these levels (outputs too, when it has them)."""
        if self.kind == "none":
            return recording
        trials = []
        for k, trial in enumerate(recording.trials):
            t = recording.time(k)
            y = trial.y - self.outputs_at(t) if recording.outputs else trial.y
            trials.append(replace(trial, u=trial.u - self.inputs_at(t), y=y))
        return replace(recording, trials=tuple(trials))

    def restore(self, recording: Recording, deviations: list[np.ndarray]) -> list[np.ndarray]:
        """The model's output deviations of every trial of ``recording`` back in the output's units."""
        if self.kind == "none":
            return deviations
        return [values + self.outputs_at(recording.time(k)) for k, values in enumerate(deviations)]

    def to_dict(self) -> dict:
        return {"kind": self.kind} | {name: getattr(self, name).tolist() for name in
                                      ("input_offset", "output_offset", "input_slope", "output_slope")}

    @classmethod
    def from_dict(cls, fields: dict) -> Trend:
        return cls(**fields)


def estimate_trend(recording: Recording, kind: str) -> Trend:
    """The levels of ``recording`` (every trial pooled): ``"none"`` zero, ``"mean"`` the channels' means,
    ``"linear"`` each channel's least-squares line in the time since its source trial's start,
    ``"estimate"`` the means as the start of the output levels' estimation."""
    if kind not in TREND_KINDS:
        raise IdentificationError(f"detrend: expected one of {', '.join(TREND_KINDS)}, got {kind!r}")
    nu, ny = recording.n_inputs, recording.n_outputs
    if kind == "none":
        return Trend.zero(nu, ny)
    signals = np.vstack([np.hstack([trial.u, trial.y]) for trial in recording.trials])
    if kind in ("mean", "estimate"):
        offset, slope = signals.mean(axis=0), np.zeros(nu + ny)
    else:
        t = np.concatenate([recording.time(k) for k in range(len(recording.trials))])
        if np.ptp(t) == 0:
            raise IdentificationError(f"{recording.source}: detrend 'linear' needs samples at more than one time")
        # centred time keeps the 2 x 2 normal equations well conditioned
        centre = t.mean()
        slope = (t - centre) @ (signals - signals.mean(axis=0)) / np.sum((t - centre) ** 2)
        offset = signals.mean(axis=0) - slope * centre
    return Trend(kind, offset[:nu], offset[nu:], slope[:nu], slope[nu:])
