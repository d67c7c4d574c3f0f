"""The lab's mechanics: exact small-strain contact on a fingertip's surface influence matrices,
and a grasped rigid part held by two fingertips.

Every experiment of the virtual lab reduces to two kinds of response:

* a **press** - an indenter (board edge, plate, tilted plate, board corner) pushed into one
  fingertip along a load path, solved exactly on the influence matrices
  (:class:`softtip.twin.influence.InfluenceEngine`), recorded after every load step so time series
  are interpolated between exact states;
* a **held part** - a thin part grasped face-on between two fingertips (both pads pressed by the
  grip, sticking), which then collides with its environment. The part is rigid; the fingertips'
  compliance holds it. Around the grasped state the pads act as a 6x6 stiffness on the part's
  small rigid motion q = (translation, rotation), with the contact patches sticking:

      K = sum_k T_k^T W_k^-1 T_k,   T_k: q -> displacement of pad k's contact nodes

  (W_k the compliance of pad k's contact nodes). A collision at points P_j with the plane
  normal n is a small linear complementarity problem: the part moves by q = K^-1 G lambda,
  G_j = (n, P_j x n), with lambda >= 0 and every touching point kept on the plane while the arm
  drives the part into it. The magnets of pad k then move by R_k W_k^-1 T_k q.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from softtip.mechanics.contact import LoadCase, ReducedContactResult
from softtip.mechanics.indenters import Plate
from softtip.mechanics.poses import MagnetPoses
from softtip.twin.influence import InfluenceEngine


def gripped(engine: InfluenceEngine, depth: float) -> tuple[np.ndarray, np.ndarray, tuple]:
    """The pad pressed ``depth`` (m) by a flat face, sticking: its contact nodes, their unknowns
    and the factorised compliance of those unknowns (computed once per engine and depth)."""
    cache = engine.__dict__.setdefault("_gripped", {})
    if depth not in cache:
        nodes = engine.press(LoadCase(Plate(), depth, friction="stick")).contact_nodes
        rows = (3 * nodes[:, None] + np.arange(3)).ravel()
        cache[depth] = nodes, rows, scipy.linalg.cho_factor(engine.influence.compliance[np.ix_(rows, rows)])
    return cache[depth]


def path_table(solution: ReducedContactResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A press's path as arrays, starting from the unloaded state: travel (K, 3), magnet rigid
    motion (K, M, 6) and force (K, 3), K = steps + 1."""
    travel = np.array([np.zeros(3)] + [t for t, _, _ in solution.path])
    rigid = np.array([np.zeros_like(solution.magnet_poses.rigid)] + [p.rigid for _, p, _ in solution.path])
    force = np.array([np.zeros(3)] + [f for _, _, f in solution.path])
    return travel, rigid, force


def interpolate_path(table: tuple[np.ndarray, np.ndarray, np.ndarray], depth: np.ndarray,
                     tangential: np.ndarray) -> tuple[MagnetPoses, np.ndarray]:
    """Magnet poses (N, M, 3) and force (N, 3) at N points of a normal-then-tangential path,
    piecewise linear between the exact states along the path's arc length."""
    travel, rigid, force = table
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(travel, axis=0), axis=1))])
    # where each query sits on the path: depth first, then tangential travel
    depth_end = -travel[:, 2].min()
    normal_arc = arc[np.argmin(travel[:, 2])] if depth_end > 0 else 0.0
    query = np.where(np.linalg.norm(tangential, axis=1) > 0,
                     normal_arc + np.linalg.norm(tangential, axis=1),
                     np.clip(depth, 0, depth_end) / max(depth_end, 1e-12) * normal_arc)
    flat = rigid.reshape(len(rigid), -1)
    out_rigid = np.column_stack([np.interp(query, arc, flat[:, k]) for k in range(flat.shape[1])])
    out_force = np.column_stack([np.interp(query, arc, force[:, k]) for k in range(3)])
    return MagnetPoses.from_rigid(out_rigid.reshape(len(query), *rigid.shape[1:])), out_force


# ---------------------------------------------------------------------------------------------------- held part

def _skew(v: np.ndarray) -> np.ndarray:
    """(n, 3) vectors -> (n, 3, 3) cross-product matrices."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return out


@dataclass
class Pad:
    """One pad of a grasp: where the part's frame sits in the pad's frame, and the pad's
    response to the part's rigid motion (all per unit of q)."""

    rotation: np.ndarray  # (3, 3) pad frame -> part frame
    origin: np.ndarray  # (3,) the part frame's origin in pad coordinates
    stiffness: np.ndarray  # (6, 6) N/m, N/rad ... on the part, in part coordinates
    magnets: np.ndarray  # (M*6, 6) the pad's magnet rigid motion per unit q
    force: np.ndarray  # (3, 6) force of the part on the pad (pad frame) per unit q


def grasp_pad(fingertip: InfluenceEngine, grip_depth: float, rotation: np.ndarray, origin: np.ndarray) -> Pad:
    """A pad pressed ``grip_depth`` (m) by a flat face (sticking), then linearised about that state."""
    influence = fingertip.influence
    nodes, rows, factor = gripped(fingertip, grip_depth)
    in_part = (influence.nodes[nodes] - origin) @ rotation.T
    # displacement of node i (pad frame) = R^T (t + w x y_i) = R^T [I, -skew(y_i)] q
    local = np.concatenate([np.broadcast_to(np.eye(3), (len(nodes), 3, 3)), -_skew(in_part)], axis=2)
    transfer = np.einsum("ji,njk->nik", rotation, local).reshape(-1, 6)
    nodal = scipy.linalg.cho_solve(factor, transfer)  # forces on the pad's nodes per unit q
    stiffness = transfer.T @ nodal
    force_on_pad = nodal.reshape(len(nodes), 3, 6).sum(axis=0)
    return Pad(rotation=rotation, origin=origin, stiffness=0.5 * (stiffness + stiffness.T),
               magnets=influence.magnets[:, rows] @ nodal, force=force_on_pad)


@dataclass
class HeldPart:
    """A rigid part between two pads (pad 0 below it, pad 1 above it, turned half a turn about x)."""

    pads: tuple[Pad, Pad]
    stiffness: np.ndarray = field(init=False)

    def __post_init__(self):
        self.stiffness = self.pads[0].stiffness + self.pads[1].stiffness

    @classmethod
    def grasp(cls, fingertip: InfluenceEngine, grip_depth: float, part_thickness: float,
              offset: tuple[float, float] = (0.0, 0.0)) -> "HeldPart":
        """The part's frame: origin on its mid-plane over the point ``offset`` (m) of pad 0's top face,
        x and y along pad 0's, z out of pad 0 through the part."""
        top = fingertip.design.height - grip_depth + part_thickness / 2
        flip = np.diag([1.0, -1.0, -1.0])
        pad0 = grasp_pad(fingertip, grip_depth, np.eye(3), np.array([offset[0], offset[1], top]))
        pad1 = grasp_pad(fingertip, grip_depth, flip, np.array([offset[0], -offset[1], top]))
        return cls(pads=(pad0, pad1))

    def collide(self, points: np.ndarray, normal: np.ndarray, approach: np.ndarray, travel: np.ndarray,
                seat_compliance: float = 0.0) -> dict:
        """The part driven by the arm along ``approach`` (unit, part frame) by ``travel`` (N,) m past
        the first touch of any of ``points`` (P, 3) with a plane of unit ``normal`` (pointing at the
        part) that gives ``seat_compliance`` (m/N) at each point. Returns the part's motion q (N, 6),
        contact forces (N, P) N and each pad's magnet poses (N, M, 3) and force (N, 3)."""
        gaps = (points - points[np.argmin(points @ normal)]) @ normal  # >= 0: distance to the plane at touch
        coupling = np.concatenate([np.broadcast_to(normal, points.shape), np.cross(points, normal)], axis=1).T
        compliance = scipy.linalg.solve(self.stiffness, coupling, assume_a="pos")  # q per unit contact force
        delassus = coupling.T @ compliance + seat_compliance * np.eye(len(points))
        drive = float(approach @ normal)  # < 0: the arm drives the part into the plane
        forces = np.array([_contact_forces(delassus, gaps + s * drive) for s in np.asarray(travel, float)])
        q = forces @ compliance.T
        out = {"q": q, "contact_forces": forces}
        for k, pad in enumerate(self.pads):
            out[f"magnets_{k}"] = MagnetPoses.from_rigid((q @ pad.magnets.T).reshape(len(q), -1, 6))
            out[f"force_{k}"] = q @ pad.force.T
        return out


def _contact_forces(delassus: np.ndarray, gaps: np.ndarray) -> np.ndarray:
    """lambda >= 0 with D lambda + g >= 0 and lambda (D lambda + g) = 0, by enumerating active sets
    (a part touches a plane at a handful of points)."""
    count = len(gaps)
    best = np.zeros(count)
    if (gaps >= -1e-15).all():
        return best
    for size in range(1, count + 1):
        for active in itertools.combinations(range(count), size):
            index = list(active)
            forces = np.zeros(count)
            try:
                forces[index] = np.linalg.solve(delassus[np.ix_(index, index)], -gaps[index])
            except np.linalg.LinAlgError:
                continue
            separation = delassus @ forces + gaps
            if (forces >= -1e-12).all() and (separation >= -1e-12).all():  # N and m
                return np.maximum(forces, 0.0)
    return best
