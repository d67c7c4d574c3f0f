"""A researcher's own force–voltage curve fitted with both models (``softtip cilia fit CURVE.csv``).

* **The publication's model**: uniform cylinders of the fitted diameter, clamped to the die
  (:func:`softtip.systems.cilia.layout.uniform_clamped`), each loaded at its tip perpendicular to its axis;
  height and Young's modulus held, moment and diameter free, as the publication fitted its balance curve.
* **softtip's model**: the die file's pillars as they are (tapered, on their film), the same load; moment and
  tip diameter free, the taper kept.

Both by :func:`softtip.systems.cilia.fit.fit_curve` (least squares in log parameters, 95 % intervals with
Student's t), on the die file's layout and readout.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from softtip._core.progress import SILENT, Progress
from softtip._core.units import MN, UM
from softtip.systems.cilia.fit import CurveFit, MeasuredCurve, fit_curve
from softtip.systems.cilia.layout import MEMU, SHIPPED_DIE, read_die, uniform_clamped
from softtip.systems.cilia.model import CiliaModel

MODELS = ("publication's model: uniform clamped cylinder", "softtip's model: the die file's pillars")


@dataclass(frozen=True)
class BothFits:
    """The measured ``curve`` and its fit by each of :data:`MODELS`, in that order."""

    curve: MeasuredCurve
    fits: tuple[CurveFit, CurveFit]

    def to_dict(self) -> dict:
        def entry(fit: CurveFit) -> dict:
            return {"moment_memu": fit.moment / MEMU, "moment_interval_memu": [v / MEMU for v in fit.interval_moment],
                    "diameter_um": fit.diameter / UM, "diameter_interval_um": [v / UM for v in fit.interval_diameter],
                    "correlation": fit.correlation, "residual_rms_uV": fit.noise * 1e6, "at_bound": fit.at_bound,
                    "evaluations": fit.evaluations}

        return {"fits": {name: entry(fit) for name, fit in zip(MODELS, self.fits)}}

    def figure(self) -> Figure:
        figure = Figure(figsize=(6.4, 4.2), layout="constrained")
        axes = figure.add_subplot()
        order = np.argsort(self.curve.force)
        axes.plot(self.curve.force / MN, self.curve.change * 1e6, "o", ms=3, color="k", label="measured")
        for index, (name, fit) in enumerate(zip(MODELS, self.fits)):
            axes.plot(self.curve.force[order] / MN, fit.prediction[order] * 1e6, "-", color=f"C{index}",
                      label=f"{name}: {fit.moment / MEMU:.3g} memu, {fit.diameter / UM:.0f} µm")
        axes.set_xlabel("force (mN)")
        axes.set_ylabel(f"voltage change, sensor {self.curve.sensor} (µV)")
        axes.legend(fontsize=7)
        return figure


def fit_both(die: Path | None, curve: MeasuredCurve, progress: Progress = SILENT) -> BothFits:
    """``curve`` fitted by both models on the die file ``die`` (default: the shipped one), each started from
    the die file's moment and tip diameter."""
    layout = read_die(die or SHIPPED_DIE)
    start = (abs(layout.pillars.moment), layout.pillars.rod.tip_diameter)
    fits = []
    with progress.task("cilia fit: both models", total=2) as task:
        for model in (CiliaModel(uniform_clamped(layout)), CiliaModel(layout)):
            fits.append(fit_curve(model, curve, start))
            task.advance()
    return BothFits(curve, (fits[0], fits[1]))
