"""Speed and quality of system identification on force-sensor-like data, beside baselines of the same run.

Data: a 3 x 3 system of second-order entries with one zero each (side-sensor forces in, table
forces out), 10 Hz, smooth random presses, 3 % output noise; 1,500 estimation samples (ten 15 s
trials) and three validation trials. Timed: the transfer-function model of order 6 (target
<= 1.5 s), the state-space model of order 8 (subspace; target <= 1 s; and with its prediction-error
refinement), and one streaming step of an order-10 3 x 3 state-space model and of the order-6
transfer function's realisation, alone and as the live pipeline's estimator (its channel selection
and checks included; target <= 50 µs at p99). Baselines: nfoursid (PO-MOESP) at order 8
on the same data (time, and fit % on the validation trials simulated from rest by the same code),
SIPPY when it is installed, and a plain numpy step (x = Ax + Bu, y = Cx + Du) for streaming. Every
fit runs with BLAS on one thread.
"""

from __future__ import annotations

import importlib.util
import os
import platform

import numpy as np
import scipy.signal

from softtip._core.channels import MAGNETIC
from softtip._core.threads import single_threaded_blas
from softtip.bench.timing import latency, timed
from softtip.realtime.estimator import Estimator
from softtip.sysid import transfer
from softtip.sysid.metrics import fit_percent
from softtip.sysid.models import StateSpaceModel, TransferFunctionModel
from softtip.sysid.recording import Recording
from softtip.sysid.simulation import StreamingSimulator, simulate
from softtip.sysid.statespace import StateSpace

TS = 0.1
TARGETS = {"transfer_function_s": 1.5, "state_space_s": 1.0, "streaming_p99_us": 50.0}
INPUTS, OUTPUTS = ("Fx_side", "Fy_side", "Fz_side"), ("Fx", "Fy", "Fz")


def force_like(estimation_trials: int = 10, validation_trials: int = 3, length: int = 150,
                  noise: float = 0.03, seed: int = 0) -> tuple[Recording, Recording]:
    """(estimation, validation) recordings of a 3 x 3 force system; see the module notes."""
    rng = np.random.default_rng(seed)
    numerators, denominators = [], []
    for i in range(3):
        numerators.append([]), denominators.append([])
        for j in range(3):
            w, z = rng.uniform(2, 8), rng.uniform(0.4, 0.9)
            gain = (1.0 if i == j else 0.2) * rng.uniform(0.5, 1.5)
            numerators[-1].append([0.2 * gain * w, gain * w * w])
            denominators[-1].append([1.0, 2 * z * w, w * w])
    truth = transfer.TransferFunctionMatrix(numerators, denominators)
    b, a = scipy.signal.butter(2, 0.15)
    trials = []
    for k in range(estimation_trials + validation_trials):
        u = np.column_stack([scipy.signal.lfilter(b, a, rng.normal(size=length)) * (3 if j == k % 3 else 0.5)
                             for j in range(3)])
        y = transfer.simulate(truth, u, TS)
        trials.append((u, y + noise * np.std(y, axis=0) * rng.normal(size=y.shape)))
    recording = Recording.from_arrays([u for u, _ in trials], [y for _, y in trials], TS, inputs=INPUTS,
                                      outputs=OUTPUTS, input_units="N", output_units="N", source="bench")
    return recording.select(range(estimation_trials)), recording.select(range(estimation_trials, len(trials)))


def _validation_fit(system: StateSpace, validation: Recording) -> list[float]:
    y = np.vstack([trial.y for trial in validation.trials])
    yhat = np.vstack([simulate(system, trial.u) for trial in validation.trials])
    return [float(v) for v in fit_percent(y, yhat)]


def _model_figures(model, seconds: float, validation: Recording) -> dict:
    return {"seconds": seconds, "states": model.system_.n_states, "stable": model.system_.is_stable(),
            "validation_fit_percent": _validation_fit(model.system_, validation)}


def _nfoursid(estimation: Recording, validation: Recording, order: int, block_rows: int) -> dict:
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    # nfoursid takes one record: the trials laid end to end
    u = np.vstack([trial.u for trial in estimation.trials])
    y = np.vstack([trial.y for trial in estimation.trials])
    frame = pd.DataFrame(np.hstack([u, y]), columns=[*INPUTS, *OUTPUTS])

    def identify():
        with single_threaded_blas():
            found = NFourSID(frame, output_columns=list(OUTPUTS), input_columns=list(INPUTS),
                             num_block_rows=block_rows)
            found.subspace_identification()
            return found.system_identification(rank=order)[0]

    system, seconds = timed(identify)
    system = StateSpace(system.a, system.b, system.c, system.d, TS)
    return {"seconds": seconds, "states": order, "num_block_rows": block_rows, "stable": system.is_stable(),
            "validation_fit_percent": _validation_fit(system, validation)}


def _sippy() -> dict:
    """SIPPY (system identification in Python, University of Pisa) when installed: its module is ``sippy``
    with ``system_identification``. The PyPI name ``sippy`` is an unrelated SIP telephony stack."""
    if importlib.util.find_spec("sippy") is None:
        return {"available": False, "note": "SIPPY is not installed; it is not published on PyPI (the name "
                                             "'sippy' there is an unrelated SIP telephony stack)"}
    import sippy

    if not hasattr(sippy, "system_identification"):
        return {"available": False, "note": "the installed 'sippy' is not SIPPY (no system_identification): "
                                            "the PyPI package of that name is a SIP telephony stack"}
    return {"available": True, "note": "installed, not compared by this bench"}


def _naive_step(system: StateSpace):
    A, B, C, D = system.A, system.B, system.C, system.D
    state = np.zeros(system.n_states)

    def step(u):
        nonlocal state
        y = C @ state + D @ u
        state = A @ state + B @ u
        return y

    return step


def bench_sysid(calls: int = 20_000, seed: int = 0) -> dict:
    """Fit times and validation fit % of the transfer-function (order 6) and state-space (order 8) models
    beside nfoursid, and streaming-step latencies beside a plain numpy step."""
    estimation, validation = force_like(seed=seed)
    transfer_model, tf_seconds = timed(TransferFunctionModel(6).fit, estimation)
    state_space, ss_seconds = timed(StateSpaceModel(8).fit, estimation)
    refined, refined_seconds = timed(StateSpaceModel(8, refine=True).fit, estimation)
    order_10 = StateSpaceModel(10).fit(estimation)
    nfoursid = _nfoursid(estimation, validation, 8, state_space.horizon_)

    frame = estimation.trials[0].u[0].copy()
    streaming = {
        "state_space_order_10": latency(StreamingSimulator(order_10.system_).step, frame, calls),
        "transfer_function_order_6": latency(transfer_model.streaming().step, frame, calls),
        "live_estimator_transfer_function_order_6": latency(
            Estimator(transfer_model, MAGNETIC.channel_names(1), target_names=OUTPUTS, target_units="N").estimate,
            frame, calls),
        "numpy_step_order_10": latency(_naive_step(order_10.system_), frame, calls),
    }
    report = transfer_model.report_
    results = {
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
                    "numpy": np.__version__},
        "data": {"inputs": list(INPUTS), "outputs": list(OUTPUTS), "ts": TS,
                 "estimation_samples": estimation.n_samples, "validation_samples": validation.n_samples},
        "transfer_function_order_6": _model_figures(transfer_model, tf_seconds, validation) | {
            "converged": bool(report.converged), "message": report.message},
        "state_space_order_8": _model_figures(state_space, ss_seconds, validation),
        "state_space_order_8_refined": _model_figures(refined, refined_seconds, validation) | {
            "refinement": refined.refinement_.to_dict()},
        "nfoursid_order_8": nfoursid,
        "sippy": _sippy(),
        "streaming_step_us": streaming,
        "targets": TARGETS,
    }
    ours = streaming["state_space_order_10"]
    results["targets_met"] = {
        "transfer_function_s": tf_seconds <= TARGETS["transfer_function_s"],
        "state_space_s": ss_seconds <= TARGETS["state_space_s"],
        "streaming_p99_us": max(ours["p99_us"], streaming["transfer_function_order_6"]["p99_us"],
                                streaming["live_estimator_transfer_function_order_6"]["p99_us"])
        <= TARGETS["streaming_p99_us"],
    }
    results["ratios"] = {
        "nfoursid_time_over_state_space": nfoursid["seconds"] / ss_seconds,
        "state_space_mean_fit_minus_nfoursid": float(np.mean(results["state_space_order_8"]["validation_fit_percent"])
                                                     - np.mean(nfoursid["validation_fit_percent"])),
        "transfer_function_time_over_nfoursid": tf_seconds / nfoursid["seconds"],
        "numpy_step_over_streaming_step": streaming["numpy_step_order_10"]["median_us"] / ours["median_us"],
    }
    return results
