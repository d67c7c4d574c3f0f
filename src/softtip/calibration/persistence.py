"""Saved calibration models: one ``.npz`` file, no pickle.

The archive (written by ``numpy.savez``, read with ``allow_pickle=False``) holds every
array of the model under a path-like name (``model/weights/0``, ``model/input_min``, or
``steps/<i>/...`` for a pipeline) and one text entry, ``metadata``, a JSON object::

    format          "softtip-model"
    schema_version  1
    softtip_version the version that wrote the file
    model           {"class", "params", "state"} for a model, or {"class": "Pipeline",
                    "steps": [{"name", "class", "params", "state"}, ...]}; "state" holds
                    the JSON-able fitted values (sizes, stop reason, ...)
    input_channels, input_units, target_names, target_units   one entry per input / output
    baseline        how readings were zeroed before calibration ("initial-value": the
                    reading before contact subtracted)
    scaling         the scaling each step applies to inputs and outputs
    extra           free JSON object for the caller
    sha256          the checksum of metadata and arrays (:mod:`softtip._core.archive`)

Saved: :class:`LMNetwork`, :class:`SoftmaxClassifier`, :class:`PolynomialFit`, and a
scikit-learn ``Pipeline`` of ``StandardScaler``/``MinMaxScaler`` steps ending in one of them.
Parameters that are not JSON (a numpy Generator as ``random_state``) are saved as null:
they only shape training, not the fitted model. Every refusal raises
:class:`ModelFileError` with one line naming the file. :func:`fitted` keeps a fit in the cache as such
a file, so the same fit is made once.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy
import sklearn
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import MinMaxScaler, StandardScaler

from softtip import __version__
from softtip._core.archive import ModelFileError, canonical_json, hash_arrays, read_archive, write_archive
from softtip._core.cache import artefact_key, cache_dir, code_hash, stored_or_made
from softtip.calibration import checks
from softtip.calibration.classifier import SoftmaxClassifier
from softtip.calibration.network import LMNetwork
from softtip.calibration.polynomial import PolynomialFit

FORMAT = "softtip-model"
SCHEMA_VERSION = 1
MODELS = {cls.__name__: cls for cls in (LMNetwork, SoftmaxClassifier, PolynomialFit)}
SCALERS = {
    "StandardScaler": (StandardScaler, ("mean_", "var_", "scale_")),
    "MinMaxScaler": (MinMaxScaler, ("min_", "scale_", "data_min_", "data_max_", "data_range_")),
}


@dataclass(frozen=True)
class ModelMetadata:
    """What a saved model says about itself, besides its arrays."""

    model_class: str
    params: dict
    input_channels: tuple[str, ...]
    input_units: tuple[str, ...]
    target_names: tuple[str, ...]
    target_units: tuple[str, ...]
    baseline: str
    scaling: dict
    softtip_version: str
    schema_version: int = SCHEMA_VERSION
    extra: dict = field(default_factory=dict)


# --------------------------------------------------------------------------
# Steps: model or scaler <-> (params, state, arrays)
# --------------------------------------------------------------------------


def _json_params(estimator) -> dict:
    params = estimator.get_params(deep=False)
    if not isinstance(params.get("random_state"), (int, type(None))):
        params["random_state"] = None  # a Generator: it only shaped training
    try:
        json.dumps(params, allow_nan=False)
    except (TypeError, ValueError):
        raise ModelFileError(f"{type(estimator).__name__}: parameters must be JSON values to be saved, "
                             f"got {params!r}") from None
    return params


def _tuples(value):
    """JSON lists back to the tuples estimators take as parameters."""
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    if isinstance(value, dict):
        return {k: _tuples(v) for k, v in value.items()}
    return value


def _export_step(step) -> tuple[dict, dict[str, np.ndarray]]:
    name = type(step).__name__
    if name in MODELS and isinstance(step, MODELS[name]):
        arrays, state = step._export()
    elif name in SCALERS and isinstance(step, SCALERS[name][0]):
        if not hasattr(step, "n_features_in_"):
            raise ModelFileError(f"{name} is not fitted")
        arrays = {a: np.asarray(getattr(step, a), dtype=np.float64) for a in SCALERS[name][1]
                  if getattr(step, a, None) is not None}
        state = {"n_features_in": int(step.n_features_in_)}
        seen = np.asarray(step.n_samples_seen_)
        if seen.ndim:
            arrays["n_samples_seen"] = seen.astype(np.int64)
        else:
            state["n_samples_seen"] = int(seen)
    else:
        raise ModelFileError(f"cannot save a {name}: expected one of {', '.join(MODELS)} "
                             f"(alone or after {' / '.join(SCALERS)} in a Pipeline)")
    return {"class": name, "params": _json_params(step), "state": state}, arrays


def _restore_step(description: dict, arrays: dict[str, np.ndarray]):
    name = description.get("class")
    params, state = description.get("params"), description.get("state")
    if not isinstance(params, dict) or not isinstance(state, dict):
        raise ValueError(f"{name}: params and state must be JSON objects")
    params = _tuples(params)
    if name in MODELS:
        try:
            return MODELS[name]._restore(params, arrays, state)
        except TypeError as problem:  # unknown parameter names
            raise ValueError(f"{name}: {problem}") from None
    if name in SCALERS:
        cls, names = SCALERS[name]
        try:
            scaler = cls(**params)
        except TypeError as problem:
            raise ValueError(f"{name}: {problem}") from None
        n_features = checks.stored_int(state, "n_features_in", 1)
        held = _fitted_arrays(scaler)
        for attribute in names:
            if (attribute in arrays) != (attribute in held):
                raise ValueError(f"{name}: array {attribute!r} is {'missing' if attribute in held else 'not used'} "
                                 f"(a {name} of these parameters holds {', '.join(held)})")
            setattr(scaler, attribute, checks.stored_array(arrays, attribute, (n_features,))
                    if attribute in arrays else None)
        _check_scaler(scaler)
        scaler.n_features_in_ = n_features
        scaler.n_samples_seen_ = (checks.stored_array(arrays, "n_samples_seen", (n_features,), kinds="i")
                                  if "n_samples_seen" in arrays else checks.stored_int(state, "n_samples_seen", 1))
        return scaler
    raise ModelFileError(f"unknown model class {name!r}")


def _fitted_arrays(scaler) -> tuple[str, ...]:
    """The arrays scikit-learn's fit sets on a scaler of these parameters (the others it leaves None)."""
    if isinstance(scaler, MinMaxScaler):
        return SCALERS["MinMaxScaler"][1]
    return ("mean_",) * (scaler.with_mean or scaler.with_std) + ("var_", "scale_") * bool(scaler.with_std)


def _check_scaler(scaler) -> None:
    """A scaler's arrays agree with each other and with its parameters, as scikit-learn's fit sets them:
    a MinMaxScaler's scale and offset follow from its data range and feature range; a StandardScaler's
    scale is the square root of its variance (1 for a constant feature)."""
    name = type(scaler).__name__
    if isinstance(scaler, MinMaxScaler):
        low, high = scaler.feature_range
        data_range = scaler.data_max_ - scaler.data_min_
        scale = (high - low) / np.where(data_range == 0, 1.0, data_range)
        consistent = (np.array_equal(scaler.data_range_, data_range) and np.allclose(scaler.scale_, scale, rtol=1e-12)
                      and np.allclose(scaler.min_, low - scaler.data_min_ * scale, rtol=1e-12, atol=1e-300))
    elif scaler.with_std:
        deviation = np.sqrt(scaler.var_)
        constant = (scaler.scale_ == 1.0) & (deviation <= 1e-6 * np.maximum(1.0, np.abs(scaler.mean_)))
        consistent = bool(np.all(np.isclose(scaler.scale_, deviation, rtol=1e-12, atol=0) | constant))
    else:
        consistent = True
    if not consistent:
        raise ValueError(f"{name}: its arrays do not agree with each other and its parameters "
                         f"({', '.join(_fitted_arrays(scaler))})")


def _scaling(step) -> dict:
    if isinstance(step, LMNetwork):
        return {"input": "mapminmax to [-1, 1] (arrays input_min, input_max)",
                "output": "mapminmax from [-1, 1] (arrays target_min, target_max)"}
    if isinstance(step, SoftmaxClassifier):
        return {"input": "mapminmax to [-1, 1] (arrays input_min, input_max)", "output": "softmax over classes"}
    if isinstance(step, PolynomialFit):
        return {"input": "none", "output": "none"}
    return {"input": f"{type(step).__name__} (scikit-learn)", "output": "none"}


def _names(value, count: int, what: str, *, broadcast: bool) -> tuple[str, ...]:
    if broadcast and isinstance(value, str):
        value = [value] * count
    if isinstance(value, str) or not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value):
        expected = f"{'a string or ' if broadcast else ''}a sequence of {count} strings"
        raise ModelFileError(f"{what} must be {expected}, got {value!r}")
    if len(value) != count:
        raise ModelFileError(f"{what} has {len(value)} entries, the model has {count}")
    return tuple(value)


def _output_count(model) -> int:
    return 1 if isinstance(model, SoftmaxClassifier) else int(model.n_outputs_)


def _serialised(model) -> tuple[dict, dict[str, np.ndarray], dict]:
    """(model description, arrays by file name, scaling) of a fitted model or scaler Pipeline ending in one,
    as a model file holds them."""
    steps = list(model.named_steps.items()) if isinstance(model, Pipeline) else [(None, model)]
    final = steps[-1][1]
    if isinstance(model, Pipeline) and not all(type(s).__name__ in SCALERS for _, s in steps[:-1]):
        raise ModelFileError(f"cannot save this Pipeline: steps before the model must be {' / '.join(SCALERS)}")
    if type(final).__name__ not in MODELS:
        raise ModelFileError(f"cannot save a {type(final).__name__}: expected one of {', '.join(MODELS)}")
    if not hasattr(final, "n_features_in_"):
        raise ModelFileError(f"the {type(final).__name__} is not fitted")
    exported = [_export_step(step) for _, step in steps]
    if not isinstance(model, Pipeline):
        return exported[0][0], {f"model/{k}": np.asarray(v) for k, v in exported[0][1].items()}, _scaling(final)
    named = [d | {"name": name} for (name, _), (d, _) in zip(steps, exported, strict=True)]
    arrays = {f"steps/{i}/{k}": np.asarray(v) for i, (_, a) in enumerate(exported) for k, v in a.items()}
    return {"class": "Pipeline", "steps": named}, arrays, {name: _scaling(step) for name, step in steps}


def _same_arrays(first: np.ndarray, second: np.ndarray) -> bool:
    return (first.dtype == second.dtype and first.shape == second.shape
            and np.ascontiguousarray(first).tobytes() == np.ascontiguousarray(second).tobytes())


def _check_agreement(model, metadata: dict, arrays: dict[str, np.ndarray]) -> None:
    """Refuses a file whose metadata does not describe its arrays exactly: the restored model, written
    out again, must give back the same description (class, parameters, fitted state: sizes, counts),
    the same scaling and the same arrays, bit for bit, no more and no fewer."""
    description, written, scaling = _serialised(model)
    if canonical_json(description) != canonical_json(metadata["model"]):
        raise ValueError("the model description does not match what its arrays hold")
    if canonical_json(scaling) != canonical_json(metadata.get("scaling")):
        raise ValueError("the metadata's scaling does not describe the model's steps")
    extra = sorted(set(arrays) - set(written))
    if extra:
        raise ValueError(f"array {extra[0]!r} is not part of the model")
    differing = [name for name in written if name not in arrays or not _same_arrays(written[name], arrays[name])]
    if differing:
        raise ValueError(f"array {differing[0]!r} does not match the model restored from it")


def save_model(path: str | os.PathLike, model, *, input_channels: Sequence[str], input_units: str | Sequence[str],
               target_names: Sequence[str], target_units: str | Sequence[str], baseline: str = "initial-value",
               extra: dict | None = None) -> Path:
    """Save a fitted model (or scaler Pipeline ending in one) to ``path``, exactly as named
    (use the ``.npz`` suffix). Units may be one string for every channel/output. For a
    classifier ``target_names`` is one name (the predicted label), e.g. ``["contact_state"]``.
    """
    path = Path(path)
    description, arrays, scaling = _serialised(model)
    steps = list(model.named_steps.items()) if isinstance(model, Pipeline) else [(None, model)]
    n_inputs = int(steps[0][1].n_features_in_)
    n_outputs = _output_count(steps[-1][1])
    if not isinstance(baseline, str) or not baseline:
        raise ModelFileError(f"baseline must be a non-empty string, got {baseline!r}")
    if extra is not None and not isinstance(extra, dict):
        raise ModelFileError(f"extra must be a dict of JSON values or None, got {type(extra).__name__}")
    metadata = {
        "format": FORMAT,
        "schema_version": SCHEMA_VERSION,
        "softtip_version": __version__,
        "model": description,
        "input_channels": list(_names(input_channels, n_inputs, "input_channels", broadcast=False)),
        "input_units": list(_names(input_units, n_inputs, "input_units", broadcast=True)),
        "target_names": list(_names(target_names, n_outputs, "target_names", broadcast=False)),
        "target_units": list(_names(target_units, n_outputs, "target_units", broadcast=True)),
        "baseline": baseline,
        "scaling": scaling,
        "extra": extra or {},
    }
    try:
        canonical_json(metadata)
    except (TypeError, ValueError) as problem:
        raise ModelFileError(f"extra must hold JSON values only ({problem})") from None
    write_archive(path, metadata, arrays)
    return path


def load_model(path: str | os.PathLike):
    """The fitted estimator saved in ``path`` and its :class:`ModelMetadata`."""
    path = Path(path)
    metadata, arrays = read_archive(path, FORMAT, SCHEMA_VERSION, "model", ModelFileError)
    description = metadata.get("model")
    if not isinstance(description, dict):
        raise ModelFileError(f"{path}: metadata has no model description")
    try:
        if description.get("class") == "Pipeline":
            steps = description.get("steps")
            if not isinstance(steps, list) or not steps or not all(isinstance(s, dict) for s in steps):
                raise ValueError("a Pipeline needs a non-empty list of steps")
            restored = [(str(s.get("name")), _restore_step(s, _sub(arrays, f"steps/{i}/")))
                        for i, s in enumerate(steps)]
            kinds = [type(s).__name__ for _, s in restored]
            if kinds[-1] not in MODELS or any(kind not in SCALERS for kind in kinds[:-1]):
                raise ValueError("a Pipeline must be scalers followed by one model")
            widths = {int(s.n_features_in_) for _, s in restored}
            if len(widths) != 1:
                raise ValueError(f"the pipeline steps expect different numbers of inputs {sorted(widths)}")
            model, final = Pipeline(restored), restored[-1][1]
            params = {"steps": [{key: s.get(key) for key in ("name", "class", "params")} for s in steps]}
        else:
            final = model = _restore_step(description, _sub(arrays, "model/"))
            params = description["params"]
        n_inputs, n_outputs = int(final.n_features_in_), _output_count(final)
        result = ModelMetadata(
            model_class=description["class"],
            params=params,
            input_channels=_names(metadata.get("input_channels"), n_inputs, "input_channels", broadcast=False),
            input_units=_names(metadata.get("input_units"), n_inputs, "input_units", broadcast=False),
            target_names=_names(metadata.get("target_names"), n_outputs, "target_names", broadcast=False),
            target_units=_names(metadata.get("target_units"), n_outputs, "target_units", broadcast=False),
            baseline=str(metadata.get("baseline")),
            scaling=metadata.get("scaling") or {},
            softtip_version=str(metadata.get("softtip_version")),
            schema_version=SCHEMA_VERSION,
            extra=metadata.get("extra") or {},
        )
        _check_agreement(model, metadata, arrays)
    except ModelFileError as problem:
        raise ModelFileError(f"{path}: {problem}") from None
    except ValueError as problem:
        raise ModelFileError(f"{path}: inconsistent model: {problem}") from None
    return model, result


def _sub(arrays: dict[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    return {name.removeprefix(prefix): array for name, array in arrays.items() if name.startswith(prefix)}


def fitted(estimator, X, y, **fit_params):
    """``estimator`` (an :class:`LMNetwork`, :class:`SoftmaxClassifier` or :class:`PolynomialFit`) fitted on
    ``X``, ``y`` and the arrays ``fit_params`` (``groups``), or the same fit made earlier, read from the
    cache: a model file keyed by the estimator's class and ``get_params()`` (its seed among them), the
    checksum of the training arrays, the code of the fit and numpy's, scipy's and scikit-learn's
    versions. A file read predicts as the fit made afresh, to the last bit. ``estimator`` itself is left
    unfitted. One seeded by a random generator object (not a number) draws anew at each fit, so it is
    fitted every time."""
    params = estimator.get_params()
    fit = lambda: type(estimator)(**params).fit(X, y, **fit_params)  # noqa: E731
    if type(estimator).__name__ not in MODELS:
        raise ModelFileError(f"cannot keep a {type(estimator).__name__} in the cache: expected one of {', '.join(MODELS)}")
    if not isinstance(params.get("random_state"), int | None):
        return fit()
    training = {"X": X, "y": y} | {f"fit/{name}": value for name, value in fit_params.items()}
    digest = hashlib.sha256()
    # labels as text: an object array's bytes are pointers, not its values
    hash_arrays(digest, {name: np.asarray(value).astype(str) if np.asarray(value).dtype == object else np.asarray(value)
                         for name, value in training.items()})
    inputs = {"class": type(estimator).__name__, "params": params, "training": digest.hexdigest(),
              "versions": [np.__version__, scipy.__version__, sklearn.__version__]}
    key = artefact_key(inputs, code_hash("softtip.calibration", "softtip._core", "softtip.metrics"))
    path = cache_dir() / "calibration" / f"{type(estimator).__name__}-{key}.npz"
    return stored_or_made(path, key, "calibration model", lambda target: load_model(target)[0], fit, _save_unnamed)[0]


def _save_unnamed(model, path: Path) -> None:
    """A model file of ``model`` whose channels and targets are only numbered: a cached fit is keyed by its
    training arrays, not by what they were named."""
    save_model(path, model, input_channels=[f"x{k}" for k in range(model.n_features_in_)], input_units="1",
               target_names=[f"y{k}" for k in range(_output_count(model))], target_units="1")
