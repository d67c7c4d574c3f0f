"""Fits the unknowns of S3's device to the publication's scale and prints the values and the
``[fit]`` record that ``src/softtip/systems/haptics/device.toml`` holds.

The three figures (``published.toml``, ``haptics-scale``): the targets' mean force on the FS, and the
standard method's mean force rendered to the small spherical cast and to the largest human cast.
The fit starts from the device file's values (``softtip.systems.haptics.fit.fit_device``: scipy's
least squares, each figure weighted by the standard error of a 100-target mean) and takes a few
minutes on one core.

    python examples/haptics_device_fit.py [DEVICE.toml]
"""

from __future__ import annotations

import sys

import numpy as np
from rich.console import Console

from softtip._core.progress import RichProgress
from softtip.published import published_table
from softtip.systems.haptics.device import DEVICE_FILE, load_device
from softtip.systems.haptics.fit import FIT_SEEDS, FIT_TARGETS, FITTED, SCALE_TABLE, fit_device


def main() -> None:
    device = load_device(sys.argv[1] if len(sys.argv) > 1 else DEVICE_FILE)
    fit = fit_device(device, progress=RichProgress(Console(stderr=True)))
    for key, value, error in zip(FITTED, fit.values, fit.standard_errors, strict=True):
        print(f"{key} = {value:.6g}  # ± {error:.3g}")
    print(f"figures {np.round(fit.figures, 4).tolist()} N, published {fit.published.tolist()} N, "
          f"standard errors {np.round(fit.figure_errors, 4).tolist()} N, {fit.evaluations} evaluations")
    rows = published_table(SCALE_TABLE).rows
    print("\n[fit]")
    print(f'method = "scipy least squares (softtip.systems.haptics.fit) over seeds '
          f'{", ".join(map(str, FIT_SEEDS))}, {FIT_TARGETS} targets each, to the three figures of the scale table."')
    print(f"parameters = {list(FITTED)}".replace("'", '"'))
    print(f"standard_errors = {[float(f'{e:.4g}') for e in fit.standard_errors]}")
    print(f"correlation = {np.round(fit.correlation, 4).tolist()}")
    print(f"figures = {list(rows)}".replace("'", '"'))
    print(f"residuals = {np.round(fit.residuals, 5).tolist()}")


if __name__ == "__main__":
    main()
