"""The one run-time of softtip's tanh networks: tanh hidden layers, a linear output layer.

A network is a list of ``(W, b)`` pairs, ``W`` of shape (outputs, inputs), with any input and
output scaling already folded into the first and last layers, so evaluating it is nothing but
products. Calibration models (:mod:`softtip.calibration`) and the reduced twin's networks
(:mod:`softtip.twin.reduced`) both run here; the layers' dtype sets the precision of a batch.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

Layers = Sequence[tuple[np.ndarray, np.ndarray]]

PREDICT_CHUNK = 4096  # rows per block: the activations of a block stay in cache


def fold_scaling(pairs: Layers, input_gain: np.ndarray, input_offset: np.ndarray,
                 output_gain: np.ndarray | None = None, output_offset: np.ndarray | None = None) -> list:
    """The pairs of a network trained on scaled data ``s = input_gain * x + input_offset`` with
    outputs ``y = output_gain * y_scaled + output_offset``, as a network of the raw data:
    ``W s + b = (W input_gain) x + (b + W input_offset)``."""
    pairs = [(np.ascontiguousarray(w), np.array(b)) for w, b in pairs]
    first_w, first_b = pairs[0]
    pairs[0] = (np.ascontiguousarray(first_w * input_gain), first_b + first_w @ input_offset)
    if output_gain is not None:
        last_w, last_b = pairs[-1]
        pairs[-1] = (np.ascontiguousarray(last_w * output_gain[:, None]), last_b * output_gain + output_offset)
    return pairs


def forward_one(pairs: Layers, sample: np.ndarray) -> np.ndarray:
    """Outputs for one sample (1-D): the real-time path."""
    activation = sample
    for weights, bias in pairs[:-1]:
        activation = np.tanh(weights @ activation + bias)
    weights, bias = pairs[-1]
    return weights @ activation + bias


def predict_batch(pairs: Layers, inputs: np.ndarray, chunk: int = PREDICT_CHUNK) -> np.ndarray:
    """Outputs (N, outputs) in float64 for many samples, block by block, each block computed in the
    layers' precision (single-precision layers are about three times faster in batch)."""
    dtype = pairs[0][0].dtype
    outputs = np.empty((len(inputs), pairs[-1][0].shape[0]))
    for start in range(0, len(inputs), chunk):
        activation = inputs[start:start + chunk].astype(dtype, copy=False)
        for weights, bias in pairs[:-1]:
            activation = activation @ weights.T
            activation += bias
            np.tanh(activation, out=activation)
        last_w, last_b = pairs[-1]
        np.add(activation @ last_w.T, last_b, out=outputs[start:start + chunk])
    return outputs
