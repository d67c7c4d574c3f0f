"""Design studies: grid, config validation, Bayesian search, FE cache, executors and the CLI contract.

FE-backed tests use a coarse 3 mm mesh and frictionless contact (~0.5 s per design).
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from softtip.cli.main import app
from softtip.design.model import shipped_design_path
from softtip.optimize.bayes import BayesianSearch, expected_improvement
from softtip.optimize.cache import FEResultCache, cache_key
from softtip.optimize.config import load_study, study_from_dict
from softtip.optimize import executors
from softtip.optimize.executors import DaskExecutor, InProcessExecutor, LocalPoolExecutor, make_executor
from softtip._core.config import PositiveNumber, schema
from softtip.optimize.errors import StudyError
from softtip.optimize.objectives import Objective, ObjectiveSettings, objective, objective_names
from softtip.optimize.runs import FEResult, Simulation
from softtip.optimize.space import Constraint, grid_candidates
from softtip.optimize.report import plot_objective, write_outputs
from softtip.optimize.study import DesignRecord, StudyResult, run_study
from softtip.twin import Twin

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FAST = {"friction": "none", "mesh_size_mm": 3.0}


def small_study(p1: list[float], p2: list[float] | None = None, **extra) -> dict:
    """A study table over explicit values of P1 (and P2), on the coarse fast mesh."""
    def span(values):
        step = round(values[1] - values[0], 10) if len(values) > 1 else 1.0
        return {"min": values[0], "max": values[-1], "step": step}

    parameters = {"cavity.radius_mm": span(p1)}
    if p2 is not None:
        parameters["magnets.circle_radius_mm"] = span(p2)
    objective = {"name": "feature_displacement", **FAST, **extra.pop("objective", {})}
    return {"design": "cylindrical-A", "parameters": parameters, "objective": objective, **extra}


@pytest.fixture
def count_fe_runs(monkeypatch):
    """Counts Twin.simulate calls in this process (the in-process executor runs here)."""
    calls = []
    original = Twin.simulate

    def counting(self, *args, **kwargs):
        calls.append(self.design.spec["cavity"]["radius_mm"])
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Twin, "simulate", counting)
    return calls


# --------------------------------------------------------------------------- grid and config


def test_published_grid_has_105_designs_in_order_with_the_values_a_user_writes():
    study = load_study(EXAMPLES / "published-grid.toml")
    candidates = grid_candidates(study.parameters)
    assert len(candidates) == 105 == study.candidate_count
    p1 = [round(8.0 + 0.1 * k, 1) for k in range(21)]  # 8.3, not 8.300000000000001: what a user writes
    p2 = [4.5, 5.0, 5.5, 6.0, 6.5]
    assert candidates == [{"cavity.radius_mm": a, "magnets.circle_radius_mm": b} for a in p1 for b in p2]
    simulation = study.objective.simulations[0]
    assert (simulation.mesh_size_mm, simulation.friction, simulation.indenter, simulation.depth_mm,
            simulation.thickness_mm) == (1.5, "stick", "board", 1.0, 1.6)
    assert study.objective.goal == "max" and study.method == "grid"


def test_published_search_searches_the_same_grid():
    grid, search = load_study(EXAMPLES / "published-grid.toml"), load_study(EXAMPLES / "published-search.toml")
    assert search.method == "bayes" and search.search.budget < 27
    assert grid_candidates(search.parameters) == grid_candidates(grid.parameters)
    assert search.objective.simulations == grid.objective.simulations


def test_integer_parameters_step_in_integers():
    study = study_from_dict(small_study([9.0], objective={}, constraints=[]) | {
        "parameters": {"magnets.count": {"min": 3, "max": 5, "step": 1}}})
    assert [c["magnets.count"] for c in grid_candidates(study.parameters)] == [3, 4, 5]
    assert all(isinstance(c["magnets.count"], int) for c in grid_candidates(study.parameters))


@pytest.mark.parametrize("change, message", [
    ({"methd": "grid"}, "methd: unknown key"),
    ({"method": "random"}, "method = 'random': expected one of grid, bayes"),
    ({"design": "cylindrical-Z"}, "design = 'cylindrical-Z'"),
    ({"parameters": {}}, "parameters = {}: expected a table"),
    ({"parameters": {"cavity.radius": {"min": 8, "max": 9, "step": 0.5}}},
     'parameters."cavity.radius": not a numeric parameter of cylindrical-A'),
    ({"parameters": {"cavity.radius_mm": {"min": 9, "max": 8, "step": 0.5}}},
     'parameters."cavity.radius_mm".max = 8: expected max >= min'),
    ({"parameters": {"cavity.radius_mm": {"min": 8, "max": 9, "step": 0.3}}},
     'parameters."cavity.radius_mm".step = 0.3: expected (max - min) = 1 to be a whole number of steps'),
    ({"parameters": {"cavity.radius_mm": {"min": 8, "max": 9, "step": -1}}},
     'parameters."cavity.radius_mm".step = -1: expected a positive number'),
    ({"parameters": {"cavity.radius_mm": {"min": 8, "max": 9, "stp": 1}}}, 'parameters."cavity.radius_mm".stp'),
    ({"parameters": {"magnets.count": {"min": 3, "max": 4, "step": 0.5}}},
     'parameters."magnets.count".step = 0.5: magnets.count is an integer'),
    ({"parameters": {"cavity.radius_mm": {"min": 1, "max": 2e5, "step": 1}, "magnets.circle_radius_mm":
                     {"min": 1, "max": 10, "step": 1}}}, "the grid has 2,000,000 designs"),
    ({"constraints": ["cavity.radius_mm +"]}, "constraints[0] = 'cavity.radius_mm +': not an expression"),
    ({"constraints": ["cavity.radius_mm"]}, "expected a comparison"),
    ({"constraints": ["cavity.radius_mm < __import__('os').getpid()"]}, "unsupported"),
    ({"constraints": ["cavity.radius_mm < cavity.radius"]}, "'cavity.radius' is not a numeric parameter"),
    ({"constraints": "cavity.radius_mm < 9"}, "constraints = 'cavity.radius_mm < 9': expected a list"),
    ({"objective": {"name": "max_displacement"}}, "objective.name = 'max_displacement': expected one of"),
    ({"objective": {"friction": "coulomb"}}, "objective.friction = 'coulomb': expected one of none, stick"),
    ({"objective": {"mesh_size_mm": 0}}, "objective.mesh_size_mm = 0: expected a positive number"),
    ({"objective": {"depht_mm": 1.0}}, "objective.depht_mm: unknown key"),
    ({"objective": {"goal": "maximise"}}, "objective.goal = 'maximise': expected one of max, min"),
    ({"objective": {"magnet": 4}}, "objective.magnet = 4: expected max, mean or a magnet index 0..3"),
    ({"objective": {"module": "no_such_objectives"}}, "objective.module = 'no_such_objectives': cannot import"),
    ({"search": {"budget": 0}}, "search.budget = 0: expected an integer >= 1"),
    ({"search": {"seed": 1.5}}, "search.seed = 1.5: expected an integer"),
])
def test_study_mistakes_are_one_line_errors_naming_the_key(change, message):
    study = small_study([8.0, 9.0], [4.5, 5.5])
    study["objective"].update(change.get("objective", {}))
    study.update({k: v for k, v in change.items() if k != "objective"})
    with pytest.raises(StudyError) as error:
        study_from_dict(study, source="s.toml")
    assert message in str(error.value) and str(error.value).startswith("s.toml") and "\n" not in str(error.value)


def test_design_paths_are_relative_to_the_study_file(tmp_path):
    (tmp_path / "designs").mkdir()
    design = shipped_design_path("cylindrical-A").read_text()
    (tmp_path / "designs" / "mine.toml").write_text(design)
    (tmp_path / "study.toml").write_text(textwrap.dedent("""
        design = "designs/mine.toml"
        [parameters]
        "cavity.radius_mm" = { min = 8.0, max = 8.5, step = 0.5 }
    """))
    study = load_study(tmp_path / "study.toml")
    assert study.design.name == "mine" and study.name == "study" and study.method == "grid"


def test_constraints_are_arithmetic_comparisons_over_dotted_parameters():
    rule = Constraint.parse("magnets.circle_radius_mm + max(magnets.diameter_mm, 1) / 2 <= cavity.radius_mm - 3",
                            "c")
    assert rule.names == {"magnets.circle_radius_mm", "magnets.diameter_mm", "cavity.radius_mm"}
    values = {"magnets.circle_radius_mm": 5.0, "magnets.diameter_mm": 2.0, "cavity.radius_mm": 9.0}
    assert rule.holds(values) and not rule.holds(values | {"cavity.radius_mm": 8.9})
    chained = Constraint.parse("4 < magnets.circle_radius_mm ** 2 / 5 < 6", "c")
    assert chained.holds({"magnets.circle_radius_mm": 5.0}) and not chained.holds({"magnets.circle_radius_mm": 6.0})
    for bad in ("a.b == 1", "a.b < 1 and a.b > 0", "a.b < c.d()", "a.b < 'x'", "a.b < lambda: 1", "a.b < sqrt()"):
        with pytest.raises(StudyError):
            Constraint.parse(bad, "c")


# --------------------------------------------------------------------------- Bayesian search


def bumpy(points: np.ndarray) -> np.ndarray:
    """An interior optimum at (0.7, 0.3) on a gentle slope with a weaker second hill at (0.15, 0.85)."""
    x, y = points[:, 0], points[:, 1]
    main_hill = np.exp(-((x - 0.7) ** 2 + (y - 0.3) ** 2) / 0.05)
    second_hill = 0.6 * np.exp(-((x - 0.15) ** 2 + (y - 0.85) ** 2) / 0.02)
    return main_hill + second_hill + 0.1 * x


def run_search(points, values, **settings) -> BayesianSearch:
    search = BayesianSearch(points, **settings)
    while batch := search.ask():
        for index in batch:
            search.tell(index, values[index])
    return search


GRID = np.array([(x, y) for x in np.linspace(0, 1, 21) for y in np.linspace(0, 1, 21)])  # 441 candidates


def test_bayes_finds_the_optimum_of_an_analytic_function_in_few_evaluations():
    values = bumpy(GRID)
    for seed in range(2):
        search = run_search(GRID, values, budget=60, seed=seed)
        best = max(search.values, key=search.values.get)
        assert best == int(np.argmax(values)), f"seed {seed}"
        assert len(search.asked) <= 30, f"seed {seed}: {len(search.asked)} of 441 candidates"
        assert "expected improvement" in search.stop_reason  # it stopped by itself, not on the budget
        assert len(set(search.asked)) == len(search.asked)  # never the same candidate twice


def test_bayes_is_deterministic_for_a_seed_and_the_seed_matters():
    values = bumpy(GRID)
    first = run_search(GRID, values, budget=15, seed=7, batch=2)
    again = run_search(GRID, values, budget=15, seed=7, batch=2)
    other = run_search(GRID, values, budget=15, seed=8, batch=2)
    assert first.asked == again.asked and len(first.asked) == 15 and first.stop_reason.startswith("budget")
    assert first.asked != other.asked


def test_bayes_survives_failed_evaluations():
    values = bumpy(GRID)
    broken = {int(i) for i in np.argsort(values)[-20:-1]}  # most of the hill around the optimum fails
    search = BayesianSearch(GRID, budget=30, seed=1)
    while batch := search.ask():
        for index in batch:
            search.tell(index, None if index in broken else values[index])
    assert search.failed and not search.failed & set(search.values)
    assert max(search.values.values()) == values.max()


def test_expected_improvement_is_zero_far_below_and_linear_far_above():
    ei = expected_improvement(np.array([-10.0, 10.0, 0.0]), np.array([0.1, 0.1, 1.0]), best=0.0, xi=0.0)
    assert ei[0] == pytest.approx(0.0, abs=1e-12) and ei[1] == pytest.approx(10.0)
    assert ei[2] == pytest.approx(1 / math.sqrt(2 * math.pi))


# --------------------------------------------------------------------------- cache, feasibility, failures


def test_a_second_run_computes_nothing_and_a_partial_cache_only_the_rest(tmp_path, count_fe_runs):
    study = study_from_dict(small_study([8.0, 9.0, 10.0]))
    cache = FEResultCache(tmp_path / "fe")
    first = run_study(study, InProcessExecutor(), cache)
    assert (first.fe_runs, first.cache_hits, len(count_fe_runs)) == (3, 0, 3)
    files = sorted(cache.root.glob("*.npz"))
    assert len(files) == 3 and all(f.read_bytes().startswith(b"PK") for f in files)  # npz + JSON, not pickle

    again = run_study(study, InProcessExecutor(), cache)
    assert (again.fe_runs, again.cache_hits, len(count_fe_runs)) == (0, 3, 3)
    assert [r.objective for r in again.records] == [r.objective for r in first.records]  # exact: arrays as computed
    assert all(r.cached for r in again.records)

    # a killed sweep: one result never written, one half-written
    cache.path(cache_key(study.design.with_params(**{"cavity.radius_mm": 9.0}).spec,
                         study.objective.simulations[0])).unlink()
    cache.path(cache_key(study.design.with_params(**{"cavity.radius_mm": 10.0}).spec,
                         study.objective.simulations[0])).write_text('{"key": "trunc')
    resumed = run_study(study, InProcessExecutor(), cache)
    assert (resumed.fe_runs, resumed.cache_hits) == (2, 1) and count_fe_runs[3:] == [9.0, 10.0]
    assert [r.objective for r in resumed.records] == [r.objective for r in first.records]


def test_a_changed_digit_or_another_designs_result_is_never_served(tmp_path, count_fe_runs, capsys):
    # as found by hand: one digit changed in a cached FE result was served to optimize as a hit
    study = study_from_dict(small_study([9.0, 10.0]))
    cache = FEResultCache(tmp_path / "fe")
    first = run_study(study, InProcessExecutor(), cache)
    nine, ten = (cache.path(cache_key(study.design.with_params(**{"cavity.radius_mm": r}).spec,
                                      study.objective.simulations[0])) for r in (9.0, 10.0))
    with np.load(ten, allow_pickle=False) as entry:  # rewritten with one value's 4th digit changed
        arrays = dict(entry)
    arrays["field_change_T"][0, 2] *= 1.001
    changed = tmp_path / "changed.npz"
    np.savez(changed, **arrays)
    ten.replace(nine)  # the 10 mm design's valid result under the 9 mm design's key
    changed.replace(ten)
    capsys.readouterr()
    again = run_study(study, InProcessExecutor(), cache)
    assert (again.fe_runs, again.cache_hits, count_fe_runs[2:]) == (2, 0, [9.0, 10.0])
    assert [r.objective for r in again.records] == [r.objective for r in first.records]
    warnings = capsys.readouterr().err.splitlines()
    assert len(warnings) == 2 and str(nine) in warnings[0] and "made for another FE result" in warnings[0]
    assert str(ten) in warnings[1] and "checksum mismatch" in warnings[1]
    assert run_study(study, InProcessExecutor(), cache).cache_hits == 2  # stored again, and served


def test_cache_key_follows_the_physics_not_the_spelling():
    spec = study_from_dict(small_study([9.0])).design.spec
    simulation = Simulation(**FAST)
    renamed = spec | {"name": "other", "description": "same design"}
    as_integer = spec | {"cavity": spec["cavity"] | {"radius_mm": 9}}
    assert cache_key(spec, simulation) == cache_key(renamed, simulation) == cache_key(as_integer, simulation)
    assert cache_key(spec, simulation) != cache_key(spec, Simulation(friction="none", mesh_size_mm=2.5))
    assert cache_key(spec, simulation) != cache_key(spec | {"cavity": spec["cavity"] | {"radius_mm": 9.1}},
                                                    simulation)


def test_infeasible_designs_are_recorded_not_computed(tmp_path, count_fe_runs):
    # cavity radius 12.5 is the body's radius (refused by the design validator); the constraint drops 8.0
    study = study_from_dict(small_study([8.0, 10.25, 12.5], constraints=["cavity.radius_mm >= 9"]))
    result = run_study(study, InProcessExecutor(), FEResultCache(tmp_path / "fe"))
    by_p1 = {r.params["cavity.radius_mm"]: r for r in result.records}
    # the magnet under a board pushed 1 mm moves down by more than half the push, and never more than it
    assert by_p1[10.25].status == "ok" and 0.5 < by_p1[10.25].objective < 1.0
    assert by_p1[8.0].status == "infeasible" and "constraint 'cavity.radius_mm >= 9' violated" in by_p1[8.0].reason
    assert by_p1[12.5].status == "infeasible" and "cavity.radius_mm = 12.5" in by_p1[12.5].reason
    assert count_fe_runs == [10.25] and result.counts()["infeasible"] == 2
    table = result.to_json()["table"]
    assert [(row["params"]["cavity.radius_mm"], row["feasible"]) for row in table] == [(10.25, True), (8.0, False),
                                                                                       (12.5, False)]
    files = write_outputs(result, tmp_path / "out")  # one parameter: a curve
    assert Path(files["plot"]).read_bytes()[:4] == b"\x89PNG"
    assert len(Path(files["csv"]).read_text().splitlines()) == 4


def test_more_than_two_parameters_are_mapped_over_the_first_two_at_the_best_design(tmp_path):
    study = study_from_dict(small_study([8.0, 9.0], [4.5, 5.5]) | {"parameters": {
        "cavity.radius_mm": {"min": 8.0, "max": 9.0, "step": 1.0},
        "magnets.circle_radius_mm": {"min": 4.5, "max": 5.5, "step": 1.0},
        "magnets.depth_mm": {"min": 1.0, "max": 1.5, "step": 0.5}}})
    records = [DesignRecord(index=i, params=p, status="ok", objective=float(i), evaluation=i + 1)
               for i, p in enumerate(grid_candidates(study.parameters))]
    result = StudyResult(config=study, records=records, fe_runs=8, cache_hits=0, wall_seconds=1.0,
                         executor="test", stop_reason="grid complete")
    assert result.best.params == {"cavity.radius_mm": 9.0, "magnets.circle_radius_mm": 5.5, "magnets.depth_mm": 1.5}
    path = plot_objective(result, tmp_path / "map.png")
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_a_design_whose_fe_run_fails_is_recorded_and_not_cached(tmp_path, monkeypatch):
    original = Twin.simulate

    def fragile(self, *args, **kwargs):
        if self.design.spec["cavity"]["radius_mm"] == 9.0:
            raise RuntimeError("solver\ndiverged")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Twin, "simulate", fragile)
    cache = FEResultCache(tmp_path / "fe")
    result = run_study(study_from_dict(small_study([8.0, 9.0])), InProcessExecutor(), cache)
    failed = result.records[1]
    assert failed.status == "failed" and failed.reason == "RuntimeError: solver diverged"
    assert result.records[0].status == "ok" and result.best is result.records[0]
    assert len(list(cache.root.glob("*.npz"))) == 1


# --------------------------------------------------------------------------- objectives are pluggable


@schema
class ScaledForce(ObjectiveSettings):
    scale: PositiveNumber = 1.0


@objective("test_vertical_force", ScaledForce)
def vertical_force(settings, design) -> Objective:
    return Objective(name="test_vertical_force", simulations=(Simulation.of(settings),), goal="min", unit="N",
                     score=lambda design, results: settings.scale * float(results[0].force_N[2]))


def test_objectives_register_from_other_modules(tmp_path, monkeypatch):
    assert {"feature_displacement", "test_vertical_force"} <= set(objective_names())
    study = study_from_dict(small_study([8.0, 9.5], objective={"name": "test_vertical_force", "scale": 2.0}))
    assert study.objective.goal == "min" and study.objective.unit == "N"
    result = run_study(study, InProcessExecutor(), FEResultCache(tmp_path / "fe"))
    forces = [r.objective for r in result.records]
    assert all(f > 0 for f in forces) and result.best.objective == min(forces)  # minimised
    with pytest.raises(ValueError, match="already registered"):
        objective("test_vertical_force")(lambda settings, design: None)

    # a module named by the study registers its objectives when the study is read
    (tmp_path / "lab_objectives.py").write_text(textwrap.dedent("""
        from softtip.optimize.objectives import Objective, objective
        from softtip.optimize.runs import Simulation

        @objective("lab_rotation")
        def lab_rotation(settings, design):
            return Objective(name="lab_rotation", simulations=(Simulation.of(settings),), unit="rad",
                             score=lambda design, results: float(abs(results[0].magnet_rotvecs_rad).max()))
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    study = study_from_dict(small_study([8.0], objective={"name": "lab_rotation", "module": "lab_objectives"}))
    assert study.objective.name == "lab_rotation" and study.objective.goal == "max"


# --------------------------------------------------------------------------- executors


@pytest.mark.slow
def test_dask_local_cluster_gives_the_local_pool_results(tmp_path, monkeypatch):
    from dask.distributed import LocalCluster

    study = study_from_dict(small_study([8.5, 9.5], [4.5, 6.5]))  # 4 designs
    monkeypatch.setattr(executors, "TASKS_PER_WORKER_PROCESS", 1)  # the pool is renewed after every 2 designs
    with LocalPoolExecutor(workers=2) as pool:
        local = run_study(study, pool, FEResultCache(tmp_path / "local"))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster, DaskExecutor(cluster.scheduler_address) as dask:
        remote = run_study(study, dask, FEResultCache(tmp_path / "dask"))
    assert "Dask cluster" in remote.executor and local.fe_runs == remote.fe_runs == 4
    assert [r.status for r in remote.records] == ["ok"] * 4
    np.testing.assert_allclose([r.objective for r in remote.records], [r.objective for r in local.records],
                               rtol=1e-10)
    for params in grid_candidates(study.parameters):  # the cached FE results, field by field
        spec, simulation = study.design.with_params(**params).spec, study.objective.simulations[0]
        pooled = FEResultCache(tmp_path / "local").get(spec, simulation)
        distributed = FEResultCache(tmp_path / "dask").get(spec, simulation)
        for field in FEResult.ARRAY_FIELDS:
            np.testing.assert_allclose(getattr(distributed, field), getattr(pooled, field), rtol=1e-10, atol=1e-18)


def test_an_unreachable_scheduler_is_a_one_line_error():
    with pytest.raises(StudyError, match="cannot reach the Dask scheduler"):
        DaskExecutor("tcp://127.0.0.1:9", timeout_s=1.0)
    with pytest.raises(StudyError, match="expected an address such as tcp://HOST:8786"):
        make_executor("127.0.0.1:8786")


# --------------------------------------------------------------------------- CLI


def write_study(path: Path, study: dict) -> Path:
    lines = [f'design = "{study["design"]}"', f'method = "{study.get("method", "grid")}"', "[parameters]"]
    lines += [f'"{name}" = {{ min = {b["min"]}, max = {b["max"]}, step = {b["step"]} }}'
              for name, b in study["parameters"].items()]
    lines += ["[objective]"] + [f"{k} = {json.dumps(v)}" for k, v in study["objective"].items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_cli_json_contract_and_resume(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path / "cache"))
    config = write_study(tmp_path / "study.toml", small_study([9.0, 12.5], [4.5, 5.5]))
    runner = CliRunner()
    args = ["optimize", "--config", str(config), "--workers", "1", "--json", "--output", str(tmp_path / "out")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["best"]["params"] == {"cavity.radius_mm": 9.0, "magnets.circle_radius_mm": 4.5}
    assert 0.5 < report["best"]["objective"] < 1.0  # mm, under a 1 mm push
    assert {k: report["evaluations"][k] for k in ("designs", "fe_runs", "cache_hits", "infeasible")} == {
        "designs": 2, "fe_runs": 2, "cache_hits": 0, "infeasible": 2}
    assert [(r["params"]["cavity.radius_mm"], r["feasible"], r["objective"] is not None) for r in report["table"]] == [
        (9.0, True, True), (9.0, True, True), (12.5, False, False), (12.5, False, False)]
    csv_lines = (tmp_path / "out" / "results.csv").read_text().splitlines()
    assert len(csv_lines) == 5 and csv_lines[0].startswith("evaluation,index,cavity.radius_mm")
    assert (tmp_path / "out" / "objective.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((tmp_path / "out" / "results.json").read_text())["best"] == report["best"]

    again = json.loads(runner.invoke(app, [*args, "--force"]).stdout)  # the results of the first run replaced
    assert (again["evaluations"]["fe_runs"], again["evaluations"]["cache_hits"]) == (0, 2)
    assert again["best"] == report["best"]

    table = runner.invoke(app, args[:-3] + ["--output", str(tmp_path / "out"), "--force"])  # the human-readable form
    assert table.exit_code == 0 and "0 FE runs computed, 2 from the cache, 2 infeasible" in table.stdout
    assert "infeasible: 12.5, 4.5: cylindrical-A: cavity.radius_mm = 12.5" in " ".join(table.stdout.split())


@pytest.mark.parametrize("args, message", [
    (["--config", "missing.toml"], "--config = missing.toml: does not exist"),
    (["--scheduler", "localhost"], "--scheduler localhost: expected an address"),
    (["--workers", "0"], "--workers = 0: expected a number >= 1 and <= 8"),
])
def test_cli_mistakes_are_one_line_errors(tmp_path, args, message):
    config = write_study(tmp_path / "study.toml", small_study([9.0]))
    full = (["--config", str(config)] if "--config" not in args else []) + args
    result = CliRunner().invoke(app, ["optimize", *full])
    assert result.exit_code == 2 and message in result.output
    assert "Traceback" not in result.output and len(result.output.strip().splitlines()) <= 2
