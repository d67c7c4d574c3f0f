"""Quasi-linear viscoelasticity (QLV): the fingertip's force as a function of time.

The elastic twin gives, for each pose of the indenter, the instantaneous
(elastic) response F_e. Fung's quasi-linear viscoelasticity (Y. C. Fung,
*Biomechanics: Mechanical Properties of Living Tissues*, 2nd ed., Springer
1993, §7.6) turns a history of it into the viscoelastic response by a
hereditary integral with a strain-independent reduced relaxation function G:

    F(t) = ∫_{-∞}^{t} G(t − s) dF_e(s),
    G(t) = g_inf + Σ_k g_k exp(−t/τ_k),   g_inf + Σ_k g_k = 1   (Prony series)

so G(0) = 1 (a sudden step gives the elastic response) and G(∞) = g_inf (the
fully relaxed fraction).

Assumption. Under displacement control (the indenter's motion is imposed) and
with a Poisson's ratio that does not change as the material relaxes, the
relaxation scales every stress by the same factor: the deformation field — and
so the magnets' poses and the Hall sensors' output — follows the imposed motion
instantly, while the force on the indenter relaxes. Sensor output plotted
against force then traces a loop; :func:`softtip._core.signals.hysteresis_percent`
measures it and :func:`prony_for_hysteresis` calibrates G to a measured value.

Force control. When the force is imposed (a person pressing with a chosen force)
the deformation creeps instead: :func:`qlv_elastic_history` inverts the same
discrete hereditary operator exactly, giving the elastic response F_e (and so,
through the elastic law, the deformation) whose QLV response is the imposed
force. For a force step F_0 held from t = 0 and one Prony term it is Fung's creep
of the reduced relaxation function, F_e(t) = (F_0/g_inf)(1 − g e^{−g_inf t/τ}):
the retardation time is τ/g_inf, longer than the relaxation time.

Limits. (1) A real elastomer's bulk and shear moduli relax differently, so its
Poisson's ratio drifts and the deformation under a held indenter creeps a
little; the sensor output's own drift is not modelled. (2) Under force control
the creep follows from QLV of the force (above), with the same single relaxation
function for loading and unloading. (3) On unloading, QLV predicts a negative (pulling)
normal force near zero depth: a contact without adhesion lets go instead (the
load cell reads 0; :func:`prony_for_hysteresis` takes max(F, 0)), and the
surface then lags the indenter, so the deformation no longer follows the motion.
(4) One relaxation function for all strains: relaxation rates that depend on
the strain (Nekouzadeh et al., J. Biomech. 40, 2007) are outside QLV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from softtip._core.signals import hysteresis_percent


@dataclass(frozen=True)
class PronySeries:
    """Reduced relaxation function G(t) = g_inf + Σ g_k exp(−t/τ_k), with g_inf = 1 − Σ g_k."""

    g: tuple[float, ...]  # weight of each relaxing term, ≥ 0, Σ g < 1
    tau: tuple[float, ...]  # s, its time constant, > 0

    def __post_init__(self):
        g = tuple(float(value) for value in self.g)
        tau = tuple(float(value) for value in self.tau)
        if len(g) != len(tau):
            raise ValueError(f"prony.g has {len(g)} terms and prony.tau {len(tau)}: expected one time constant per weight")
        if not all(math.isfinite(value) and value >= 0 for value in g):
            raise ValueError(f"prony.g = {self.g}: expected non-negative weights")
        if not sum(g) < 1:
            raise ValueError(f"prony.g = {self.g}: the weights sum to {sum(g):g}; expected less than 1 (g_inf > 0)")
        if not all(math.isfinite(value) and value > 0 for value in tau):
            raise ValueError(f"prony.tau = {self.tau}: expected positive time constants in s")
        object.__setattr__(self, "g", g)
        object.__setattr__(self, "tau", tau)

    @property
    def g_inf(self) -> float:
        """The long-term (fully relaxed) fraction of the elastic response."""
        return 1.0 - sum(self.g)

    def relaxation(self, t: np.ndarray | float) -> np.ndarray:
        """G(t) at times t ≥ 0 (s) since a step, any shape."""
        t = np.asarray(t, dtype=float)
        if np.any(t < 0):
            raise ValueError("t: expected times since the step, ≥ 0")
        return self.g_inf + np.exp(-t[..., None] / np.array(self.tau)) @ np.array(self.g)


def qlv_response(times: np.ndarray, elastic: np.ndarray, prony: PronySeries) -> np.ndarray:
    """The viscoelastic response F(t) to the elastic response history ``elastic``
    (N, ...) sampled at ``times`` (N,), strictly increasing, not necessarily uniform.

    F_e is taken as linear in time between samples and zero before times[0] (a
    non-zero first sample is a step at times[0]). With F = g_inf F_e + Σ_k h_k,
    each term's memory is updated exactly over a step Δ of the piecewise-linear
    history:

        h_k(t + Δ) = e^{−Δ/τ_k} h_k(t) + g_k (τ_k/Δ)(1 − e^{−Δ/τ_k}) ΔF_e,   h_k(t_0) = g_k F_e(t_0)

    so the result depends on the sample rate only through the linear
    interpolation of F_e. O(N·K) for K terms; vectorised over trailing axes.
    """
    elastic = np.asarray(elastic, dtype=float)
    g, decay, gain = _step_coefficients(times, elastic, prony, "elastic")
    increments = np.diff(elastic, axis=0)

    response = np.empty_like(elastic)
    memory = g * elastic[0]
    response[0] = prony.g_inf * elastic[0] + memory.sum(axis=0)
    for n, increment in enumerate(increments):
        memory = decay[n] * memory + gain[n] * increment
        response[n + 1] = prony.g_inf * elastic[n + 1] + memory.sum(axis=0)
    return response


def qlv_elastic_history(times: np.ndarray, response: np.ndarray, prony: PronySeries) -> np.ndarray:
    """The elastic response history F_e (N, ...) whose viscoelastic response
    (:func:`qlv_response`) is ``response``, sampled at ``times``: force control.

    The exact inverse of :func:`qlv_response`'s recursion: at every step the new
    sample enters F linearly, F(t + Δ) = (g_inf + Σ_k gain_k) F_e(t + Δ) + (what the
    memory already holds), so it is solved for in closed form. Imposing a force
    history and mapping F_e through the elastic law gives the creeping deformation.
    """
    response = np.asarray(response, dtype=float)
    g, decay, gain = _step_coefficients(times, response, prony, "response")
    # every step's instantaneous factor g_inf + Σ gain > 0, since g_inf > 0 and gains >= 0
    instantaneous = prony.g_inf + gain.sum(axis=1)

    elastic = np.empty_like(response)
    elastic[0] = response[0]  # a step at times[0]: G(0) = 1
    memory = g * elastic[0]
    for n in range(len(response) - 1):
        carried = decay[n] * memory - gain[n] * elastic[n]
        elastic[n + 1] = (response[n + 1] - carried.sum(axis=0)) / instantaneous[n]
        memory = carried + gain[n] * elastic[n + 1]
    return elastic


def _step_coefficients(times: np.ndarray, values: np.ndarray, prony: PronySeries,
                       name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The weights g (K, 1, ...) and, per step Δ of ``times``, each term's decay e^{−Δ/τ_k} and
    gain g_k (τ_k/Δ)(1 − e^{−Δ/τ_k}), both (N-1, K, 1, ...), shaped to broadcast over the
    trailing axes of ``values`` (N, ...)."""
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or len(times) == 0:
        raise ValueError(f"times has shape {times.shape}: expected a non-empty 1-D array")
    if values.shape[:1] != times.shape:
        raise ValueError(f"{name} has shape {values.shape}: expected ({len(times)}, ...) to match times")
    steps = np.diff(times)
    if not np.all(steps > 0):
        raise ValueError("times: expected strictly increasing sample times")
    trailing = (1,) * (values.ndim - 1)
    g = np.array(prony.g).reshape(-1, *trailing)  # (K, 1, ...) broadcasts over the trailing axes
    ratio = steps[:, None] / np.array(prony.tau)  # (N-1, K), Δ/τ
    decay = np.exp(-ratio).reshape(len(steps), -1, *trailing)
    # (τ/Δ)(1 − e^{−Δ/τ}) by expm1: exact to round-off even when Δ ≪ τ
    gain = g * (-np.expm1(-ratio) / ratio).reshape(len(steps), -1, *trailing)
    return g, decay, gain


def prony_for_hysteresis(
    target_percent: float,
    times: np.ndarray,
    sensor_z: np.ndarray,
    elastic_force: np.ndarray,
    tau: tuple[float, ...] | None = None,
) -> PronySeries:
    """The Prony series whose QLV force, paired with the (elastic) sensor output,
    has ``target_percent`` hysteresis on the given load/unload cycle.

    ``elastic_force`` is the normal force of the elastic twin along the cycle;
    since a contact cannot pull, the force the hysteresis is measured on is
    max(F, 0), what a load cell reads once the surface lets go of a fast
    retreating indenter (see the module's limits). The relaxing weight
    w = Σ g_k is split equally between the time constants ``tau`` (default: one
    term, τ = the time from the start to the peak of the elastic force, the
    cycle's own time scale) and found by root finding on w ∈ [0, 1).
    """
    times = np.asarray(times, dtype=float)
    elastic_force = np.asarray(elastic_force, dtype=float)
    if not (math.isfinite(target_percent) and target_percent >= 0):
        raise ValueError(f"target_percent = {target_percent}: expected a non-negative percentage")
    if times.ndim != 1 or times.shape != elastic_force.shape:
        raise ValueError(f"times {times.shape} and elastic_force {elastic_force.shape}: expected two 1-D arrays of one cycle")
    if tau is not None and len(tau) == 0:
        raise ValueError("tau = (): expected at least one time constant")
    if tau is None:
        tau = (float(times[np.argmax(elastic_force)] - times[0]),)
        if not tau[0] > 0:
            raise ValueError("elastic_force peaks at the first sample: pass tau, or a cycle that starts unloaded")
    shares = PronySeries(tuple(0.5 / len(tau) for _ in tau), tuple(tau))
    # F is linear in the weight: F_w = F_e + w (R − F_e), R being the fully relaxing
    # response; one QLV run at w = 1/2 gives R − F_e for every w.
    relaxing_part = 2 * (qlv_response(times, elastic_force, shares) - elastic_force)

    def miss(weight: float) -> float:
        force = np.maximum(elastic_force + weight * relaxing_part, 0.0)
        return hysteresis_percent(sensor_z, force) - target_percent

    elastic_miss = miss(0.0)
    if elastic_miss >= 0:
        if elastic_miss > 1e-9:
            raise ValueError(f"target_percent = {target_percent}: below the purely elastic cycle's {elastic_miss + target_percent:.3g} %")
        return PronySeries(tuple(0.0 for _ in tau), shares.tau)
    largest = 1 - 1e-9  # keeps g_inf > 0
    widest = miss(largest) + target_percent
    if widest < target_percent:
        raise ValueError(
            f"target_percent = {target_percent}: not reachable with tau = {shares.tau} s on this cycle "
            f"(at most {widest:.3g} %, with all of the force relaxing); try time constants nearer the cycle's"
        )
    weight = brentq(miss, 0.0, largest, xtol=1e-12)
    return PronySeries(tuple(weight / len(tau) for _ in tau), shares.tau)
