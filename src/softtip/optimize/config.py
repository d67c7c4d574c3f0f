"""Study files: what to vary, what to compute, how to search - validated up front.

A study is a TOML file::

    name = "published-grid"            # optional; default: the file's stem
    design = "my-design.toml"          # a shipped design, or a path relative to this file
    method = "grid"                    # or "bayes"
    output = "optimize-results"        # optional; relative to the working directory

    [parameters]                       # any numeric TOML-level design parameter
    "cavity.radius_mm" = { min = 8.0, max = 10.0, step = 0.1 }
    "magnets.circle_radius_mm" = { min = 4.5, max = 6.5, step = 0.5 }

    constraints = ["magnets.circle_radius_mm + 1 <= cavity.radius_mm"]   # optional, top level

    [objective]                        # a registered objective and its settings
    name = "feature_displacement"
    friction = "stick"
    mesh_size_mm = 1.5

    [search]                           # method = "bayes" only
    budget = 26
    seed = 0

Every mistake is refused with one line naming the key. Designs that the
design validator refuses are not mistakes: they become infeasible rows of the
results.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from softtip._core.config import (NonNegativeNumber, Number, PositiveNumber, Refusal, Text, choice, expect, integer,
                                  parse, read_toml, refused, schema, where)
from softtip.design.model import Design, DesignError, load_design
from softtip.optimize.errors import StudyError
from softtip.optimize.objectives import Objective, build_objective
from softtip.optimize.space import Constraint, ParameterRange, whole_steps

METHODS = ("grid", "bayes")
MAX_CANDIDATES = 1_000_000  # the candidate list is held in memory


@schema
class SearchSettings:
    budget: integer(1) = 25  # at most this many designs evaluated (cache hits included)
    seed: integer() = 0
    initial: integer(1) | None = None  # size of the space-filling start; default 2 * parameters + 1
    batch: integer(1) = 1  # designs proposed per step (use the workers' count on a cluster)
    ei_tolerance: NonNegativeNumber = 1e-3  # stop when the best expected improvement is below this many sd ...
    patience: integer(1) = 3  # ... for this many steps in a row


@schema
class _Range:
    """One entry of ``[parameters]``; ``step`` defaults to the whole range (one step)."""

    min: Number
    max: Number
    step: PositiveNumber | None = None

    def __post_init__(self):
        if self.max < self.min:
            raise Refusal("max", f"expected max >= min = {self.min}")
        if self.step is None:
            object.__setattr__(self, "step", self.max - self.min if self.max > self.min else 1.0)
        elif not whole_steps(self.min, self.max, self.step):
            raise Refusal("step", f"expected (max - min) = {self.max - self.min:g} to be a whole number of steps")


Constraints = Annotated[list[Text], expect('a list of strings such as "magnets.circle_radius_mm < cavity.radius_mm"')]


@schema
class _StudyFile:
    design: Text  # a shipped design, or a path relative to the study file
    parameters: dict[str, _Range]
    name: Text | None = None
    method: choice(*METHODS) = "grid"
    output: Text | None = None
    constraints: Constraints = field(default_factory=list)
    objective: dict[str, Any] = field(default_factory=dict)  # checked by the objective's own schema
    search: SearchSettings = SearchSettings()


@dataclass(frozen=True)
class StudyConfig:
    name: str
    source: str  # where it came from, for messages
    design: Design
    parameters: tuple[ParameterRange, ...]
    constraints: tuple[Constraint, ...]
    objective: Objective
    objective_settings: dict[str, Any]  # the [objective] table as written, echoed in reports
    method: str
    search: SearchSettings
    output: Path

    @property
    def candidate_count(self) -> int:
        return math.prod(parameter.count for parameter in self.parameters)


def load_study(path: str | Path) -> StudyConfig:
    path = Path(path)
    data = read_toml(path, "study", StudyError)
    return study_from_dict(data, source=str(path), base_dir=path.parent, default_name=path.stem)


def study_from_dict(data: dict[str, Any], source: str = "study", base_dir: Path = Path("."),
                    default_name: str = "study") -> StudyConfig:
    """Validate a study table; ``base_dir`` resolves a design given as a relative path."""
    study = parse(_StudyFile, data, source, error=StudyError)
    name = study.name or default_name
    design = _design(study.design, source, base_dir)
    parameters = _parameters(study.parameters, data, design, source)
    constraints = _constraints(study.constraints, design, source)
    objective = build_objective(study.objective, design, source)
    config = StudyConfig(name=name, source=source, design=design, parameters=parameters,
                         constraints=constraints, objective=objective, objective_settings=dict(study.objective),
                         method=study.method, search=study.search, output=Path(study.output or f"optimize-{name}"))
    if config.candidate_count > MAX_CANDIDATES:
        count = config.candidate_count
        shown = f"{count:,}" if count < 10 ** 12 else f"{float(count):.3g}"
        raise StudyError(f"{where(source, 'parameters')}: the grid has {shown} designs "
                         f"(at most {MAX_CANDIDATES:,}; use larger steps)")
    return config


def _design(reference: str, source: str, base_dir: Path) -> Design:
    path = Path(reference)
    try:
        return load_design(path if path.is_absolute() or not path.suffix else base_dir / path)
    except DesignError as error:
        raise refused(str(error), source, "design", value=reference, error=StudyError) from None


def numeric_parameters(design: Design) -> dict[str, float]:
    """The design's numeric TOML-level parameters by dotted name (``"cavity.radius_mm"``)."""
    return {f"{section}.{key}": value for section, table in design.spec.items() if isinstance(table, dict)
            for key, value in table.items() if isinstance(value, (int, float)) and not isinstance(value, bool)}


def _parameters(ranges: dict[str, _Range], data: dict[str, Any], design: Design,
                source: str) -> tuple[ParameterRange, ...]:
    if not ranges:
        raise refused('expected a table such as "cavity.radius_mm" = { min = 8, max = 10, step = 0.1 }', source,
                      "parameters", value=ranges, error=StudyError)
    known = numeric_parameters(design)
    swept = []
    for name, span in ranges.items():
        if name not in known:
            raise StudyError(f"{where(source, 'parameters', name)}: not a numeric parameter of {design.name} "
                             f"(expected one of {', '.join(sorted(known))})")
        integer_valued = isinstance(known[name], int)
        if integer_valued and not all(float(v).is_integer() for v in (span.min, span.max, span.step)):
            raise Refusal("step", f"{name} is an integer: expected whole-number min, max and step").locate(
                data["parameters"][name], source, "parameters", name, error=StudyError)
        swept.append(ParameterRange(name, span.min, span.max, span.step, integer_valued))
    return tuple(swept)


def _constraints(texts: list[str], design: Design, source: str) -> tuple[Constraint, ...]:
    known = numeric_parameters(design)
    constraints = []
    for index, text in enumerate(texts):
        place = where(source, "constraints", index)
        constraint = Constraint.parse(text, place)
        unknown = sorted(constraint.names - set(known))
        if unknown:
            raise StudyError(f"{place} = {text!r}: {unknown[0]!r} is not a numeric parameter of {design.name}")
        constraints.append(constraint)
    return tuple(constraints)
