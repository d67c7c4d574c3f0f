"""Models in the live path: a frame's change of reading to the model's targets.

A static model (a calibration model: ``predict``) maps each frame on its own. A dynamic model (an
identified system, :mod:`softtip.sysid`: ``streaming()``) keeps its state between frames: the
estimate of frame k is the model's simulation of every frame since the baseline, computed one frame
at a time, so it equals the offline simulation of the same frames (a test holds it to 1e-9 of full
scale).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from softtip._core.archive import archive_format
from softtip._core.systems import reading_of


class Estimator:
    """A model in the live path.

    ``model``: any object with ``predict(X)`` (X of shape (1, n_inputs)); its
    ``predict_one(x)`` (x 1-D float64) is used when present; a model with ``streaming()``
    (returning an object with ``step(u)`` and ``reset()``) is dynamic: its state is kept from
    frame to frame and restarts from rest with every new baseline. ``input_channels``: the
    channel of each input, e.g. ``s0_bx_uT`` (flux density) or ``side_fx_N`` (a force chip's
    force chip), all of one sensor kind (:attr:`reading`); ``input_units``: their unit (the
    reading's, as stored in datasets, or another of its :attr:`~softtip._core.channels.Reading.units`).
    ``kind``: ``"regression"`` (``target_names`` and ``target_units`` required) or
    ``"classifier"`` (the predicted label is the contact state; ``classes`` from the model's
    ``classes_``); ``"auto"``: a classifier when the model has ``classes_``.
    """

    def __init__(self, model: Any, input_channels: Sequence[str], *, target_names: Sequence[str] | None = None,
                 target_units: str | Sequence[str] | None = None, input_units: str | Sequence[str] | None = None,
                 kind: str = "auto", name: str = "model") -> None:
        streaming = getattr(model, "streaming", None)
        self.dynamic = callable(streaming)
        if not self.dynamic and not callable(getattr(model, "predict", None)):
            raise ValueError(f"model {name}: expected an object with a predict(X) or streaming() method, "
                             f"got {type(model).__name__}")
        self.name = name
        self.model = model
        self.input_channels = tuple(input_channels)
        if not self.input_channels:
            raise ValueError(f"model {name}: input_channels is empty")
        try:
            self.reading = reading_of(self.input_channels)
        except ValueError as problem:
            raise ValueError(f"model {name}: {problem}") from None
        self.input_index = np.array([self.reading.channel_index(c) for c in self.input_channels], dtype=np.intp)
        if input_units is None:
            input_units = self.reading.unit
        units = (input_units,) * len(self.input_channels) if isinstance(input_units, str) else tuple(input_units)
        if len(units) != len(self.input_channels):
            raise ValueError(f"model {name}: {len(units)} input units for {len(self.input_channels)} input channels")
        unknown = sorted({u for u in units if u not in self.reading.units})
        if unknown:
            raise ValueError(f"model {name}: input unit {unknown[0]!r} is not one of {', '.join(self.reading.units)}")
        scale = 1.0 / np.array([self.reading.units[u] for u in units])  # model units per reading unit
        self._scale = None if np.all(scale == 1.0) else scale
        self.chips_needed = int(self.input_index.max()) // len(self.reading.axes) + 1
        if kind == "auto":
            kind = "classifier" if hasattr(model, "classes_") else "regression"
        if kind == "classifier" and not self.dynamic:
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
            raise ValueError(f"kind = {kind!r}: expected 'regression', 'classifier' or 'auto'"
                             + (" (a dynamic model is a regression)" if kind == "classifier" else ""))
        self.kind = kind
        # Inputs that are the first channels in storage order are a slice: a view, no copy.
        self._leading_inputs = np.array_equal(self.input_index, np.arange(len(self.input_index)))
        # a dynamic model holds at its own sample time only (an identified system's ts_)
        self.sample_time_s = getattr(model, "ts_", None) if self.dynamic else None
        if self.dynamic:
            self._stream = streaming()
            self._predict_one = self._stream.step
        else:
            predict_one = getattr(model, "predict_one", None)
            self._predict_one = predict_one if callable(predict_one) else self._predict_via_batch

    @classmethod
    def from_file(cls, path: str | Path) -> Estimator:
        """A model saved by :func:`softtip.calibration.save_model` or :func:`softtip.sysid.save_model`,
        with its channels and targets."""
        path = Path(path)
        from softtip.sysid.files import FORMAT as SYSTEM_FORMAT

        if archive_format(path) == SYSTEM_FORMAT:
            from softtip.sysid.files import load_model as load_system

            system = load_system(path)
            return cls(system, system.inputs_, target_names=system.outputs_, target_units=system.output_units_,
                       input_units=system.input_units_, name=path.name)
        from softtip.calibration.persistence import load_model

        model, meta = load_model(path)
        return cls(model, meta.input_channels, target_names=meta.target_names, target_units=meta.target_units,
                   input_units=meta.input_units, name=path.name)

    def _predict_via_batch(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.model.predict(x[None, :]))[0]

    def reset(self) -> None:
        """A dynamic model back to rest (the zero state); nothing for a static one."""
        if self.dynamic:
            self._stream.reset()

    def inputs(self, change_flat: np.ndarray) -> np.ndarray:
        """The model's input vector from a frame's flattened change (in the reading's unit)."""
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
        return {"name": self.name, "kind": self.kind, "model": type(self.model).__name__, "dynamic": self.dynamic,
                "reading": self.reading.quantity, "input_channels": list(self.input_channels),
                "target_names": list(self.target_names), "target_units": list(self.target_units),
                "classes": None if self.classes is None else list(self.classes)}
