"""Throughput of the magnet field kernel, printed as JSON.

One reading is one sensor's three field components for one set of magnet
poses. Usage: ``python benchmarks/bench_magnetics.py [--poses 100000 1000000]
[--sensors 1 2] [--magnets 4] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform

import numpy as np

from softtip.magnetics import measure_throughput


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, nargs="+", default=[100_000, 1_000_000])
    parser.add_argument("--sensors", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--magnets", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    results = [
        measure_throughput(n_poses, args.magnets, n_sensors, repeats=args.repeats)
        for n_poses in args.poses
        for n_sensors in args.sensors
    ]
    report = {
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor(), "numpy": np.__version__},
        "results": results,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
