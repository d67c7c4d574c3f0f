"""What a fit owes its user beyond its numbers: whether it is stable, unstable or uncertain, and the
warnings a real record calls for.

- A pole whose confidence interval reaches the stability boundary (a continuous pole's real part
  reaching 0, a discrete pole's modulus reaching 1) leaves the stability "uncertain", not "stable".
- A fit from rest ``FAR_BELOW`` points or more below the fit from each trial's estimated initial state:
  the record does not start at rest, and a model run from rest will not follow it.
- A validation fit ``FAR_BELOW`` points or more below the estimation fit (both from estimated initial
  states): the model is overfitted, or the records differ.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from softtip.sysid.metrics import Scores

FAR_BELOW = 20.0  # fit-% points: a gap that no noise level explains


def _pole_text(pole: dict, unit: str) -> str:
    return f"{pole['real']:.4g}{pole['imag']:+.4g}j{unit}"


def boundary_poles(uncertainty: dict | None) -> list[str]:
    """Every pole of a model's ``uncertainty`` summary (a transfer function's per entry, or a state space's)
    whose interval reaches the stability boundary, described in one line each."""
    if uncertainty is None:
        return []
    z, level = uncertainty["z"], f"{100 * uncertainty['confidence']:g} %"
    found = []
    groups = [(entry["poles"], "continuous") for entry in uncertainty["entries"]] if "entries" in uncertainty \
        else [(uncertainty["poles"], uncertainty["poles_domain"])]
    for poles, domain in groups:
        for pole in poles:
            if domain == "continuous":
                if pole["real"] < 0 <= pole["real"] + z * pole["real_std"]:
                    found.append(f"pole {_pole_text(pole, ' rad/s')}: its {level} interval, ± "
                                 f"{z * pole['real_std']:.2g} on the real part, reaches the imaginary axis")
            else:
                modulus = float(np.hypot(pole["real"], pole["imag"]))
                if modulus < 1 <= modulus + z * pole["modulus_std"]:
                    found.append(f"pole {_pole_text(pole, '')}: its modulus {modulus:.5g} ± "
                                 f"{z * pole['modulus_std']:.2g} ({level}) reaches the unit circle")
    return found


def stability(stable: bool, uncertainty: dict | None) -> tuple[str, list[str]]:
    """("stable" | "unstable" | "uncertain", the warnings that make it uncertain)."""
    if not stable:
        return "unstable", []
    crossing = boundary_poles(uncertainty)
    return ("uncertain" if crossing else "stable"), [f"stability uncertain: {text}" for text in crossing]


def fit_warnings(outputs: Sequence[str], from_rest: Scores, from_state: Scores, data: str,
                 estimation: Scores | None = None) -> list[str]:
    """Warnings on the fits of ``outputs`` on the record ``data``: from rest far below from the estimated
    initial states; and, given the ``estimation`` fit (from estimated states) when ``data`` validates,
    the validation fit far below it."""
    warnings = []
    for k, name in enumerate(outputs):
        rest, state = from_rest.values["fit_percent"][k], from_state.values["fit_percent"][k]
        if state - rest >= FAR_BELOW:
            warnings.append(f"{data}: {name}: the fit from rest, {rest:.4g} %, is {state - rest:.3g} points below "
                            f"the fit from each trial's estimated initial state ({state:.4g} %): the record does "
                            "not start at rest; fit with --initial-state estimate, and run the model from an "
                            "estimated state")
        if estimation is not None:
            fitted = estimation.values["fit_percent"][k]
            if fitted - state >= FAR_BELOW:
                warnings.append(f"{data}: {name}: the validation fit, {state:.4g} %, is {fitted - state:.3g} points "
                                f"below the estimation fit ({fitted:.4g} %; both from estimated initial states): "
                                "overfitted (try a lower order: sysid orders) or the records differ")
    return warnings
