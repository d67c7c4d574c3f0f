"""Kernels of the tanh feedforward networks: scaling, initialisation, forward pass,
gradient, Gauss–Newton matrix and data division. Pure numpy, vectorised over samples.

A layer's weights are one augmented matrix of shape ``(n_out, n_in + 1)`` whose last column
is the bias. The parameter vector θ is the concatenation of the row-major augmented
matrices, so the parameters feeding output ``k`` of the last layer form one contiguous run
(row ``k``), which the Gauss–Newton matrix exploits.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from softtip._core.network import fold_scaling

# tanh is steep (not saturated) for net inputs in [-2, 2]: the Nguyen–Widrow spread targets it
TANH_ACTIVE_HALF_WIDTH = 2.0


# --------------------------------------------------------------------------
# mapminmax scaling
# --------------------------------------------------------------------------


def minmax_gain(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Per-column gain mapping [low, high] onto [-1, 1]; 1 for constant columns (as mapminmax)."""
    span = high - low
    return np.where(span > 0, 2.0 / np.where(span > 0, span, 1.0), 1.0)


def to_unit_range(values: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """``values`` mapped column-wise so that ``low -> -1`` and ``high -> +1``."""
    return (values - low) * minmax_gain(low, high) - 1.0


# --------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------


def layer_shapes(sizes: Sequence[int]) -> list[tuple[int, int]]:
    """Augmented weight shapes for layer sizes ``[n_inputs, hidden..., n_outputs]``."""
    return [(n_out, n_in + 1) for n_in, n_out in zip(sizes[:-1], sizes[1:], strict=True)]


def unpack(theta: np.ndarray, shapes: Sequence[tuple[int, int]]) -> list[np.ndarray]:
    """Views of ``theta`` as the augmented weight matrices of each layer."""
    layers, start = [], 0
    for rows, cols in shapes:
        layers.append(theta[start:start + rows * cols].reshape(rows, cols))
        start += rows * cols
    return layers


def pack(layers: Sequence[np.ndarray]) -> np.ndarray:
    return np.concatenate([w.ravel() for w in layers])


def nguyen_widrow(n_out: int, n_in: int, rng: np.random.Generator) -> np.ndarray:
    """Augmented weights of a tanh layer whose inputs lie in [-1, 1] (Nguyen & Widrow 1990).

    As the toolbox's ``initnw``: random unit directions of magnitude 0.7·n_out^(1/n_in),
    biases spread evenly over the same magnitude, both stretched to tanh's active range.
    """
    directions = rng.uniform(-1.0, 1.0, (n_out, n_in))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    magnitude = 0.7 * n_out ** (1.0 / n_in)
    weights = magnitude * directions
    if n_out > 1:
        biases = magnitude * np.linspace(-1.0, 1.0, n_out) * np.sign(weights[:, 0])
    else:
        biases = np.zeros(1)
    return TANH_ACTIVE_HALF_WIDTH * np.column_stack([weights, biases])


def initial_layers(sizes: Sequence[int], rng: np.random.Generator) -> list[np.ndarray]:
    """Nguyen–Widrow hidden layers and a uniform [-1, 1] output layer (the toolbox's ``rands``)."""
    shapes = layer_shapes(sizes)
    hidden = [nguyen_widrow(rows, cols - 1, rng) for rows, cols in shapes[:-1]]
    return hidden + [rng.uniform(-1.0, 1.0, shapes[-1])]


# --------------------------------------------------------------------------
# Forward pass, gradient, Gauss–Newton matrix
# --------------------------------------------------------------------------


def affine(weights: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    return inputs @ weights[:, :-1].T + weights[:, -1]


def forward(layers: Sequence[np.ndarray], inputs: np.ndarray) -> list[np.ndarray]:
    """Activations ``[inputs, tanh hidden..., linear output]``, each of shape (n_samples, width)."""
    activations = [inputs]
    for weights in layers[:-1]:
        activations.append(np.tanh(affine(weights, activations[-1])))
    activations.append(affine(layers[-1], activations[-1]))
    return activations


def _augmented(activation: np.ndarray) -> np.ndarray:
    return np.column_stack([activation, np.ones(len(activation))])


def backprop_gradient(layers: Sequence[np.ndarray], activations: Sequence[np.ndarray],
                      output_delta: np.ndarray) -> np.ndarray:
    """Σ_n,k output_delta[n, k] · ∂y[n, k]/∂θ, where y is the output layer's net input.

    With ``output_delta = ∂loss/∂y`` this is the loss gradient; with the residuals of
    a least-squares fit it is Jᵀe.
    """
    gradients = []
    delta = output_delta
    for index in range(len(layers) - 1, -1, -1):
        below = activations[index]
        gradient = np.empty(layers[index].shape)
        gradient[:, :-1] = delta.T @ below
        gradient[:, -1] = delta.sum(axis=0)
        gradients.append(gradient.ravel())
        if index:
            delta = (delta @ layers[index][:, :-1]) * (1.0 - below**2)
    return np.concatenate(gradients[::-1])


def gauss_newton_matrix(layers: Sequence[np.ndarray], activations: Sequence[np.ndarray]) -> np.ndarray:
    """JᵀJ, J = ∂y/∂θ the Jacobian of the linear outputs over all samples and outputs.

    The output layer's block is block-diagonal (output k depends only on row k of the last
    layer), so only the hidden layers' Jacobian is formed densely.
    """
    if len(layers) == 2:
        return _single_hidden_gauss_newton_matrix(layers, activations)
    n_samples, n_outputs = activations[-1].shape
    shapes = [w.shape for w in layers]
    n_hidden_params = sum(rows * cols for rows, cols in shapes[:-1])
    last_hidden = _augmented(activations[-2])
    width = last_hidden.shape[1]

    # sensitivities ∂y_k/∂(net input of a hidden layer), from the last hidden layer down
    jacobian = np.empty((n_samples, n_outputs, n_hidden_params))
    delta = layers[-1][None, :, :-1] * (1.0 - activations[-2] ** 2)[:, None, :]
    stop = n_hidden_params
    for index in range(len(layers) - 2, -1, -1):
        rows, cols = shapes[index]
        block = jacobian[:, :, stop - rows * cols:stop].reshape(n_samples, n_outputs, rows, cols)
        np.multiply(delta[:, :, :, None], _augmented(activations[index])[:, None, None, :], out=block)
        stop -= rows * cols
        if index:
            delta = (delta @ layers[index][:, :-1]) * (1.0 - activations[index] ** 2)[:, None, :]

    flat = jacobian.reshape(n_samples * n_outputs, n_hidden_params)
    size = n_hidden_params + n_outputs * width
    matrix = np.empty((size, size))
    matrix[:n_hidden_params, :n_hidden_params] = flat.T @ flat
    for k in range(n_outputs):
        columns = slice(n_hidden_params + k * width, n_hidden_params + (k + 1) * width)
        cross = jacobian[:, k, :].T @ last_hidden
        matrix[:n_hidden_params, columns] = cross
        matrix[columns, :n_hidden_params] = cross.T
    gram = last_hidden.T @ last_hidden
    matrix[n_hidden_params:, n_hidden_params:] = np.kron(np.eye(n_outputs), gram)
    return matrix


def _single_hidden_gauss_newton_matrix(layers: Sequence[np.ndarray], activations: Sequence[np.ndarray]) -> np.ndarray:
    """JᵀJ of a one-hidden-layer network, its hidden block in 1/K of the general case's flops.

    ∂y_k/∂W1[j, i] = W2[k, j]·d_j·x̃_i with d = 1 − h², so the hidden block is
    Σ_k W2[k, j]W2[k, j′] · Σ_n Z_n,(j,i) Z_n,(j′,i′) with Z = d ⊗ x̃: one Gram matrix of Z
    weighted by W2ᵀW2, instead of one Gram matrix per output.
    """
    inputs, hidden = _augmented(activations[0]), activations[1]
    n_samples, n_inputs = inputs.shape
    n_hidden = hidden.shape[1]
    output_weights = layers[1][:, :-1]
    n_outputs = output_weights.shape[0]
    # Z is built input-major (column i·H + j: numpy's product is faster along the longer axis);
    # ``order`` takes θ's (j, i) index to that column
    z = np.einsum("ni,nj->nij", inputs, 1.0 - hidden**2).reshape(n_samples, n_inputs * n_hidden)
    order = (np.arange(n_hidden)[:, None] + n_hidden * np.arange(n_inputs)).ravel()
    last_hidden = _augmented(hidden)
    width = n_hidden + 1
    n_hidden_params = n_hidden * n_inputs
    size = n_hidden_params + n_outputs * width
    matrix = np.empty((size, size))
    matrix[:n_hidden_params, :n_hidden_params] = (z.T @ z)[np.ix_(order, order)] * np.repeat(
        np.repeat(output_weights.T @ output_weights, n_inputs, axis=0), n_inputs, axis=1)
    z_hidden = (z.T @ last_hidden)[order]
    for k in range(n_outputs):
        columns = slice(n_hidden_params + k * width, n_hidden_params + (k + 1) * width)
        cross = z_hidden * np.repeat(output_weights[k], n_inputs)[:, None]
        matrix[:n_hidden_params, columns] = cross
        matrix[columns, :n_hidden_params] = cross.T
    matrix[n_hidden_params:, n_hidden_params:] = np.kron(np.eye(n_outputs), last_hidden.T @ last_hidden)
    return matrix


def softmax(logits: np.ndarray) -> np.ndarray:
    shifted = np.exp(logits - logits.max(axis=-1, keepdims=True))
    return shifted / shifted.sum(axis=-1, keepdims=True)


def cross_entropy(probabilities: np.ndarray, one_hot: np.ndarray) -> float:
    """Mean over samples of −Σ_k t_k log p_k (log clipped at the smallest positive double)."""
    return float(-np.sum(one_hot * np.log(np.maximum(probabilities, np.finfo(float).tiny))) / len(one_hot))


# --------------------------------------------------------------------------
# Data division and run-time weights
# --------------------------------------------------------------------------


def divide(n_samples: int, fractions: Sequence[float], rng: np.random.Generator,
           groups: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random train/validation/test indices in the given fractions (the toolbox's ``dividerand``).

    With ``groups`` (e.g. trial ids) whole groups are divided, never single samples, and the
    fractions count groups. At least one sample (group) is always kept for training.
    """
    if groups is None:
        units, unit_of_sample = n_samples, np.arange(n_samples)
    else:
        _, unit_of_sample = np.unique(groups, return_inverse=True)
        units = int(unit_of_sample.max()) + 1
    n_validation = int(round(fractions[1] * units))
    n_test = int(round(fractions[2] * units))
    while n_validation + n_test >= units and n_validation + n_test > 0:
        if n_test >= n_validation:
            n_test -= 1
        else:
            n_validation -= 1
    order = rng.permutation(units)
    role = np.zeros(units, dtype=np.int8)
    role[order[units - n_validation - n_test:units - n_test]] = 1
    role[order[units - n_test:]] = 2
    sample_role = role[unit_of_sample]
    return tuple(np.flatnonzero(sample_role == r) for r in range(3))


def runtime_layers(layers: Sequence[np.ndarray], input_low: np.ndarray, input_high: np.ndarray,
                   output_gain: np.ndarray | None = None,
                   output_offset: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(W, b) pairs for the run-time network (:mod:`softtip._core.network`), with the input
    scaling (mapminmax: ``s = g x - (g low + 1)``) folded into the first layer and the output map
    ``y = output_gain * y_scaled + output_offset`` into the last."""
    gain = minmax_gain(input_low, input_high)
    pairs = [(w[:, :-1], w[:, -1]) for w in layers]
    return fold_scaling(pairs, gain, -(gain * input_low + 1.0), output_gain, output_offset)


# --------------------------------------------------------------------------
# Early stopping
# --------------------------------------------------------------------------


class EarlyStopping:
    """The toolbox's validation rule: keep the parameters of the lowest validation error so
    far; every later epoch above it is a failure, and only a new lowest error resets the
    count (an epoch equal to it neither fails nor resets). Without a validation set (NaN
    errors) the latest parameters are kept and nothing fails.
    """

    def __init__(self, theta: np.ndarray, validation_error: float):
        self.best_theta = theta.copy()
        self.best_error = validation_error
        self.best_epoch = 0
        self.failures = 0

    def update(self, epoch: int, theta: np.ndarray, validation_error: float) -> None:
        if np.isnan(validation_error) or validation_error < self.best_error:
            self.best_theta = theta.copy()
            self.best_error = validation_error
            self.best_epoch = epoch
            self.failures = 0
        elif validation_error > self.best_error:
            self.failures += 1


def stop_reason(epoch: int, perf: float, gradient_norm: float, stopping: EarlyStopping, *, max_epochs: int,
                goal: float, min_grad: float, max_fail: int, limit_reached: str = "") -> str:
    """Why training stops after ``epoch``, by the toolbox's rules in their order of precedence, or ""
    to go on; ``limit_reached`` names a limit of the training method itself that was hit (checked
    after min_grad, before validation)."""
    if perf <= goal:
        return "goal"
    if epoch == max_epochs:
        return "max_epochs"
    if gradient_norm <= min_grad:
        return "min_grad"
    if limit_reached:
        return limit_reached
    if stopping.failures >= max_fail:
        return "validation"
    return ""
