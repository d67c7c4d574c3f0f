"""Where the main demo's live force error comes from, like for like, over seeds.

For each seed: the published calibration (``force3``: pushes only, 0.5 mm/s, the first reading as the
baseline) and the live use's cycles (``force-cycles``: pushed and released after 2 s in the air, at
0.5 and at 2 mm/s, the baseline the mean of the readings in the air) run on the same fabricated unit;
a network is fitted to each calibration set and scored on the held-out trials of each, Fz by phase
(rest, loading, unloading). Then ``softtip demo``'s own run (calibrated on ``force-cycles`` at the
stream's 2 mm/s, 20 s live on the emulated fingertip): its offline error on the held-out trials beside
its live error, over every frame and over the stream's whole loops of the three motions. Means and 95 %
t-intervals over the seeds.

    python examples/fingertip_live_error.py --seeds 1 2 3
"""

from __future__ import annotations

import argparse

import numpy as np

from softtip.calibration import LMNetwork
from softtip.data.splits import by_role
from softtip.lab import load_protocol, run_protocol
from softtip.systems.hall_fingertip.demo import run_main_demo
from softtip.systems.hall_fingertip.force_model import FORCES, axis_scores
from softtip.systems.hall_fingertip.tolerance import interval

PHASES = ("rest", "loading", "unloading")
SPEEDS_MM_S = [0.5, 2.0]


def like_for_like(seed: int) -> dict[str, float]:
    """Fz's mean absolute error (N) of each calibration's network on each held-out set, overall and by phase."""
    published, _ = run_protocol(load_protocol("force3").changed(seed=seed))
    cycles, _ = run_protocol(load_protocol("force-cycles").changed(seed=seed, speeds_mm_s=SPEEDS_MM_S))
    speed = cycles.column("speed_mm_s")
    (published_train, published_test), (cycles_train, cycles_test) = by_role(published), by_role(cycles)

    def fitted(dataset, rows):
        y = np.column_stack([dataset.column(k) for k in FORCES])
        return LMNetwork((10,), anchored=True, random_state=seed).fit(dataset.X()[rows], y[rows],
                                                                      groups=dataset.groups[rows])

    models = {"force3": fitted(published, published_train)}
    models |= {f"cycles {s:g} mm/s": fitted(cycles, cycles_train & (speed == s)) for s in SPEEDS_MM_S}
    held_out = {"force3": (published, published_test)}
    held_out |= {f"cycles {s:g} mm/s": (cycles, cycles_test & (speed == s)) for s in SPEEDS_MM_S}
    figures = {}
    for trained, model in models.items():
        for scored, (dataset, rows) in held_out.items():
            scores = axis_scores(dataset.column("fz_N")[rows], model.predict(dataset.X()[rows])[:, 2])
            figures[f"{trained} -> {scored}: all"] = scores["mean_abs_error_N"]
            for phase in PHASES:
                figures[f"{trained} -> {scored}: {phase}"] = scores["by_phase"][f"{phase}_mean_abs_error_N"]
                figures[f"{trained} -> {scored}: {phase} share"] = scores["by_phase"][f"{phase}_share"]
    return figures


def demo_figures(seed: int) -> dict[str, float]:
    """The demo's Fz: offline on its held-out trials and live, overall and by phase."""
    report = run_main_demo(seed=seed, dashboard=False)
    offline, live = report["calibration"]["validation"]["fz_N"], report["live"]["fz_N"]
    figures = {}
    for name, scores in (("demo offline", offline), ("demo live", live),
                         ("demo live, whole loops", report["live_whole_loops"]["fz_N"])):
        figures[f"{name}: all"] = scores["mean_abs_error_N"]
        figures[f"{name}: rest mean"] = scores["rest_mean_N"]
        figures[f"{name}: rest sd"] = scores["rest_sd_N"]
        for phase in PHASES:
            figures[f"{name}: {phase}"] = scores["by_phase"][f"{phase}_mean_abs_error_N"]
            figures[f"{name}: {phase} share"] = scores["by_phase"][f"{phase}_share"]
    for name in ("demo live", "demo live, whole loops"):  # paired: the same seed's model, unit and noise
        figures[f"{name} - offline: all"] = figures[f"{name}: all"] - figures["demo offline: all"]
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    seeds = parser.parse_args().seeds
    runs = [like_for_like(seed) | demo_figures(seed) for seed in seeds]
    print(f"Fz (N) over seeds {seeds}: each seed's figure; mean [95 % t-interval]")
    for name in runs[0]:
        values = np.array([run[name] for run in runs])
        mean, low, high = interval(values) if len(values) > 1 else (values[0], np.nan, np.nan)
        print(f"{name:52s} {' '.join(f'{v:.3f}' for v in values)}   {mean:.3f} [{low:.3f}, {high:.3f}]")


if __name__ == "__main__":
    main()
