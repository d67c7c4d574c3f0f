"""Per-output scores of a model's outputs against measured ones, with full scale stated.

For every output: R² (1 - SS_res/SS_tot), Pearson r, RMSE and MAE in the output's unit and in %
of full scale, and MATLAB's normalised-RMSE fit, ``fit % = 100 (1 - ||y - ŷ|| / ||y - mean(y)||)``
(``compare``'s figure; it equals 100 (1 - sqrt(1 - R²))). The samples scored are the scored
samples of every trial, pooled.

Full scale (the published work leaves it undefined) is :data:`MEASURED` by default: the range
max - min of each output in the data scored; or :func:`rated`: ranges the user gives (a sensor's
rated range). Every result carries which one was used.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from softtip.metrics import mae_percent_fs, mean_abs_error, pearson_r, r2, rmse, rmse_percent_fs
from softtip.sysid.statespace import IdentificationError


@dataclass(frozen=True)
class FullScale:
    """What 100 % of an output is: ``"measured"`` (its range in the data scored) or ``"rated"`` (``values``)."""

    definition: str
    values: tuple[float, ...] = ()

    def __post_init__(self):
        if self.definition not in ("measured", "rated"):
            raise IdentificationError(f"full scale: expected 'measured' or 'rated', got {self.definition!r}")
        values = tuple(float(v) for v in self.values)
        if (self.definition == "rated") != bool(values):
            raise IdentificationError("full scale: a rated full scale needs its values, a measured one takes none")
        if not all(np.isfinite(v) and v > 0 for v in values):
            raise IdentificationError(f"full scale: rated ranges must be positive numbers, got {list(values)}")
        object.__setattr__(self, "values", values)

    @property
    def description(self) -> str:
        if self.definition == "measured":
            return "measured range (max - min) of each output in the data scored"
        return "rated range given by the user"

    def ranges(self, y: np.ndarray, outputs: Sequence[str]) -> np.ndarray:
        if self.definition == "rated":
            if len(self.values) not in (1, len(outputs)):
                raise IdentificationError(f"full scale: {len(self.values)} rated ranges for {len(outputs)} outputs "
                                          f"({', '.join(outputs)})")
            return np.broadcast_to(np.asarray(self.values), (len(outputs),)).copy()
        ranges = np.ptp(y, axis=0)
        flat = np.flatnonzero(ranges == 0)
        if flat.size:
            raise IdentificationError(f"output {outputs[flat[0]]!r} is constant in the data scored: its measured "
                                      "range is 0, so % of full scale is undefined (give a rated full scale)")
        return ranges


MEASURED = FullScale("measured")


def rated(values: float | Sequence[float]) -> FullScale:
    """A rated full scale: one range for every output, or one per output, in the outputs' units."""
    return FullScale("rated", (values,) if np.ndim(values) == 0 else tuple(values))


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """MATLAB's NRMSE fit per output: 100 (1 - ||y - ŷ|| / ||y - mean(y)||); NaN for a constant output."""
    y, yhat = np.asarray(y, dtype=np.float64), np.asarray(yhat, dtype=np.float64)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spread > 0, 100.0 * (1.0 - np.linalg.norm(y - yhat, axis=0) / spread), np.nan)


@dataclass(frozen=True)
class Scores:
    """Per-output scores, the full scale they were normalised by, and the initial state the model ran from
    ("zero": from rest; "estimated": each trial's best initial state)."""

    outputs: tuple[str, ...]
    units: tuple[str, ...]
    values: dict[str, np.ndarray]  # metric name -> one value per output
    full_scale: FullScale
    full_scale_values: np.ndarray
    samples: int
    initial_state: str = "zero"

    METRICS = ("r2", "r", "rmse", "mae", "rmse_fs_percent", "mae_fs_percent", "fit_percent")

    def to_dict(self) -> dict:
        """JSON-able: per output its metrics, unit and full scale; the full-scale definition; the sample count."""
        per_output = {}
        for k, name in enumerate(self.outputs):
            row = {metric: _number(self.values[metric][k]) for metric in self.METRICS}
            per_output[name] = row | {"unit": self.units[k], "full_scale": float(self.full_scale_values[k])}
        return {"outputs": per_output, "full_scale": {"definition": self.full_scale.definition,
                                                       "description": self.full_scale.description},
                "samples": self.samples, "initial_state": self.initial_state}

    def mean(self, metric: str) -> float:
        return float(np.mean(self.values[metric]))


def _number(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def score_outputs(y: np.ndarray, yhat: np.ndarray, outputs: Sequence[str], units: Sequence[str],
                  full_scale: FullScale = MEASURED) -> Scores:
    """The scores of ``yhat`` against ``y`` (samples, outputs)."""
    y, yhat = np.asarray(y, dtype=np.float64), np.asarray(yhat, dtype=np.float64)
    if y.shape != yhat.shape or y.ndim != 2 or y.shape[1] != len(outputs) or not len(y):
        raise IdentificationError(f"scores: y and yhat must both be (samples, {len(outputs)}), "
                                  f"got {y.shape} and {yhat.shape}")
    ranges = full_scale.ranges(y, outputs)
    values = {"r2": r2(y, yhat), "r": pearson_r(y, yhat), "rmse": rmse(y, yhat), "mae": mean_abs_error(y, yhat),
              "rmse_fs_percent": rmse_percent_fs(y, yhat, ranges), "mae_fs_percent": mae_percent_fs(y, yhat, ranges),
              "fit_percent": fit_percent(y, yhat)}
    return Scores(tuple(outputs), tuple(units), {k: np.atleast_1d(v) for k, v in values.items()}, full_scale,
                  ranges, len(y))
