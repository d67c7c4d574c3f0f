"""Load histories and quasi-linear viscoelasticity against independent references.

References: the relaxation function written out here, the closed-form QLV
response to a constant-rate ramp, the creep under a held force derived by hand
from a one-term Prony series, and the published definition of hysteresis
evaluated with np.interp on monotone branches.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from softtip._core.signals import hysteresis_percent
from softtip.mechanics.motion import Motion
from softtip.mechanics.viscoelastic import PronySeries, prony_for_hysteresis, qlv_elastic_history, qlv_response

# A fingertip-like cycle: 3 mm at 0.25 mm/s, 1 s rest, back at 0.25 mm/s (12 + 1 + 12 s).
FULL_DEPTH = 3e-3
SPEED = 0.25e-3
REST = 1.0
STIFFNESS = 2000.0  # N/m, initial slope
STIFFENING = (10.0 - STIFFNESS * FULL_DEPTH) / FULL_DEPTH**2  # N/m², so that F_e(3 mm) = 10 N
SENSOR_GAIN = -4e4  # µT/m: the sensor's z output falls as the magnets approach


def load_unload_cycle(rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    times, depth, _ = Motion().push(FULL_DEPTH, SPEED).hold(REST).release(SPEED).sample(rate_hz)
    return times, depth


def elastic_force(depth: np.ndarray) -> np.ndarray:
    return STIFFNESS * depth + STIFFENING * depth**2


def reference_relaxation(t: np.ndarray, g: tuple[float, ...], tau: tuple[float, ...]) -> np.ndarray:
    return (1 - sum(g)) + sum(gk * np.exp(-t / tk) for gk, tk in zip(g, tau))


def reference_hysteresis(sensor_z: np.ndarray, force: np.ndarray) -> float:
    """The published definition on a cycle whose branches are monotone where the force is positive."""
    peak = int(np.argmax(force))
    mid = (force.min() + force.max()) / 2
    z_up = np.interp(mid, force[: peak + 1], sensor_z[: peak + 1])
    falling = force[peak:] > 0
    z_down = np.interp(mid, force[peak:][falling][::-1], sensor_z[peak:][falling][::-1])
    return abs(z_up - z_down) / np.ptp(sensor_z) * 100


# --- quasi-linear viscoelasticity ---------------------------------------------------------


def test_relaxation_after_a_fast_step_follows_G():
    g, tau = (0.3, 0.2), (0.25, 4.0)
    rise, step = 1e-3, 5.0  # a 5 N step applied over 1 ms
    times = np.concatenate([np.linspace(0, rise, 5), rise + np.geomspace(1e-3, 20, 200)])
    elastic = step * np.clip(times / rise, 0, 1)
    response = qlv_response(times, elastic, PronySeries(g, tau))
    # a ramp over `rise` relaxes like a step at its middle, to O(rise² / τ²)
    after = times > rise
    expected = step * reference_relaxation(times[after] - rise / 2, g, tau)
    np.testing.assert_allclose(response[after], expected, rtol=0, atol=1e-5 * step)


def test_a_history_that_starts_loaded_is_a_step_at_the_first_sample():
    g, tau = (0.4,), (2.0,)
    times = np.array([1.0, 1.5, 3.0, 10.0])
    response = qlv_response(times, np.full(4, 7.0), PronySeries(g, tau))
    np.testing.assert_allclose(response, 7.0 * reference_relaxation(times - 1.0, g, tau), rtol=1e-13)


def test_constant_rate_ramp_matches_the_closed_form_on_an_irregular_clock():
    g, tau = (0.25, 0.15), (0.5, 6.0)
    times = np.sort(np.random.default_rng(1).uniform(0, 15, 60))
    times[0] = 0.0
    rates = np.array([[1.0, -2.0], [0.5, 3.0]])  # k·v of four independent ramps, on trailing axes
    elastic = times[:, None, None] * rates
    response = qlv_response(times, elastic, PronySeries(g, tau))
    # F(t) = k v [g_inf t + Σ g_k τ_k (1 − e^{−t/τ_k})] (Fung's QLV under a constant strain rate)
    memory = (1 - sum(g)) * times + sum(gk * tk * -np.expm1(-times / tk) for gk, tk in zip(g, tau))
    np.testing.assert_allclose(response, memory[:, None, None] * rates, rtol=1e-11, atol=1e-13)


def test_the_response_does_not_depend_on_the_sample_rate():
    # A fast tap (3 mm in 0.6 s): a scheme that is only first-order in the sample period
    # would be out by several percent at 20 Hz; the exact update only sees the linear
    # interpolation of F_e between samples.
    prony = PronySeries((0.3, 0.2), (0.1, 1.0))
    tap = Motion().push(FULL_DEPTH, 5e-3).hold(0.2).release(5e-3)
    coarse_times, coarse_depth, _ = tap.sample(20.0)
    fine_times, fine_depth, _ = tap.sample(1000.0)
    coarse = qlv_response(coarse_times, elastic_force(coarse_depth), prony)
    fine = qlv_response(fine_times, elastic_force(fine_depth), prony)
    np.testing.assert_array_equal(fine_times[::50], coarse_times)  # the common times
    assert np.max(np.abs(fine[::50] - coarse)) < 0.005 * fine.max()


def test_a_purely_elastic_series_returns_the_input():
    times = np.cumsum(np.random.default_rng(2).uniform(0.01, 0.5, 40))
    elastic = np.random.default_rng(3).normal(size=(40, 2, 3))
    for prony in (PronySeries((), ()), PronySeries((0.0, 0.0), (1.0, 5.0))):
        np.testing.assert_array_equal(qlv_response(times, elastic, prony), elastic)


def test_a_held_force_creeps_by_the_prony_creep_function():
    # G = g_inf + g e^{-t/τ}: in Laplace, F = s Ĝ F_e = (s + g_inf/τ)/(s + 1/τ) F_e, so a force step F0
    # held from 0 needs F_e = F0 (s + 1/τ)/(s (s + g_inf/τ)) = (F0/g_inf)(1 - g e^{-g_inf t/τ}): the
    # elastic response starts at F0 and creeps to F0/g_inf with the retardation time τ/g_inf
    g, tau, force = 0.6, 1.4, 2.0
    times = np.linspace(0.0, 10.0, 20001)
    elastic = qlv_elastic_history(times, np.full(len(times), force), PronySeries((g,), (tau,)))
    g_inf = 1 - g
    creep = force / g_inf * (1 - g * np.exp(-g_inf * times / tau))
    # the scheme takes F_e piecewise linear between samples: an O(Δ²) error on an exponential
    np.testing.assert_allclose(elastic, creep, rtol=1e-6)


def test_force_control_inverts_the_qlv_response_on_an_irregular_clock():
    prony = PronySeries((0.25, 0.15, 0.2), (0.004, 0.07, 1.4))
    rng = np.random.default_rng(0)
    times = np.cumsum(rng.uniform(1e-3, 2e-2, 400))
    force = np.abs(rng.normal(size=(400, 2, 3))).cumsum(axis=0)
    elastic = qlv_elastic_history(times, force, prony)
    np.testing.assert_allclose(qlv_response(times, elastic, prony), force, rtol=1e-12, atol=1e-12)
    # and the other way round: the imposed elastic history is recovered from its response
    np.testing.assert_allclose(qlv_elastic_history(times, qlv_response(times, force, prony), prony), force,
                               rtol=1e-12, atol=1e-12)


def test_prony_series_is_validated():
    for g, tau, name in [
        ((0.2,), (1.0, 2.0), "prony.g has 1 terms"),
        ((-0.1,), (1.0,), "prony.g"),
        ((0.6, 0.4), (1.0, 2.0), "sum to 1"),
        ((0.2,), (0.0,), "prony.tau"),
    ]:
        with pytest.raises(ValueError, match=name):
            PronySeries(g, tau)
    prony = PronySeries([0.2, 0.3], [1.0, 10.0])
    assert prony.g == (0.2, 0.3) and prony.g_inf == pytest.approx(0.5)
    np.testing.assert_allclose(prony.relaxation([0.0, 1.0, 1e6]), [1.0, reference_relaxation(1.0, prony.g, prony.tau), 0.5])


def test_qlv_response_refuses_bad_clocks():
    with pytest.raises(ValueError, match="strictly increasing"):
        qlv_response(np.array([0.0, 1.0, 1.0]), np.zeros(3), PronySeries((0.1,), (1.0,)))
    with pytest.raises(ValueError, match="elastic has shape"):
        qlv_response(np.arange(3.0), np.zeros(4), PronySeries((0.1,), (1.0,)))


# --- hysteresis -----------------------------------------------------------------------------


def test_hysteresis_is_zero_when_elastic_and_grows_with_the_relaxing_weight():
    times, depth = load_unload_cycle(100.0)
    sensor_z, elastic = SENSOR_GAIN * depth, elastic_force(depth)
    loops = [hysteresis_percent(sensor_z, qlv_response(times, elastic, PronySeries((w,), (5.0,)))) for w in np.linspace(0, 0.9, 10)]
    assert loops[0] == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.diff(loops) > 0.5)  # percentage points per 0.1 of weight


@pytest.mark.parametrize("tau", [None, (1.0, 10.0)])
def test_calibration_hits_the_published_hysteresis(tau):
    times, depth = load_unload_cycle(200.0)
    sensor_z, elastic = SENSOR_GAIN * depth, elastic_force(depth)
    prony = prony_for_hysteresis(7.3, times, sensor_z, elastic, tau=tau)
    assert prony.g_inf < 1 and len(set(prony.g)) == 1  # the weight split equally between the terms
    if tau is not None:
        assert prony.tau == tau
    force = np.maximum(qlv_response(times, elastic, prony), 0.0)  # a contact does not pull
    assert reference_hysteresis(sensor_z, force) == pytest.approx(7.3, abs=0.1)


def test_calibration_refuses_an_unreachable_target():
    times, depth = load_unload_cycle(50.0)
    with pytest.raises(ValueError, match="not reachable"):
        prony_for_hysteresis(90.0, times, SENSOR_GAIN * depth, elastic_force(depth))
    zero = prony_for_hysteresis(0.0, times, SENSOR_GAIN * depth, elastic_force(depth))
    assert zero.g_inf == 1.0


# --- motions --------------------------------------------------------------------------------


@pytest.mark.parametrize("rate_hz", [1.0, 3.0, 20.0, 1000.0])
def test_segment_end_points_are_hit_exactly(rate_hz):
    times, depth = load_unload_cycle(rate_hz)
    for end_time, end_depth in [(0.0, 0.0), (12.0, FULL_DEPTH), (13.0, FULL_DEPTH), (25.0, 0.0)]:
        index = round(end_time * rate_hz)
        assert times[index] == end_time and depth[index] == end_depth


def test_a_peak_that_round_off_moves_off_the_clock_is_still_hit():
    motion = Motion().push(0.3e-3, 0.1e-3).release(0.1e-3)
    assert motion.duration != 6.0  # 0.3e-3 / 0.1e-3 is 2.9999999999999996 in floating point
    times, depth, _ = motion.sample(10.0)
    assert len(times) == 61 and times[30] == 3.0 and depth[30] == 0.3e-3
    assert times[-1] == 6.0 and depth[-1] == 0.0


def test_sampling_at_any_rate_is_uniform_and_piecewise_linear():
    rate = 0.7  # no segment end falls on this clock except t = 0
    times, depth = load_unload_cycle(rate)
    ticks = np.arange(18) / rate  # 17 / 0.7 = 24.3 s is the last tick before 25 s
    np.testing.assert_array_equal(times, np.append(ticks, 25.0))
    expected = np.where(times <= 12, SPEED * times, np.where(times <= 13, FULL_DEPTH, FULL_DEPTH - SPEED * (times - 13)))
    np.testing.assert_allclose(depth, expected, rtol=0, atol=1e-15)


def test_durations_are_distance_over_speed():
    motion = Motion().push(1e-3, 0.5e-3).shear(3e-3, -4e-3, 1e-3).move_to(depth=0.0, tx=0.0, ty=0.0, speed=2e-3)
    assert motion.duration == pytest.approx(2.0 + 5.0 + math.sqrt(1 + 9 + 16) / 2)
    times, depth, tangential = motion.sample(1000.0)
    at = {t: int(round(t * 1000)) for t in (2.0, 7.0)}
    assert depth[at[2.0]] == 1e-3 and tuple(tangential[at[2.0]]) == (0.0, 0.0)
    assert depth[at[7.0]] == 1e-3 and tuple(tangential[at[7.0]]) == (3e-3, -4e-3)  # the shear keeps the depth
    assert depth[-1] == 0.0 and tuple(tangential[-1]) == (0.0, 0.0)


def test_release_lifts_straight_up_and_move_to_keeps_what_it_is_not_given():
    motion = Motion().push(2e-3, 1e-3).shear(1e-3, 0.0, 1e-3).release(1e-3).move_to(ty=2e-3, speed=1e-3)
    _, depth, tangential = motion.sample(1.0)  # ends at 2, 3, 5 and 7 s
    assert depth[5] == 0.0 and tuple(tangential[5]) == (1e-3, 0.0)
    assert depth[7] == 0.0 and tuple(tangential[7]) == (1e-3, 2e-3)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: Motion().push(1e-3, -1.0), "push.speed = -1.0"),
        (lambda: Motion().push(0.0, 1e-3), "push.depth = 0.0"),
        (lambda: Motion().hold(0.0), "hold.seconds = 0.0"),
        (lambda: Motion().shear(1e-3, 0.0, math.nan), "shear.speed = nan"),
        (lambda: Motion().push(1e-3, 1e-3).move_to(depth=-1e-3, speed=1e-3), "move_to.depth = -0.001"),
        (lambda: Motion().release(1e-3), r"steps\[0\] \(release\): already at"),
        (lambda: Motion().push(1e-3, 1e-3).shear(0.0, 0.0, 1e-3), r"steps\[1\] \(shear\): already at"),
        (lambda: Motion().push(1e-3, 1e-3).sample(0.0), "rate_hz = 0.0"),
        (lambda: Motion().hold("1"), "hold.seconds = '1'"),
    ],
)
def test_invalid_motions_are_refused_in_one_line_naming_the_parameter(build, message):
    with pytest.raises(ValueError, match=message) as error:
        build()
    assert "\n" not in str(error.value)


def test_motion_from_tables():
    tables = [
        {"kind": "push", "depth": 3e-3, "speed": 0.25e-3},
        {"kind": "hold", "seconds": 1.0},
        {"kind": "shear", "dx": 1e-3, "dy": 0.0, "speed": 0.5e-3},
        {"kind": "move_to", "depth": 1e-3, "speed": 1e-3},
        {"kind": "release", "speed": 0.25e-3},
    ]
    motion = Motion.from_dicts(tables)
    assert motion == Motion().push(3e-3, 0.25e-3).hold(1.0).shear(1e-3, 0.0, 0.5e-3).move_to(depth=1e-3, speed=1e-3).release(0.25e-3)
    assert motion.to_dicts() == tables
    for bad, message in [
        ([{"kind": "push", "depth": 1e-3, "speed": 1e-3, "sped": 1.0}], r"motion\[0\]\.sped: unknown key"),
        ([{"kind": "hold", "seconds": 1.0}, {"kind": "wiggle"}], r"motion\[1\]\.kind = 'wiggle'"),
        ([{"kind": "push", "depth": 1e-3}], r"motion\[0\]: push needs speed"),
        ([{"kind": "release", "speed": -1.0}], r"motion\[0\]: release\.speed = -1\.0"),
        ({"kind": "hold", "seconds": 1.0}, "expected a list of step tables"),
    ]:
        with pytest.raises(ValueError, match=message):
            Motion.from_dicts(bad)
