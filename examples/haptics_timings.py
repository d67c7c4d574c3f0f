"""Times the S3 renderer's two speed figures on this machine, each beside a same-run baseline:
one rendering (k-d tree query + weighting) at the 99th percentile, and building a personalised
13³ table (method A from a 7³ user table; method B by geometry), median of repeats.

    python examples/haptics_timings.py
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from softtip.systems.haptics.collection import CollectionSettings, motor_grid, sensed_contact
from softtip.systems.haptics.device import load_device
from softtip.systems.haptics.fingertips import FINGERTIP_SENSOR, TEST_FINGERTIPS
from softtip.systems.haptics.personalisation import personalise_data_driven, personalise_geometric
from softtip.systems.haptics.rendering import NearestNeighbourRenderer


def timed(call, repeats: int) -> np.ndarray:
    seconds = np.empty(repeats)
    for i in range(repeats):
        start = time.perf_counter()
        call()
        seconds[i] = time.perf_counter() - start
    return seconds


def main() -> None:
    device, rng = load_device(), np.random.default_rng(0)
    fs = sensed_contact(device, FINGERTIP_SENSOR, motor_grid(device, 13), CollectionSettings(), rng).unsaturated()
    renderer = NearestNeighbourRenderer().fit(fs.finger_wrenches, fs.motor_inputs)
    touching = np.linalg.norm(fs.finger_wrenches[:, :3], axis=1) > 0.1
    wanted = fs.finger_wrenches[touching][rng.integers(0, touching.sum(), 20_000)] + rng.normal(0, 0.05, (20_000, 6))
    tree = cKDTree(renderer.features_)
    queries = iter(wanted)
    render = timed(lambda: renderer.render_one(next(queries)), 20_000)
    queries = iter(wanted[:, :3])
    baseline = timed(lambda: tree.query(next(queries), k=8), 20_000)
    print(f"one rendering: p50 {np.percentile(render, 50) * 1e6:.1f} us, p99 {np.percentile(render, 99) * 1e6:.1f} us "
          f"(baseline, the bare cKDTree query k=8: p50 {np.percentile(baseline, 50) * 1e6:.1f} us, "
          f"p99 {np.percentile(baseline, 99) * 1e6:.1f} us)")

    user_finger = TEST_FINGERTIPS[5]
    user = sensed_contact(device, user_finger, motor_grid(device, 7), CollectionSettings(), rng).unsaturated()

    def build_a():
        personal = personalise_data_driven(device, fs.motor_inputs, fs.platform_wrenches, user.motor_inputs,
                                           user.platform_wrenches)
        NearestNeighbourRenderer().fit(fs.finger_wrenches, personal.motor_inputs)

    def build_b():
        personal = personalise_geometric(device, fs.motor_inputs, FINGERTIP_SENSOR.radius, user_finger.radius)
        NearestNeighbourRenderer().fit(fs.finger_wrenches, personal.motor_inputs)

    def build_standard():
        NearestNeighbourRenderer().fit(fs.finger_wrenches, fs.motor_inputs)

    for name, call in (("A (data-driven, 7^3 user table)", build_a), ("B (geometric)", build_b),
                       ("baseline: the standard 13^3 table indexed", build_standard)):
        seconds = timed(call, 30)
        print(f"personalised 13^3 table {name}: median {np.median(seconds) * 1e3:.1f} ms, "
              f"max {seconds.max() * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
