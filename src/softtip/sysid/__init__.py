"""System identification: linear models of a system from sampled input/output recordings.

What a MATLAB System Identification Toolbox user expects, for recordings such as a fingertip
force sensor's (side-sensor forces in, table-sensor forces out, at 10 Hz):

- :mod:`~softtip.sysid.recording`: :class:`Recording` (sample time, named channels with units,
  trials) from a softtip dataset, a CSV or a plain Parquet file, with detrending, and the checks
  that refuse data no model can be identified from;
- :mod:`~softtip.sysid.trends`: levels and linear trends fitted on the estimation data and kept
  with the model (MATLAB's ``TrendInfo``); :mod:`~softtip.sysid.delays`: input delays per channel,
  declared or estimated;
- :mod:`~softtip.sysid.splits`: estimation / validation splits by trial and by contiguous time
  (honest for time series) and the published random split by sample (leaky: it warns);
- :mod:`~softtip.sysid.transfer`: continuous transfer-function matrices (``tfest``);
- :mod:`~softtip.sysid.subspace` and :mod:`~softtip.sysid.refine`: state-space models by N4SID,
  MOESP or CVA and prediction-error refinement (``n4sid``, ``ssest``);
- :mod:`~softtip.sysid.statespace`, :mod:`~softtip.sysid.realisation`,
  :mod:`~softtip.sysid.simulation`: state-space systems, zero-order-hold conversions, transfer
  functions as state space, simulation, k-step prediction and frame-by-frame streaming;
- :mod:`~softtip.sysid.metrics`: R², r, RMSE, MAE (in units and % of a stated full scale) and
  the NRMSE fit % per output, from the zero or the estimated initial state;
- :mod:`~softtip.sysid.uncertainty`: confidence intervals of a transfer function's coefficients,
  poles, zeros and frequency response, its Bode plot with the band, and the empirical transfer
  function; :mod:`~softtip.sysid.residuals`: residual whiteness and input-independence tests;
- :mod:`~softtip.sysid.models`: :class:`StateSpaceModel` and :class:`TransferFunctionModel`
  (``fit``/``simulate``/``predict``/``score``), order-selection tables with AIC and BIC;
- :mod:`~softtip.sysid.files`: :func:`save_model` / :func:`load_model` (npz + JSON), and :func:`fitted`:
  a fit kept in the cache as such a file.
"""

from importlib import import_module
from typing import TYPE_CHECKING

# every public name -> the module that defines it, imported on first use (PEP 562): importing the package
# costs nothing, and a command pays for the stages it uses (scikit-learn, scipy) when it uses them
_HOMES = {
    "estimate_delays": "delays",
    "fitted": "files", "load_model": "files", "save_model": "files",
    "MEASURED": "metrics", "FullScale": "metrics", "Scores": "metrics", "fit_percent": "metrics", "rated": "metrics",
    "score_outputs": "metrics",
    "StateSpaceModel": "models", "TransferFunctionModel": "models", "information_criteria": "models",
    "order_table": "models", "validated_order": "models",
    "Recording": "recording", "Trial": "recording", "read_recording": "recording",
    "ResidualTests": "residuals", "residual_tests": "residuals",
    "StreamingSimulator": "simulation", "estimate_initial_state": "simulation", "predict": "simulation",
    "simulate": "simulation",
    "split_by_sample": "splits", "split_by_time": "splits", "split_by_trial": "splits",
    "IdentificationError": "statespace", "StateSpace": "statespace",
    "TransferFunctionMatrix": "transfer",
    "Trend": "trends", "estimate_trend": "trends",
    "empirical_transfer_function": "uncertainty",
}

if TYPE_CHECKING:
    from softtip.sysid.delays import estimate_delays
    from softtip.sysid.files import fitted, load_model, save_model
    from softtip.sysid.metrics import MEASURED, FullScale, Scores, fit_percent, rated, score_outputs
    from softtip.sysid.models import (
        StateSpaceModel,
        TransferFunctionModel,
        information_criteria,
        order_table,
        validated_order,
    )
    from softtip.sysid.recording import Recording, Trial, read_recording
    from softtip.sysid.residuals import ResidualTests, residual_tests
    from softtip.sysid.simulation import StreamingSimulator, estimate_initial_state, predict, simulate
    from softtip.sysid.splits import split_by_sample, split_by_time, split_by_trial
    from softtip.sysid.statespace import IdentificationError, StateSpace
    from softtip.sysid.transfer import TransferFunctionMatrix
    from softtip.sysid.trends import Trend, estimate_trend
    from softtip.sysid.uncertainty import empirical_transfer_function


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{_HOMES[name]}"), name)
    globals()[name] = value
    return value


__all__ = [
    "MEASURED",
    "FullScale",
    "IdentificationError",
    "Recording",
    "ResidualTests",
    "Scores",
    "StateSpace",
    "StateSpaceModel",
    "StreamingSimulator",
    "TransferFunctionMatrix",
    "TransferFunctionModel",
    "Trend",
    "Trial",
    "empirical_transfer_function",
    "estimate_delays",
    "estimate_initial_state",
    "estimate_trend",
    "fit_percent",
    "fitted",
    "information_criteria",
    "load_model",
    "order_table",
    "predict",
    "rated",
    "read_recording",
    "residual_tests",
    "save_model",
    "score_outputs",
    "simulate",
    "split_by_sample",
    "split_by_time",
    "split_by_trial",
    "validated_order",
]
