"""Saved identified models: one ``.npz`` archive of arrays and JSON metadata, never pickled.

The archive (:mod:`softtip._core.archive`: checksummed, written atomically) holds the discrete
system (``system/A`` ... ``system/K``, ``system/noise_covariance``), the subspace singular values
of a state-space model or the coefficients of a transfer function (``tf/numerators/<i>/<j>``,
``tf/denominators/<i>/<j>``), and the metadata::

    format          "softtip-sysid-model"
    schema_version  1
    softtip_version the version that wrote the file
    kind            "StateSpaceModel" or "TransferFunctionModel"
    params          the identification settings (get_params)
    fitted          sample time, input and output names and units, the data identified on
                    (source, trials, samples, detrending and the sha256 of its arrays), the fit
                    report, fit % and fit time
    sha256          the checksum of all of it

:func:`load_model` checks all of it and refuses a bad file with one :class:`ModelFileError` line.
:func:`fitted` keeps each fit in the cache as such a file, so the same fit is made once.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import scipy

from softtip import __version__
from softtip._core.archive import read_archive, write_archive
from softtip._core.archive import ModelFileError
from softtip._core.cache import artefact_key, cache_dir, code_hash, stored_or_made
from softtip.sysid.models import KINDS, IdentifiedModel
from softtip.sysid.recording import Recording
from softtip.sysid.statespace import IdentificationError

FORMAT = "softtip-sysid-model"
SCHEMA_VERSION = 1
CLASSES = {cls.__name__: cls for cls in KINDS.values()}


def save_model(path: str | os.PathLike, model: IdentifiedModel) -> Path:
    """Saves a fitted model to ``path`` (exactly as named; use ``.npz``)."""
    path = Path(path)
    if type(model).__name__ not in CLASSES:
        raise ModelFileError(f"cannot save a {type(model).__name__}: expected one of {', '.join(CLASSES)}")
    try:
        state, arrays = model._export()
    except IdentificationError as problem:
        raise ModelFileError(f"{path}: {problem}") from None
    if not path.parent.is_dir():
        raise ModelFileError(f"model file {path}: directory {path.parent} does not exist")
    metadata = {"format": FORMAT, "schema_version": SCHEMA_VERSION, "softtip_version": __version__,
                "kind": type(model).__name__, "params": model.get_params(), "fitted": state}
    return write_archive(path, metadata, arrays)


def load_model(path: str | os.PathLike) -> IdentifiedModel:
    """The fitted model saved in ``path``."""
    path = Path(path)
    metadata, arrays = read_archive(path, FORMAT, SCHEMA_VERSION, "system model", ModelFileError)
    kind, params, state = metadata.get("kind"), metadata.get("params"), metadata.get("fitted")
    if kind not in CLASSES:
        raise ModelFileError(f"{path}: unknown model kind {kind!r} (expected one of {', '.join(CLASSES)})")
    if not isinstance(params, dict) or not isinstance(state, dict):
        raise ModelFileError(f"{path}: params and fitted must be JSON objects")
    try:
        model = CLASSES[kind](**params)
        model._check_params()
        model._restore(state, arrays)
    except TypeError as problem:  # unknown parameter or report fields
        raise ModelFileError(f"{path}: inconsistent model: {problem}") from None
    except KeyError as problem:
        raise ModelFileError(f"{path}: inconsistent model: {problem.args[0]!r} is missing") from None
    except ValueError as problem:
        raise ModelFileError(f"{path}: inconsistent model: {problem}") from None
    return model


def fitted(model: IdentifiedModel, recording: Recording) -> IdentifiedModel:
    """``model`` fitted on ``recording``, or the same fit made earlier, read from the cache: a model file
    keyed by the recording (its names, units and the checksum of its arrays), the model's kind and
    ``get_params()``, the code of the fit and numpy's and scipy's versions. A file read is the fit made
    afresh to the last bit (``fit_seconds_`` aside, the time the first fit took). ``model`` itself is
    left unfitted."""
    inputs = {"kind": type(model).__name__, "params": model.get_params(), "data": recording.describe(),
              "numpy": np.__version__, "scipy": scipy.__version__}
    key = artefact_key(inputs, code_hash("softtip.sysid", "softtip._core", "softtip.metrics"))
    path = cache_dir() / "sysid" / f"{type(model).__name__}-{key}.npz"
    return stored_or_made(path, key, "identified model", load_model,
                          lambda: type(model)(**model.get_params()).fit(recording),
                          lambda made, target: save_model(target, made))[0]
