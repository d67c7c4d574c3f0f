"""Study files: what to vary, what to compute, how to search - validated up front.

A study is a TOML file::

    name = "published-grid"            # optional; default: the file's stem
    design = "cylindrical-A"           # a shipped design, or a path relative to this file
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

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from softtip.design.model import Design, DesignError, load_design
from softtip.optimize.objectives import Objective, build_objective
from softtip.optimize.settings import SettingsReader, StudyError
from softtip.optimize.space import Constraint, ParameterRange, whole_steps
from softtip.tomlfile import read_toml

METHODS = ("grid", "bayes")
MAX_CANDIDATES = 1_000_000  # the candidate list is held in memory


@dataclass(frozen=True)
class SearchSettings:
    budget: int = 25  # at most this many designs evaluated (cache hits included)
    seed: int = 0
    initial: int | None = None  # size of the space-filling start; default 2 * parameters + 1
    batch: int = 1  # designs proposed per step (use the workers' count on a cluster)
    ei_tolerance: float = 1e-3  # stop when the best expected improvement is below this many sd ...
    patience: int = 3  # ... for this many steps in a row


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
        count = 1
        for parameter in self.parameters:
            count *= len(parameter.values)
        return count


def load_study(path: str | Path) -> StudyConfig:
    path = Path(path)
    data = read_toml(path, "study", StudyError)
    return study_from_dict(data, source=str(path), base_dir=path.parent, default_name=path.stem)


def study_from_dict(data: dict[str, Any], source: str = "study", base_dir: Path = Path("."),
                    default_name: str = "study") -> StudyConfig:
    """Validate a study table; ``base_dir`` resolves a design given as a relative path."""
    top = SettingsReader(source, data, "")
    name = top.string("name", default_name)
    design = _design(top, base_dir)
    method = top.choice("method", METHODS, "grid")
    output = Path(top.string("output", f"optimize-{name}"))
    parameters = _parameters(top, design)
    constraints = _constraints(top, design)
    objective_table = top.raw("objective", {})
    objective = build_objective(objective_table, design, source)
    search = _search(SettingsReader(source, top.raw("search", {}), "search"))
    top.finish()
    config = StudyConfig(name=name, source=source, design=design, parameters=parameters,
                         constraints=constraints, objective=objective, objective_settings=dict(objective_table),
                         method=method, search=search, output=output)
    if config.candidate_count > MAX_CANDIDATES:
        raise StudyError(f"{source}: parameters: the grid has {config.candidate_count:,} designs "
                         f"(at most {MAX_CANDIDATES:,}; use larger steps)")
    return config


def _design(top: SettingsReader, base_dir: Path) -> Design:
    reference = top.string("design")
    path = Path(reference)
    try:
        return load_design(path if path.is_absolute() or not path.suffix else base_dir / path)
    except DesignError as error:
        raise top.fail("design", str(error)) from None


def numeric_parameters(design: Design) -> dict[str, float]:
    """The design's numeric TOML-level parameters by dotted name (``"cavity.radius_mm"``)."""
    return {f"{section}.{key}": value for section, table in design.spec.items() if isinstance(table, dict)
            for key, value in table.items() if isinstance(value, (int, float)) and not isinstance(value, bool)}


def _parameters(top: SettingsReader, design: Design) -> tuple[ParameterRange, ...]:
    table = top.raw("parameters", None)
    if not isinstance(table, dict) or not table:
        raise top.fail("parameters", 'expected a table such as "cavity.radius_mm" = { min = 8, max = 10, step = 0.1 }')
    known = numeric_parameters(design)
    ranges = []
    for name, bounds in table.items():
        where = f'parameters."{name}"'
        if name not in known:
            raise StudyError(f"{top.source}: {where}: not a numeric parameter of {design.name} "
                             f"(expected one of {', '.join(sorted(known))})")
        reader = SettingsReader(top.source, bounds, where)
        minimum, maximum = reader.number("min"), reader.number("max")
        if maximum < minimum:
            raise reader.fail("max", f"expected max >= min = {minimum}")
        step = reader.number("step", maximum - minimum if maximum > minimum else 1.0, positive=True)
        reader.finish()
        if not whole_steps(minimum, maximum, step):
            raise reader.fail("step", f"expected (max - min) = {maximum - minimum:g} to be a whole number of steps")
        integer = isinstance(known[name], int)
        if integer and not all(float(v).is_integer() for v in (minimum, maximum, step)):
            raise reader.fail("step", f"{name} is an integer: expected whole-number min, max and step")
        ranges.append(ParameterRange(name, minimum, maximum, step, integer))
    return tuple(ranges)


def _constraints(top: SettingsReader, design: Design) -> tuple[Constraint, ...]:
    texts = top.raw("constraints", [])
    if not isinstance(texts, list) or not all(isinstance(t, str) for t in texts):
        raise top.fail("constraints",
                       "expected a list of strings such as \"magnets.circle_radius_mm < cavity.radius_mm\"")
    known = numeric_parameters(design)
    constraints = []
    for index, text in enumerate(texts):
        where = f"{top.source}: constraints[{index}]"
        constraint = Constraint.parse(text, where)
        unknown = sorted(constraint.names - set(known))
        if unknown:
            raise StudyError(f"{where} = {text!r}: {unknown[0]!r} is not a numeric parameter of {design.name}")
        constraints.append(constraint)
    return tuple(constraints)


def _search(reader: SettingsReader) -> SearchSettings:
    defaults = SearchSettings()
    settings = SearchSettings(
        budget=reader.integer("budget", defaults.budget, minimum=1),
        seed=reader.integer("seed", defaults.seed),
        initial=None if reader.optional("initial") is None else reader.integer("initial", minimum=1),
        batch=reader.integer("batch", defaults.batch, minimum=1),
        ei_tolerance=reader.number("ei_tolerance", defaults.ei_tolerance, non_negative=True),
        patience=reader.integer("patience", defaults.patience, minimum=1),
    )
    reader.finish()
    return settings
