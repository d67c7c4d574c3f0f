"""Speed and quality of system identification, beside baselines of the same run.

Data: a 3 x 3 system of second-order entries with one zero each (side-sensor forces in, table
forces out), 10 Hz, smooth random presses, 3 % output noise; 1,500 estimation samples (ten 15 s
trials) and three validation trials. Timed: the transfer-function model of order 6 (target
<= 1.5 s), the state-space model of order 8 (subspace; target <= 1 s; and with its prediction-error
refinement), and one streaming step of an order-10 3 x 3 state-space model and of the order-6
transfer function's realisation, alone and as the live pipeline's estimator (its channel selection
and checks included; target <= 50 µs at p99). Baselines: nfoursid (PO-MOESP) at order 8
on the same data (time, and fit % on the validation trials simulated from rest by the same code),
SIPPY's MOESP likewise, and a plain numpy step (x = Ax + Bu, y = Cx + Du) for streaming.

Two single-input cases of known truth, the Rao–Garnier benchmark (:func:`rao_garnier`) and a
laboratory process with levels and coloured noise (:func:`laboratory_process`): our transfer
function and continuous state-space model beside nfoursid and SIPPY's output-error model (time,
validation fit, the largest relative error of a continuous pole). And N4SID, MOESP and CVA on all
three cases: the evidence for the default subspace method. Every fit runs with BLAS on one thread.
"""

from __future__ import annotations

import contextlib
import io
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.signal

from softtip._core.channels import MAGNETIC
from softtip._core.threads import single_threaded_blas
from softtip.bench.timing import latency, timed
from softtip.realtime.estimator import Estimator
from softtip.sysid import transfer
from softtip.sysid.delays import shift_inputs
from softtip.sysid.metrics import fit_percent
from softtip.sysid.models import StateSpaceModel, TransferFunctionModel
from softtip.sysid.recording import Recording
from softtip.sysid.simulation import StreamingSimulator, simulate
from softtip.sysid.statespace import StateSpace
from softtip.sysid.subspace import METHODS

TS = 0.1
TARGETS = {"transfer_function_s": 1.5, "state_space_s": 1.0, "streaming_p99_us": 50.0, "start_s": 1.0}
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


def _end_to_end(recording: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(u, y) of a recording's trials laid end to end: the one record the other libraries take."""
    return np.vstack([trial.u for trial in recording.trials]), np.vstack([trial.y for trial in recording.trials])


def _quiet_sippy(identify) -> tuple[object, float, str]:
    """SIPPY's ``identify()`` timed on one BLAS thread: its result, seconds and what it printed (SIPPY prints
    its warnings; the report keeps them, and the JSON on stdout clean)."""
    printed = io.StringIO()

    def run():
        with single_threaded_blas(), contextlib.redirect_stdout(printed):
            return identify()

    found, seconds = timed(run)
    return found, seconds, printed.getvalue().strip()


def _nfoursid(estimation: Recording, validation: Recording, order: int, block_rows: int) -> dict:
    """nfoursid (PO-MOESP) on the same data: its figures, and its ``system`` (popped by callers that use it)."""
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    u, y = _end_to_end(estimation)
    inputs, outputs = list(estimation.inputs), list(estimation.outputs)
    frame = pd.DataFrame(np.hstack([u, y]), columns=[*inputs, *outputs])

    def identify():
        with single_threaded_blas():
            found = NFourSID(frame, output_columns=outputs, input_columns=inputs, num_block_rows=block_rows)
            found.subspace_identification()
            return found.system_identification(rank=order)[0]

    system, seconds = timed(identify)
    system = StateSpace(system.a, system.b, system.c, system.d, estimation.ts)
    return {"seconds": seconds, "states": order, "num_block_rows": block_rows, "stable": system.is_stable(),
            "validation_fit_percent": _validation_fit(system, validation), "system": system}


def _sippy_state_space(estimation: Recording, validation: Recording, order: int, horizon: int) -> dict:
    """SIPPY's MOESP (its ``system_identification``, module ``sippy_unipi``, PyPI ``sippy-unipi``) on the same
    record as nfoursid, with our horizon as its past and future windows."""
    from sippy_unipi import system_identification

    u, y = _end_to_end(estimation)
    found, seconds, printed = _quiet_sippy(lambda: system_identification(
        y.T, u.T, "MOESP", SS_fixed_order=order, SS_f=horizon, SS_p=horizon, tsample=estimation.ts))
    system = StateSpace(found.A, found.B, found.C, found.D, estimation.ts)
    return {"seconds": seconds, "states": order, "horizon": horizon, "stable": system.is_stable(),
            "validation_fit_percent": _validation_fit(system, validation), "printed": printed}


# ------------------------------------------------------------------------ single-input benchmark cases

RAO_GARNIER = transfer.TransferFunctionMatrix([[[-6400.0, 1600.0]]], [[[1.0, 5.0, 408.0, 416.0, 1600.0]]])
PROCESS = transfer.TransferFunctionMatrix([[[2.4]]], [[[1.0, 2.8, 4.0]]])


def rao_garnier(seed: int, samples: int = 3000, snr_db: float = 20.0) -> Recording:
    """The Rao–Garnier fourth-order benchmark (Rao & Garnier 2002; Garnier & Wang 2008, ch. 5):
    G(s) = (-6400 s + 1600) / (s⁴ + 5 s³ + 408 s² + 416 s + 1600), a slow (-0.5 ± 1.9j) and a fast
    (-2 ± 19.9j) mode, non-minimum phase; 10 ms samples of a random binary input held 7 samples,
    white output noise at ``snr_db``."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], size=samples // 7 + 1), 7)[:samples, None]
    y = transfer.simulate(RAO_GARNIER, u, 0.01)
    noise = np.std(y) * 10 ** (-snr_db / 20) * rng.normal(size=y.shape)
    return Recording.from_arrays(u, y + noise, 0.01, source="Rao-Garnier")


def laboratory_process(seed: int, samples: int = 1000, delay: int = 0) -> Recording:
    """A laboratory process as a control engineer meets it: G(s) = 2.4 / (s² + 2.8 s + 4) at 0.08 s behind
    ``delay`` samples of dead time, a random binary input held 4 samples about a level of 5, the output
    about 4.5 with noise coloured by 1 / (1 - 0.8 q⁻¹) (about 19 dB)."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], size=samples // 4 + 1), 4)[:samples, None]
    y = transfer.simulate(PROCESS, shift_inputs(u, [delay]), 0.08)
    noise = scipy.signal.lfilter([1.0], [1.0, -0.8], 0.03 * rng.normal(size=samples))[:, None]
    return Recording.from_arrays(u + 5.0, y + noise + 4.5, 0.08, inputs=["heater_V"], outputs=["temperature_V"],
                                 input_units="V", output_units="V", source="laboratory process")


def _pole_error(found: np.ndarray, truth: np.ndarray) -> float:
    """The largest relative distance from a true pole to the nearest found one (continuous, rad/s)."""
    if not found.size or not np.all(np.isfinite(found)):
        return float("inf")
    return float(max(np.min(np.abs(found - pole)) / abs(pole) for pole in truth))


def _siso_case(estimation: Recording, validation: Recording, truth: transfer.TransferFunctionMatrix,
               n_zeros: int) -> dict:
    """One single-input case: our transfer function and continuous state space, nfoursid and SIPPY's
    output-error model on the same detrended record: seconds, validation fit % (from rest) and the
    largest relative error of a continuous pole."""
    from sippy_unipi import system_identification

    poles = np.roots(truth.denominators[0][0])
    order = len(poles)
    ts = estimation.ts
    figures = {"truth": {"numerator": truth.numerators[0][0].tolist(), "denominator": truth.denominators[0][0].tolist()}}
    tf_model, seconds = timed(TransferFunctionModel(order, n_zeros, detrend="mean").fit, estimation)
    figures["softtip_transfer_function"] = {
        "seconds": seconds, "validation_fit_percent": float(tf_model.evaluate(validation).values["fit_percent"][0]),
        "pole_error": _pole_error(np.roots(tf_model.tf_.denominators[0][0]), poles), "stable": tf_model.tf_.is_stable()}
    ss_model, seconds = timed(StateSpaceModel(order, domain="continuous", detrend="mean").fit, estimation)
    figures["softtip_state_space"] = {
        "seconds": seconds, "validation_fit_percent": float(ss_model.evaluate(validation).values["fit_percent"][0]),
        "pole_error": _pole_error(ss_model.continuous_.poles(), poles), "stable": ss_model.is_stable(),
        "horizon": ss_model.horizon_}
    level = ss_model.trend_
    centred_estimation, centred_validation = level.remove(estimation), level.remove(validation)
    nfoursid = _nfoursid(centred_estimation, centred_validation, order, ss_model.horizon_)
    system = nfoursid.pop("system")
    figures["nfoursid"] = nfoursid | {"pole_error": _pole_error(np.log(system.poles().astype(complex)) / ts, poles)}
    u, y = centred_estimation.trials[0].u[:, 0], centred_estimation.trials[0].y[:, 0]

    found, seconds, printed = _quiet_sippy(lambda: system_identification(y, u, "OE", OE_orders=[n_zeros + 1, order, 1],
                                                                         tsample=ts))
    numerator, denominator = (np.asarray(part[0][0], dtype=np.float64) for part in (found.NUMERATOR, found.DENOMINATOR))
    discrete = np.roots(denominator)
    discrete = discrete[np.abs(discrete) > 1e-12]  # its delay's poles at the origin aside
    with np.errstate(over="ignore", invalid="ignore"):
        simulated = scipy.signal.dlsim((np.trim_zeros(numerator, "f"), denominator, ts),
                                       centred_validation.trials[0].u[:, 0])[1]
        fit = float(fit_percent(centred_validation.trials[0].y, simulated)[0])
    figures["sippy_output_error"] = {"seconds": seconds, "validation_fit_percent": fit if np.isfinite(fit) else None,
                                     "pole_error": _pole_error(np.log(discrete.astype(complex)) / ts, poles),
                                     "stable": bool(np.all(np.abs(discrete) < 1)),
                                     "printed": printed}
    return figures


def subspace_methods(cases: dict[str, tuple[Recording, Recording, int]]) -> dict:
    """Validation fit % (mean over outputs, from rest) of N4SID, MOESP and CVA on each case at its order:
    the evidence for the default method."""
    return {name: {method: float(StateSpaceModel(order, method, detrend="mean").fit(estimation)
                                 .evaluate(validation).mean("fit_percent")) for method in METHODS}
            for name, (estimation, validation, order) in cases.items()}


def _naive_step(system: StateSpace):
    A, B, C, D = system.A, system.B, system.C, system.D
    state = np.zeros(system.n_states)

    def step(u):
        nonlocal state
        y = C @ state + D @ u
        state = A @ state + B @ u
        return y

    return step


def _run_seconds(arguments: list[str], repeats: int) -> float:
    """The shortest wall time (s) of ``repeats`` runs of the Python interpreter with ``arguments``: the
    least disturbed by other work."""
    environment = os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)}
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([sys.executable, *arguments], check=True, capture_output=True, env=environment)
        best = min(best, time.perf_counter() - start)
    return best


def start_times(repeats: int = 3) -> dict:
    """Seconds, each the best of ``repeats`` fresh processes, of: the interpreter alone (the baseline),
    ``import softtip.sysid``, ``softtip sysid --help``, and a whole ``softtip sysid fit`` of a 200-sample
    record, CSV and Parquet (state space, order 2: the fit itself takes milliseconds, the rest is starting);
    with the load average they were measured under."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rng = np.random.default_rng(0)
    u = rng.normal(size=200)
    y = np.convolve(u, [0.0, 0.5, 0.25])[:200]
    with tempfile.TemporaryDirectory() as folder:
        record = Path(folder) / "record.csv"
        record.write_text("time_s,u,y\n" + "".join(f"{0.01 * k:.2f},{a:.6f},{b:.6f}\n"
                                                      for k, (a, b) in enumerate(zip(u, y))))
        pq.write_table(pa.table({"time_s": 0.01 * np.arange(200), "u": u, "y": y}), Path(folder) / "record.parquet")
        command = ["-m", "softtip", "sysid"]
        fit = ["-u", "u", "-y", "y", "--kind", "ss", "--order", "2"]
        return {"interpreter_s": _run_seconds(["-c", "pass"], repeats),
                "import_sysid_s": _run_seconds(["-c", "import softtip.sysid"], repeats),
                "help_s": _run_seconds([*command, "--help"], repeats),
                "fit_s": _run_seconds([*command, "fit", "--data", str(record), *fit], repeats),
                "fit_parquet_s": _run_seconds([*command, "fit", "--data", str(record.with_suffix(".parquet")), *fit],
                                              repeats),
                "load_average": list(os.getloadavg()), "repeats": repeats}


def bench_sysid(calls: int = 20_000, seed: int = 0) -> dict:
    """Fit times and validation fit % of the transfer-function (order 6) and state-space (order 8) models
    beside nfoursid, and streaming-step latencies beside a plain numpy step."""
    estimation, validation = force_like(seed=seed)
    transfer_model, tf_seconds = timed(TransferFunctionModel(6).fit, estimation)
    state_space, ss_seconds = timed(StateSpaceModel(8).fit, estimation)
    refined, refined_seconds = timed(StateSpaceModel(8, refine=True).fit, estimation)
    order_10 = StateSpaceModel(10).fit(estimation)
    nfoursid = _nfoursid(estimation, validation, 8, state_space.horizon_)
    nfoursid.pop("system")
    sippy = _sippy_state_space(estimation, validation, 8, state_space.horizon_)
    cases = {"rao_garnier": (rao_garnier(seed), rao_garnier(seed + 1)),
             "laboratory_process": (laboratory_process(seed), laboratory_process(seed + 1))}
    siso = {"rao_garnier": _siso_case(*cases["rao_garnier"], RAO_GARNIER, 1),
            "laboratory_process": _siso_case(*cases["laboratory_process"], PROCESS, 0)}
    methods = subspace_methods({"force_3x3": (estimation, validation, 8),
                                "rao_garnier": (*cases["rao_garnier"], 4),
                                "laboratory_process": (*cases["laboratory_process"], 2)})

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
        "sippy": {"note": "SIPPY (PyPI sippy-unipi, module sippy_unipi): MOESP on the same record and horizon; "
                          "its output-error model in the single-input cases", "moesp_order_8": sippy},
        "single_input_cases": siso,
        "subspace_methods": {"validation_fit_percent": methods, "default": StateSpaceModel().method,
                             "default_points_below_the_best": {
                                 name: max(fits.values()) - fits[StateSpaceModel().method]
                                 for name, fits in methods.items()}},
        "streaming_step_us": streaming,
        "start": start_times(),
        "targets": TARGETS,
    }
    ours = streaming["state_space_order_10"]
    results["targets_met"] = {
        "transfer_function_s": tf_seconds <= TARGETS["transfer_function_s"],
        "state_space_s": ss_seconds <= TARGETS["state_space_s"],
        "streaming_p99_us": max(ours["p99_us"], streaming["transfer_function_order_6"]["p99_us"],
                                streaming["live_estimator_transfer_function_order_6"]["p99_us"])
        <= TARGETS["streaming_p99_us"],
        "start_s": max(results["start"]["help_s"], results["start"]["fit_s"], results["start"]["fit_parquet_s"])
        <= TARGETS["start_s"],
    }
    results["ratios"] = {
        "nfoursid_time_over_state_space": nfoursid["seconds"] / ss_seconds,
        "sippy_time_over_state_space": sippy["seconds"] / ss_seconds,
        "state_space_mean_fit_minus_nfoursid": float(np.mean(results["state_space_order_8"]["validation_fit_percent"])
                                                     - np.mean(nfoursid["validation_fit_percent"])),
        "transfer_function_time_over_nfoursid": tf_seconds / nfoursid["seconds"],
        "numpy_step_over_streaming_step": streaming["numpy_step_order_10"]["median_us"] / ours["median_us"],
    }
    return results
