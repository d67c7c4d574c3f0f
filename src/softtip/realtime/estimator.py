"""Calibration models in the live path: a frame's change of flux density to the model's targets."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from softtip._core.channels import channel_index

INPUT_UNITS_PER_UT = {"uT": 1.0, "µT": 1.0, "mT": 1e-3, "T": 1e-6}


class Estimator:
    """A calibration model in the live path.

    ``model``: any object with ``predict(X)`` (X of shape (1, n_inputs)); its
    ``predict_one(x)`` (x 1-D float64) is used when present. ``input_channels``: the
    channel of each input, e.g. ``s0_bx_uT``; ``input_units``: their unit (µT as stored
    in datasets, or mT, T). ``kind``: ``"regression"`` (``target_names`` and
    ``target_units`` required) or ``"classifier"`` (the predicted label is the contact
    state; ``classes`` from the model's ``classes_``); ``"auto"``: a classifier when the
    model has ``classes_``.
    """

    def __init__(self, model: Any, input_channels: Sequence[str], *, target_names: Sequence[str] | None = None,
                 target_units: str | Sequence[str] | None = None, input_units: str | Sequence[str] = "uT",
                 kind: str = "auto", name: str = "model") -> None:
        if not callable(getattr(model, "predict", None)):
            raise ValueError(f"model {name}: expected an object with a predict(X) method, got {type(model).__name__}")
        self.name = name
        self.model = model
        self.input_channels = tuple(input_channels)
        if not self.input_channels:
            raise ValueError(f"model {name}: input_channels is empty")
        self.input_index = np.array([channel_index(c) for c in self.input_channels], dtype=np.intp)
        units = [input_units] * len(self.input_channels) if isinstance(input_units, str) else list(input_units)
        if len(units) != len(self.input_channels):
            raise ValueError(f"model {name}: {len(units)} input units for {len(self.input_channels)} input channels")
        unknown = sorted({u for u in units if u not in INPUT_UNITS_PER_UT})
        if unknown:
            raise ValueError(f"model {name}: input unit {unknown[0]!r} is not one of {', '.join(INPUT_UNITS_PER_UT)}")
        scale = np.array([INPUT_UNITS_PER_UT[u] for u in units])
        self._scale = None if np.all(scale == 1.0) else scale
        self.chips_needed = int(self.input_index.max()) // 3 + 1
        if kind == "auto":
            kind = "classifier" if hasattr(model, "classes_") else "regression"
        if kind == "classifier":
            self.classes = tuple(str(c) for c in getattr(model, "classes_", ()))
            self.target_names: tuple[str, ...] = ("contact_state",)
            self.target_units: tuple[str, ...] = ("1",)
        elif kind == "regression":
            self.classes = None
            if target_names is None or target_units is None:
                raise ValueError(f"model {name}: a regression model needs target_names and target_units")
            self.target_names = tuple(target_names)
            self.target_units = ((target_units,) * len(self.target_names) if isinstance(target_units, str)
                                 else tuple(target_units))
            if len(self.target_units) != len(self.target_names) or not self.target_names:
                raise ValueError(f"model {name}: expected one unit per target, got {len(self.target_names)} targets "
                                 f"and {len(self.target_units)} units")
        else:
            raise ValueError(f"kind = {kind!r}: expected 'regression', 'classifier' or 'auto'")
        self.kind = kind
        # Inputs that are the first channels in storage order are a slice: a view, no copy.
        self._leading_inputs = np.array_equal(self.input_index, np.arange(len(self.input_index)))
        predict_one = getattr(model, "predict_one", None)
        self._predict_one = predict_one if callable(predict_one) else self._predict_via_batch

    @classmethod
    def from_file(cls, path: str | Path) -> Estimator:
        """A model saved by :func:`softtip.calibration.save_model`, with its channels and targets."""
        from softtip.calibration.persistence import load_model

        model, meta = load_model(path)
        return cls(model, meta.input_channels, target_names=meta.target_names, target_units=meta.target_units,
                   input_units=meta.input_units, name=Path(path).name)

    def _predict_via_batch(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.model.predict(x[None, :]))[0]

    def inputs(self, change_flat: np.ndarray) -> np.ndarray:
        """The model's input vector from a frame's flattened change (µT)."""
        x = change_flat[:len(self.input_index)] if self._leading_inputs else change_flat[self.input_index]
        return x if self._scale is None else x * self._scale

    def estimate(self, change_flat: np.ndarray) -> np.ndarray | str:
        """Target values (regression, 1-D float64) or the contact state (classifier)."""
        output = self._predict_one(self.inputs(change_flat))
        if self.kind == "classifier":
            return str(output)
        # the real-time models already return a 1-D float64 array: no conversion for them
        values = output if type(output) is np.ndarray and output.dtype == np.float64 and output.ndim == 1 else (
            np.asarray(output, dtype=np.float64).reshape(-1))
        if len(values) != len(self.target_names):
            raise ValueError(f"model {self.name}: {values.size} outputs for {len(self.target_names)} target names")
        return values

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "model": type(self.model).__name__,
                "input_channels": list(self.input_channels), "target_names": list(self.target_names),
                "target_units": list(self.target_units), "classes": None if self.classes is None else list(self.classes)}
