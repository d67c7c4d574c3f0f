"""The reduced-order twin: load parameters -> magnet poses and force, in microseconds.

Built automatically for one design and one indenter family, in three stages:

1. influence matrices of the contact surface (:mod:`softtip.mechanics.contact.influence`),
   from one factorisation of the finite-element stiffness;
2. a design of experiments over the load parameters, each solved exactly on
   those matrices (milliseconds each, on every core), with contact on cells
   of the indenter's footprint (:mod:`softtip.mechanics.contact.footprint`): with
   contact on nodes, a board narrower than two elements makes the response
   step as rows of nodes enter its footprint, steps no interpolator follows;
3. a smooth interpolator fitted to it: small tanh networks (scikit-learn's
   MLPRegressor) from the scaled load parameters to the magnets' rigid poses
   and the force, two from independent initialisations, averaged. Networks
   are the right interpolator here because the response is smooth but not
   separable in six dimensions, and they evaluate as a few small matrix
   products (fast in batch).

It reports its own error on held-out *finite-element* solves (not on stage-2
samples), in % of full scale of every sensor axis and of the range of every
magnet displacement. It is stored as npz (weights) + JSON (everything else)
and reloaded without rebuilding; nothing is pickled.

Load parameters (SI): contact position x, y (m), indenter angle about the
vertical axis (rad), normal depth (m), tangential travel tx, ty (m). With
sticking friction the twin covers the loads the board holds without sliding
at the spec's friction coefficient (|Ft| <= 0.7 Fz): a shallow push dragged
far would hold the skin with up to five times its normal force, which no
real board does, and the response there grows steeply from zero depth, a
corner no smooth interpolator follows. Samples and held-out loads are drawn
from the load ranges and those that would slide are set aside; the report
gives the error on them too.
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from softtip import __version__
from softtip._core.archive import read_archive, write_archive
from softtip._core.network import fold_scaling, predict_batch
from softtip._core.progress import SILENT, Progress, Task
from softtip._core.units import MM, UT_PER_T
from softtip.design.model import Design, design_from_dict
from softtip.mechanics.contact import (CELL_SIZE, FootprintBody, LoadCase, SurfaceInfluence, SurfacePatch,
                                      solve_footprint_contact, stiffness_compliance)
from softtip.mechanics.indenters import make_indenter
from softtip.mechanics.poses import MagnetPoses
from softtip.twin.engines import Response
from softtip.twin.readout import Readout

# 2: a board enters by the foot of its centre line; 3: footprint contact; 4: an ensemble of networks
FORMAT, SCHEMA_VERSION = "softtip-reduced-twin", 5


class ReducedTwinError(ValueError):
    """A reduced-twin file that cannot be trusted."""
PARAMETERS = ("x_m", "y_m", "angle_rad", "depth_m", "tx_m", "ty_m")
# with contact on footprint cells the samples are smooth, and more of them lower the error's tail:
# over 500 held-out loads (one network, sliding loads included), the largest sensor error was
# 2.9 % of full scale from 5,000 samples and 1.5-2.1 % from 8,000 (five fits); 12,000 gained nothing
SAMPLES = 8000
# networks from independent initialisations, averaged: their errors' tails fall on different loads,
# and two fit side by side on two cores in the time of one (500 held-out loads, four seeds: largest
# sensor error 1.65-2.01 % of full scale for one network, 1.39-1.89 % for pairs of them)
ENSEMBLE = 2
_SCALING = ("x_mean", "x_scale", "y_mean", "y_scale")


@dataclass(frozen=True)
class LoadRanges:
    """The load space the reduced twin covers."""

    position_radius: float = 5 * MM  # contact positions within this radius of the axis
    depth: float = 3 * MM
    tangential: float = 2 * MM  # tangential travel within this radius
    angle: tuple[float, float] = (0.0, math.pi)  # a board is symmetric under a half turn
    shear_fraction: float = 0.5  # share of samples with tangential travel
    # depths have a density growing linearly with depth, from 5 % of the range: the magnets
    # approach the sensors and the response changes fastest in the deepest pushes

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        radius = self.position_radius * np.sqrt(rng.uniform(size=n))
        phase = rng.uniform(0, 2 * np.pi, n)
        shear = rng.uniform(size=n) < self.shear_fraction
        t_radius = self.tangential * np.sqrt(rng.uniform(size=n)) * shear
        t_phase = rng.uniform(0, 2 * np.pi, n)
        depth = self.depth * np.sqrt(rng.uniform(0.05 ** 2, 1.0, n))
        return np.column_stack([radius * np.cos(phase), radius * np.sin(phase), rng.uniform(*self.angle, n), depth,
                                t_radius * np.cos(t_phase), t_radius * np.sin(t_phase)])


@dataclass(frozen=True)
class IndenterFamily:
    kind: str = "board"
    thickness: float = 1.6 * MM
    radius: float = 5 * MM
    # "stick" is the easier map to interpolate: Coulomb's onset of sliding puts a kink in the
    # response (500 held-out loads: largest errors 2.5 % of full scale, 5.1 % of displacement range).
    # A sticking twin covers the loads the board holds without sliding at mu (see slides)
    friction: str = "stick"
    mu: float = 0.7  # the spec's soft body / board coefficient

    def slides(self, force: np.ndarray) -> np.ndarray:
        """Which loads, by their forces (N, 3), need more friction than ``mu`` to hold: with
        ``stick`` these lie outside the twin's domain (the board would slide over the skin)."""
        force = np.atleast_2d(force)
        if self.friction != "stick":
            return np.zeros(len(force), dtype=bool)
        return np.hypot(force[:, 0], force[:, 1]) > self.mu * force[:, 2]

    def parameters(self, load: LoadCase) -> np.ndarray:
        """The load parameters (6,) of a load case of this family (the inverse of :meth:`load`)."""
        indenter = load.indenter
        kind = type(indenter).__name__.lower()
        if kind != self.kind:
            raise ValueError(f"indenter = {kind}: this reduced twin was built for a {self.kind}")
        if load.friction != self.friction:
            raise ValueError(f"friction = {load.friction!r}: this reduced twin was built with {self.friction!r}")
        if kind == "board" and not math.isclose(indenter.thickness, self.thickness):
            raise ValueError(f"board thickness = {indenter.thickness} m: this reduced twin was built for "
                             f"{self.thickness} m")
        if kind == "sphere" and not math.isclose(indenter.radius, self.radius):
            raise ValueError(f"sphere radius = {indenter.radius} m: this reduced twin was built for {self.radius} m")
        return np.array([*load.position, getattr(indenter, "angle", 0.0), load.depth, *load.tangential])

    def load(self, p: np.ndarray) -> LoadCase:
        indenter = make_indenter(self.kind, thickness=self.thickness, angle_deg=math.degrees(p[2]),
                                 radius=self.radius)
        return LoadCase(indenter, float(p[3]), tangential=(float(p[4]), float(p[5])),
                        position=(float(p[0]), float(p[1])), friction=self.friction, mu=self.mu)


def _features(params: np.ndarray, family: IndenterFamily) -> np.ndarray:
    """Inputs of the network. A board is infinitely long, so a load depends on where its centre
    line lies, not on the point of that line given: the line enters by its foot from the axis,
    ``(p . a) a`` with ``a`` across the board, which also keeps the board's half-turn symmetry, and
    the angle as (cos 2a, sin 2a). Other indenters enter by their position."""
    angle = params[:, 2]
    if family.kind == "board":
        across = np.column_stack([-np.sin(angle), np.cos(angle)])
        offset = np.einsum("ij,ij->i", params[:, :2], across)
        position = offset[:, None] * across
    else:
        position = params[:, :2]
    return np.column_stack([position, np.cos(2 * angle), np.sin(2 * angle), params[:, 3:6]])


# stage 2 runs in worker processes that inherit these through fork
_WORKER: dict = {}


def _solve_samples(rows: np.ndarray) -> np.ndarray:
    from threadpoolctl import threadpool_limits

    influence, patch, family = _WORKER["influence"], _WORKER["patch"], _WORKER["family"]
    out = np.empty((len(rows), influence.magnets.shape[0] + 3))
    # one BLAS thread per worker: the workers fill the cores, more threads only contend
    with threadpool_limits(limits=1):
        for k, p in enumerate(rows):
            solution = solve_footprint_contact(FootprintBody(patch, influence.compliance_of), family.load(p))
            out[k] = np.concatenate([solution.magnet_poses.rigid.ravel(), solution.force])
    return out


@dataclass
class ReducedTwin:
    design: Design
    family: IndenterFamily
    ranges: LoadRanges
    mesh_size: float
    networks: list[dict]  # each: weights, biases, input/output scaling (arrays); their outputs are averaged
    report: dict = field(default_factory=dict)  # build timings and held-out errors
    contact_layer_size: float | None = None  # element size (m) in the layer indenters reach, if refined

    # ------------------------------------------------------------------ evaluation

    def predict(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 6) load parameters -> magnet rigid poses (N, M, 6) [t (m), rotvec (rad)] and force (N, 3) N."""
        params = np.atleast_2d(np.asarray(params, dtype=float))
        features = _features(params, self.family)
        out = sum(predict_batch(layers, features) for layers in self._single_precision) / len(self.networks)
        # no contact, no response: the network is exact at zero depth only up to its error
        out *= (params[:, 3] > 0)[:, None]
        return out[:, :-3].reshape(len(params), -1, 6), out[:, -3:]

    def respond_parameters(self, params: np.ndarray) -> Response:
        """Magnet poses (N, M, 3) and force (N, 3) for (N, 6) load parameters: the batch path."""
        rigid, force = self.predict(params)
        return Response(poses=MagnetPoses.from_rigid(rigid), force=force, model="reduced")

    def respond(self, loads) -> Response:
        """The engine interface: load cases of this twin's indenter family."""
        return self.respond_parameters(np.array([self.family.parameters(load) for load in loads]))

    @cached_property
    def _single_precision(self) -> list[list]:
        """The networks as run-time layers in single precision, cast once for every batch to come:
        three times faster in batch, and their rounding (a few 1e-6 of each output's spread) is three
        orders of magnitude below the networks' own error."""
        return [[(w.astype(np.float32), b.astype(np.float32)) for w, b in _runtime_layers(net)]
                for net in self.networks]

    @cached_property
    def _readout(self) -> Readout:
        """The nominal readout, for the errors in % of the sensors' full scale."""
        return Readout(self.design)

    # ------------------------------------------------------------------ storage

    def save(self, path: str | Path) -> Path:
        """Write ``path`` (.npz: the weights, and everything else as its checksummed JSON metadata)."""
        path = Path(path).with_suffix(".npz")
        arrays = {}
        for j, net in enumerate(self.networks):
            arrays |= {f"network_{j}_weight_{k}": w for k, w in enumerate(net["weights"])}
            arrays |= {f"network_{j}_bias_{k}": b for k, b in enumerate(net["biases"])}
            arrays |= {f"network_{j}_{k}": net[k] for k in _SCALING}
        meta = {"format": FORMAT, "schema_version": SCHEMA_VERSION, "softtip": __version__, "design": self.design.spec,
                "design_name": self.design.name, "family": vars(self.family),
                "ranges": {k: v for k, v in vars(self.ranges).items()}, "mesh_size_m": self.mesh_size,
                "contact_layer_size_m": self.contact_layer_size, "networks": len(self.networks),
                "layers": len(self.networks[0]["weights"]), "parameters": PARAMETERS,
                "report": json.loads(json.dumps(self.report, default=float))}
        return write_archive(path, meta, arrays)

    @classmethod
    def load(cls, path: str | Path) -> "ReducedTwin":
        """Read a saved reduced twin; refuses foreign, truncated or tampered files with one line."""
        path = Path(path).with_suffix(".npz")
        meta, data = read_archive(path, FORMAT, SCHEMA_VERSION, "reduced twin", ReducedTwinError)
        layers = int(meta["layers"])
        try:
            networks = [{"weights": [data[f"network_{j}_weight_{k}"] for k in range(layers)],
                         "biases": [data[f"network_{j}_bias_{k}"] for k in range(layers)],
                         **{k: data[f"network_{j}_{k}"] for k in _SCALING}} for j in range(int(meta["networks"]))]
        except KeyError as missing:
            raise ReducedTwinError(f"{path}: inconsistent reduced twin: array {missing.args[0]!r} is missing") from None
        ranges = meta["ranges"]
        ranges["angle"] = tuple(ranges["angle"])
        return cls(design=design_from_dict(meta["design"], source=meta["design_name"]),
                   family=IndenterFamily(**meta["family"]), ranges=LoadRanges(**ranges),
                   mesh_size=float(meta["mesh_size_m"]), networks=networks, report=meta["report"],
                   contact_layer_size=meta.get("contact_layer_size_m"))

    # ------------------------------------------------------------------ building

    @classmethod
    def build(cls, design: Design, family: IndenterFamily = IndenterFamily(), ranges: LoadRanges = LoadRanges(),
              mesh_size: float = 1.5 * MM, samples: int = SAMPLES, holdout: int = 12, exact_holdout: int = 500,
              hidden: tuple[int, ...] = (128, 128), ensemble: int = ENSEMBLE, seed: int = 0, workers: int = 2,
              contact_layer_size: float | None = None, progress: Progress = SILENT) -> "ReducedTwin":
        """Influence matrices, ``samples`` exact contact solves on them, the fitted network, and its
        errors on ``holdout`` FE solves and on ``exact_holdout`` exact solves on the influence
        matrices. ``contact_layer_size``: element size (m) in the layer the load ranges reach
        (default: ``mesh_size`` everywhere)."""
        from softtip.mechanics.fe import BodyModel
        from softtip.mechanics.mesh import mesh_design

        timings = {}
        start = time.perf_counter()
        # contact can reach as low as the deepest push below the top surface, plus a margin
        reach = ranges.depth + 1.5 * MM
        layer = None if contact_layer_size is None else (reach, contact_layer_size)
        body = BodyModel.for_design(design, mesh_design(design, mesh_size, contact_layer=layer))
        lowest = design.height - reach
        influence = SurfaceInfluence.build(body, lowest, progress=progress)
        patch = SurfacePatch(body, lowest)
        timings["influence_s"] = time.perf_counter() - start

        start = time.perf_counter()
        with progress.task("contact samples (loads solved)") as task:
            params, targets, _, held_share = _held_loads(influence, patch, family, ranges, np.random.default_rng(seed),
                                                         samples, workers, task)
        timings["samples_s"] = time.perf_counter() - start

        start = time.perf_counter()
        networks = _fit_networks(_features(params, family), targets, hidden, seed, ensemble, workers)
        timings["fit_s"] = time.perf_counter() - start
        twin = cls(design=design, family=family, ranges=ranges, mesh_size=mesh_size, networks=networks,
                   contact_layer_size=contact_layer_size)

        start = time.perf_counter()
        twin.report = {"samples": samples, "hidden": list(hidden), "networks": ensemble, "seed": seed,
                       "timings_s": timings,
                       "surface_nodes": len(influence.nodes), "contact": "footprint cells",
                       "contact_cell_m": CELL_SIZE, "domain": twin.domain,
                       "held_share": held_share}
        scales = twin._full_scales(targets[:, :-3].reshape(samples, -1, 6))
        twin.report["full_scale"] = {"sensor_uT": (scales["field_T"] * UT_PER_T).tolist(),
                                     "magnet_displacement_um": (scales["displacement_m"] * 1e6).tolist()}
        # many held-out loads solved exactly on the influence matrices (which reproduce the FE
        # solution, as the FE held-out loads check) give the error's distribution, not a few values
        with progress.task("held-out exact solves (loads solved)") as task:
            exact, reference, sliding, _ = _held_loads(influence, patch, family, ranges,
                                                       np.random.default_rng(seed + 2), exact_holdout, workers, task)
        twin.report["exact_holdout"] = twin._exact_errors(exact, reference, scales)
        if len(sliding[0]):  # how far off the twin is where the board would slide: outside its domain
            twin.report["exact_sliding_loads"] = twin._exact_errors(*sliding, scales)
        fe_loads = _held_loads(influence, patch, family, ranges, np.random.default_rng(seed + 1), holdout, workers,
                               Task())[0]
        with progress.task("held-out FE solves", len(fe_loads)) as task:
            twin.report["holdout"] = twin._fe_errors(body, patch, fe_loads, scales, task)
        timings["holdout_s"] = time.perf_counter() - start
        timings["build_s"] = sum(v for k, v in timings.items() if k != "holdout_s")
        return twin

    @property
    def domain(self) -> str:
        """The loads the twin was built on and answers for."""
        ranges = self.ranges
        covered = (f"contact within {ranges.position_radius / MM:g} mm of the axis, "
                   f"depth up to {ranges.depth / MM:g} mm, tangential travel up to {ranges.tangential / MM:g} mm")
        if self.family.friction == "stick":
            covered += f", where the board holds without sliding (|Ft| <= {self.family.mu:g} Fz)"
        return covered

    def _exact_errors(self, params: np.ndarray, reference: np.ndarray, scales: dict) -> dict:
        return self._errors(self.predict(params), reference[:, :-3].reshape(len(params), -1, 6), reference[:, -3:],
                            scales)

    def _fe_errors(self, body, patch: SurfacePatch, params: np.ndarray, scales: dict, task: Task) -> dict:
        """Errors against full finite-element solves at loads the network never saw: the same
        contact problem on the factorised stiffness, each load from scratch."""
        fe_rigid, fe_force, fe_seconds = [], [], []
        for k, p in enumerate(params):
            start = time.perf_counter()
            result = solve_footprint_contact(FootprintBody(patch, stiffness_compliance(body)), self.family.load(p))
            fe_seconds.append(time.perf_counter() - start)
            fe_rigid.append(result.magnet_poses.rigid)
            fe_force.append(result.force)
            task.advance()
        start = time.perf_counter()
        predicted = self.predict(params)
        rom_seconds = (time.perf_counter() - start) / len(params)
        return self._errors(predicted, np.array(fe_rigid), np.array(fe_force), scales) | {
            "fe_seconds_per_load": float(np.mean(fe_seconds)), "reduced_seconds_per_load_unbatched": rom_seconds}

    def _field(self, rigid: np.ndarray) -> np.ndarray:
        return self._readout.field_change(MagnetPoses.from_rigid(rigid))

    def _full_scales(self, sample_rigid: np.ndarray) -> dict:
        """Full scales over the load ranges, from exact samples that span them: the largest
        change of every sensor axis, the range of every magnet displacement."""
        return {"field_T": np.abs(self._field(sample_rigid)).max(axis=0),
                "displacement_m": np.ptp(sample_rigid[..., :3], axis=0)}

    def _errors(self, predicted: tuple[np.ndarray, np.ndarray], rigid: np.ndarray, force: np.ndarray,
                scales: dict) -> dict:
        """Errors of the network's ``predicted`` (poses, forces) against reference poses (N, M, 6)
        and forces (N, 3): the largest and the 99th percentile, in % of the full scales over the
        load ranges, and the largest in % of the largest change among these loads (stricter for a
        few loads)."""
        rom_rigid, rom_force = predicted
        field = self._field(rigid)
        field_error = np.abs(self._field(rom_rigid) - field)
        disp_error = np.abs(rom_rigid[..., :3] - rigid[..., :3])

        def percent(error: np.ndarray, scale: np.ndarray) -> list:
            return (error / scale * 100).tolist()

        force_scale = np.abs(force).max(axis=0)
        return {
            "loads": len(rigid),
            "sensor_error_percent_fs": percent(field_error.max(axis=0), scales["field_T"]),
            "sensor_error_p99_percent_fs": percent(np.percentile(field_error, 99, axis=0), scales["field_T"]),
            "magnet_displacement_error_percent_range": percent(disp_error.max(axis=0), scales["displacement_m"]),
            "magnet_displacement_error_p99_percent_range": percent(np.percentile(disp_error, 99, axis=0),
                                                                   scales["displacement_m"]),
            "sensor_error_percent_of_largest_change": percent(field_error.max(axis=0), np.abs(field).max(axis=0)),
            "magnet_displacement_error_percent_of_own_range": percent(disp_error.max(axis=0),
                                                                      np.ptp(rigid[..., :3], axis=0)),
            # an axis these loads never load (e.g. no shear among them) has no full scale
            "force_error_percent_of_largest": [float(e / f * 100) if f > 0 else None
                                               for e, f in zip(np.abs(rom_force - force).max(axis=0), force_scale)],
        }


def _held_loads(influence: SurfaceInfluence, patch: SurfacePatch, family: IndenterFamily, ranges: LoadRanges,
                rng: np.random.Generator, count: int, workers: int, task: Task) -> tuple:
    """``count`` loads drawn from ``ranges`` that the family holds without sliding and their exact
    solutions (magnet poses, force); the loads drawn on the way that slide, with their solutions;
    and the share of drawn loads that hold."""
    batches, outs, holding = [], [], []
    held = drawn = 0
    while held < count:
        share = held / drawn if drawn else 1.0  # draw what is missing at the share held so far, and a little more
        batch = ranges.sample(rng, math.ceil((count - held) / max(share, 0.2) * 1.05) + 8)
        out = _solve_in_parallel(influence, patch, family, batch, workers, task)
        batches.append(batch)
        outs.append(out)
        holding.append(~family.slides(out[:, -3:]))
        drawn += len(batch)
        held += int(holding[-1].sum())
    params, solutions, holds = np.vstack(batches), np.vstack(outs), np.concatenate(holding)
    first = np.flatnonzero(holds)[:count]
    return params[first], solutions[first], (params[~holds], solutions[~holds]), float(holds.mean())


def _solve_in_parallel(influence: SurfaceInfluence, patch: SurfacePatch, family: IndenterFamily, params: np.ndarray,
                       workers: int, task: Task) -> np.ndarray:
    _WORKER.update(influence=influence, patch=patch, family=family)
    chunks = np.array_split(params, max(1, len(params) // 100))
    results = []
    if workers <= 1 or os.name != "posix":
        for chunk in chunks:
            results.append(_solve_samples(chunk))
            task.advance(len(chunk))
    else:
        import multiprocessing

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
            for out in pool.map(_solve_samples, chunks):
                results.append(out)
                task.advance(len(out))
    _WORKER.clear()
    return np.vstack(results)


def _fit_networks(features: np.ndarray, targets: np.ndarray, hidden: tuple[int, ...], seed: int, count: int,
                  workers: int) -> list[dict]:
    """``count`` networks from independent initialisations, fitted side by side on the cores."""
    seeds = [int(s) for s in np.random.SeedSequence(seed).generate_state(count)]
    if workers <= 1 or count == 1 or os.name != "posix":
        return [_fit_network(features, targets, hidden, s) for s in seeds]
    import multiprocessing

    with ProcessPoolExecutor(min(workers, count), mp_context=multiprocessing.get_context("fork")) as pool:
        return list(pool.map(_fit_network, *zip(*[(features, targets, hidden, s) for s in seeds])))


def _runtime_layers(net: dict) -> list:
    """A fitted network (scikit-learn's layout: weights (inputs, outputs), standardised inputs
    and outputs) as run-time layers of the raw features and targets."""
    return fold_scaling([(w.T, b) for w, b in zip(net["weights"], net["biases"])], 1 / net["x_scale"],
                        -net["x_mean"] / net["x_scale"], net["y_scale"], net["y_mean"])


def _fit_network(features: np.ndarray, targets: np.ndarray, hidden: tuple[int, ...], seed: int) -> dict:
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor
    from threadpoolctl import threadpool_limits

    x_mean, x_scale = features.mean(axis=0), features.std(axis=0) + 1e-12
    y_mean, y_scale = targets.mean(axis=0), targets.std(axis=0) + 1e-30
    model = MLPRegressor(hidden_layer_sizes=hidden, activation="tanh", solver="lbfgs", max_iter=3000, tol=1e-9,
                         random_state=seed)
    # the products are thin: one BLAS thread fits faster than two on this kind of machine
    with warnings.catch_warnings(), threadpool_limits(limits=1):
        warnings.simplefilter("ignore", ConvergenceWarning)  # the iteration cap bounds the build time
        model.fit((features - x_mean) / x_scale, (targets - y_mean) / y_scale)
    return {"weights": [w.copy() for w in model.coefs_], "biases": [b.copy() for b in model.intercepts_],
            "x_mean": x_mean, "x_scale": x_scale, "y_mean": y_mean, "y_scale": y_scale}
