"""Running a study: candidates -> feasibility -> cache -> executor -> scores -> search.

:func:`run_study` is the client side of every sweep. It checks each candidate
design (constraints, then the design validator) before anything is computed,
looks every FE run up in the cache, submits only what is missing, writes each
result to the cache the moment it arrives, and scores designs as their results
complete. The grid evaluates every feasible candidate; the Bayesian search asks
:class:`~softtip.optimize.bayes.BayesianSearch` which ones to evaluate next.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np

from softtip import __version__
from softtip._core.progress import SILENT, Progress, Task
from softtip.design.model import Design, DesignError
from softtip.optimize.bayes import BayesianSearch
from softtip.optimize.cache import FEResultCache
from softtip.optimize.config import StudyConfig, numeric_parameters
from softtip.optimize.errors import StudyError
from softtip.optimize.executors import Executor, FEJob
from softtip.optimize.objectives import Infeasible
from softtip.optimize.runs import FEResult
from softtip.optimize.space import grid_candidates, normalised_points

OK, INFEASIBLE, FAILED = "ok", "infeasible", "failed"


@dataclass
class DesignRecord:
    """One candidate design and what became of it."""

    index: int  # position in the grid (the first parameter varies slowest)
    params: dict[str, float]
    status: str = ""  # ok | infeasible | failed; "" while not evaluated
    objective: float | None = None
    reason: str = ""  # why infeasible or failed
    evaluation: int | None = None  # 1-based order in which the search asked for it
    cached: bool = False  # every FE result came from the cache
    fe_seconds: float | None = None  # wall time of the FE runs computed now

    @property
    def values(self) -> str:
        """The parameter values as a user writes them: ``8.3, 4.5``."""
        return ", ".join(f"{v:g}" for v in self.params.values())

    def to_json(self) -> dict[str, Any]:
        return {"evaluation": self.evaluation, "index": self.index, "params": self.params,
                "feasible": self.status != INFEASIBLE, "status": self.status, "objective": self.objective,
                "cached": self.cached, "fe_seconds": None if self.fe_seconds is None else round(self.fe_seconds, 3),
                "reason": self.reason}


@dataclass
class StudyResult:
    config: StudyConfig
    records: list[DesignRecord]  # every candidate, in grid order
    fe_runs: int  # simulations computed in this run
    cache_hits: int  # simulations taken from the cache
    wall_seconds: float
    executor: str
    stop_reason: str

    @property
    def table(self) -> list[DesignRecord]:
        """Evaluated designs in evaluation order, then the infeasible ones."""
        evaluated = sorted((r for r in self.records if r.evaluation is not None), key=lambda r: r.evaluation)
        return evaluated + [r for r in self.records if r.status == INFEASIBLE]

    @property
    def best(self) -> DesignRecord | None:
        """The best design; ties go to the one evaluated first."""
        sign = 1.0 if self.config.objective.goal == "max" else -1.0
        scored = [r for r in self.table if r.status == OK]
        return max(scored, key=lambda r: (sign * r.objective, -r.evaluation)) if scored else None

    def counts(self) -> dict[str, Any]:
        best = self.best
        statuses = [r.status for r in self.records]
        return {"designs": sum(r.evaluation is not None for r in self.records), "fe_runs": self.fe_runs,
                "cache_hits": self.cache_hits, "infeasible": statuses.count(INFEASIBLE),
                "failed": statuses.count(FAILED), "candidates": len(self.records),
                "best_at": best.evaluation if best else None, "stop": self.stop_reason}

    def to_json(self) -> dict[str, Any]:
        config, best = self.config, self.best
        return {
            "softtip": __version__, "study": config.name, "source": config.source, "design": config.design.name,
            "method": config.method,
            "objective": {"name": config.objective.name, "goal": config.objective.goal, "unit": config.objective.unit,
                          "settings": config.objective_settings},
            "parameters": [{"name": p.name, "min": p.minimum, "max": p.maximum, "step": p.step,
                            "values": len(p.values)} for p in config.parameters],
            "constraints": [c.text for c in config.constraints],
            "search": dataclasses.asdict(config.search) if config.method == "bayes" else None,
            "best": {"params": best.params, "objective": best.objective, "evaluation": best.evaluation}
            if best else None,
            "evaluations": self.counts(), "executor": self.executor, "wall_seconds": round(self.wall_seconds, 2),
            "table": [r.to_json() for r in self.table],
        }


def check_feasibility(config: StudyConfig, params: dict[str, float]) -> tuple[Design | None, str]:
    """The candidate's design, or None and the reason it cannot be built."""
    try:
        design = config.design.with_params(**params)
    except DesignError as error:
        return None, str(error)
    if config.constraints:
        values = numeric_parameters(design)
        for constraint in config.constraints:
            try:
                if not constraint.holds(values):
                    return None, f"constraint {constraint.text!r} violated"
            except (ArithmeticError, ValueError, TypeError) as error:  # e.g. sqrt(-1), 1/0, (-1) ** 0.5
                return None, f"constraint {constraint.text!r} cannot be evaluated ({error})"
    return design, ""


class _Evaluator:
    """Scores batches of designs through the cache and the executor, counting FE runs."""

    def __init__(self, config: StudyConfig, executor: Executor, cache: FEResultCache):
        self.objective = config.objective
        self.executor, self.cache = executor, cache
        self.fe_runs = self.cache_hits = 0

    def evaluate(self, batch: list[tuple[DesignRecord, Design]]) -> Iterator[DesignRecord]:
        simulations = self.objective.simulations
        jobs, pending = [], {}
        for record, design in batch:
            results: list[FEResult | None] = [self.cache.get(design.spec, s) for s in simulations]
            self.cache_hits += sum(r is not None for r in results)
            if all(r is not None for r in results):
                record.cached = True
                yield self._score(record, design, results)
                continue
            missing = tuple(s.to_dict() for s, r in zip(simulations, results) if r is None)
            jobs.append(FEJob(tag=record.index, design_spec=design.spec, simulations=missing))
            pending[record.index] = (record, design, results)
        for job, answer in self.executor.run(jobs):
            record, design, results = pending.pop(job.tag)
            self.fe_runs += len(answer["seconds"])
            record.fe_seconds = sum(answer["seconds"])
            if answer["error"] is not None:
                record.status, record.reason = FAILED, answer["error"]
                yield record
                continue
            fresh = iter(zip(answer["results"], answer["seconds"]))
            for position, simulation in enumerate(simulations):
                if results[position] is None:
                    data, seconds = next(fresh)
                    results[position] = FEResult.from_dict(data)
                    self.cache.put(design.spec, simulation, results[position], seconds)  # now, not at the end
            yield self._score(record, design, results)

    def _score(self, record: DesignRecord, design: Design, results: list[FEResult]) -> DesignRecord:
        try:
            value = float(self.objective.score(design, results))
        except Infeasible as error:
            record.status, record.reason = INFEASIBLE, str(error)
            return record
        except StudyError as error:
            record.status, record.reason = FAILED, str(error)
            return record
        if not np.isfinite(value):
            record.status, record.reason = FAILED, f"objective is {value}"
        else:
            record.status, record.objective = OK, value
        return record


def run_study(config: StudyConfig, executor: Executor, cache: FEResultCache | None = None,
              progress: Progress = SILENT) -> StudyResult:
    """Evaluate the study; ``progress`` gets one task, advanced per design evaluated, its note the
    design's parameters and objective."""
    start = time.perf_counter()
    cache = FEResultCache() if cache is None else cache
    records = [DesignRecord(index=i, params=params) for i, params in enumerate(grid_candidates(config.parameters))]
    designs: dict[int, Design] = {}
    for record in records:
        design, reason = check_feasibility(config, record.params)
        if design is None:
            record.status, record.reason = INFEASIBLE, reason
        else:
            designs[record.index] = design
    evaluator = _Evaluator(config, executor, cache)
    asked = 0

    def evaluate(indices: list[int], task: Task) -> Iterator[DesignRecord]:
        nonlocal asked
        for index in indices:
            asked += 1
            records[index].evaluation = asked
        for record in evaluator.evaluate([(records[i], designs[i]) for i in indices]):
            value = f"{record.objective:.4g}" if record.objective is not None else record.status
            task.advance(note=f"last: {record.values} -> {value}")
            yield record

    feasible = sorted(designs)
    description = f"{config.name} ({config.method})"
    if not feasible:
        stop = "no feasible candidate"
    elif config.method == "grid":
        with progress.task(description, total=len(feasible)) as task:
            for _ in evaluate(feasible, task):
                pass
        stop = "grid complete"
    else:
        stop = _bayes(config, records, feasible, evaluate, progress, description)
    return StudyResult(config=config, records=records, fe_runs=evaluator.fe_runs, cache_hits=evaluator.cache_hits,
                       wall_seconds=time.perf_counter() - start, executor=executor.description, stop_reason=stop)


def _bayes(config: StudyConfig, records: list[DesignRecord], feasible: list[int],
           evaluate: Callable[[list[int], Task], Iterator[DesignRecord]], progress: Progress,
           description: str) -> str:
    settings = config.search
    points = normalised_points(config.parameters, [records[i].params for i in feasible])
    search = BayesianSearch(points, budget=settings.budget, seed=settings.seed, initial=settings.initial,
                            batch=settings.batch, ei_tolerance=settings.ei_tolerance, patience=settings.patience)
    sign = 1.0 if config.objective.goal == "max" else -1.0  # the search maximises
    position = {index: k for k, index in enumerate(feasible)}
    with progress.task(description, total=search.budget) as task:
        while picks := search.ask():
            for record in evaluate([feasible[k] for k in picks], task):
                search.tell(position[record.index], None if record.status != OK else sign * record.objective)
    return search.stop_reason
