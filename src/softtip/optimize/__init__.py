"""Design optimisation on the physics twin: grid sweeps and Bayesian search of design parameters.

A study (:mod:`~softtip.optimize.config`) names a base design, the TOML-level
parameters to vary on a grid, optional constraints, an objective from the
registry (:mod:`~softtip.optimize.objectives`) and a search method.
:func:`~softtip.optimize.study.run_study` evaluates it through an executor
(:mod:`~softtip.optimize.executors`: this process, a local process pool or a
Dask cluster) and an on-disk cache of FE results
(:mod:`~softtip.optimize.cache`); :func:`~softtip.optimize.report.write_outputs`
writes the CSV, JSON and plot.

Names are imported on first use, so a worker that only needs
:func:`~softtip.optimize.runs.run_design` does not import the search machinery.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "StudyError": "errors",
    "StudyConfig": "config", "SearchSettings": "config", "load_study": "config", "study_from_dict": "config",
    "ParameterRange": "space", "Constraint": "space", "grid_candidates": "space",
    "Objective": "objectives", "ObjectiveSettings": "objectives", "objective": "objectives",
    "objective_names": "objectives",
    "Simulation": "runs", "FEResult": "runs", "run_design": "runs",
    "FEResultCache": "cache", "cache_key": "cache",
    "InProcessExecutor": "executors", "LocalPoolExecutor": "executors", "DaskExecutor": "executors",
    "make_executor": "executors",
    "BayesianSearch": "bayes", "expected_improvement": "bayes",
    "StudyResult": "study", "DesignRecord": "study", "run_study": "study",
    "write_outputs": "report",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'softtip.optimize' has no attribute {name!r}")
    return getattr(importlib.import_module(f"softtip.optimize.{_EXPORTS[name]}"), name)
