"""The anchored network: its output layer refitted so that a zero input gives a zero output, against the
equality-constrained least squares solved from its own KKT system."""

from __future__ import annotations

import numpy as np
import pytest

from softtip.calibration import LMNetwork, load_model, save_model
from softtip.calibration.feedforward import forward, initial_layers
from softtip.calibration.network import anchored_output_layer


def test_the_anchored_output_layer_is_the_constrained_least_squares_solution():
    rng = np.random.default_rng(3)
    layers = initial_layers([2, 5, 2], rng)
    inputs, targets = rng.uniform(-1, 1, (40, 2)), rng.normal(size=(40, 2))
    anchor_input, anchor_target = np.array([-0.2, 0.4]), np.array([0.3, -0.1])
    layer = anchored_output_layer(layers, inputs, targets, anchor_input, anchor_target)
    # reference: min |A w - b|^2 subject to c . w = d per output, A = [hidden, 1], c = [anchor's hidden, 1],
    # from the KKT system [[2 A'A, c], [c', 0]] [w, lambda] = [2 A'b, d]
    hidden = np.column_stack([forward(layers, inputs)[-2], np.ones(len(inputs))])
    anchor = np.append(forward(layers, anchor_input[None])[-2][0], 1.0)
    kkt = np.block([[2 * hidden.T @ hidden, anchor[:, None]], [anchor[None], np.zeros((1, 1))]])
    for k in range(2):
        solution = np.linalg.solve(kkt, np.append(2 * hidden.T @ targets[:, k], anchor_target[k]))
        np.testing.assert_allclose(layer[k], solution[:-1], rtol=1e-8, atol=1e-10)
    anchored = [*layers[:-1], layer]
    np.testing.assert_allclose(forward(anchored, anchor_input[None])[-1][0], anchor_target, atol=1e-12)


def test_an_anchored_network_reads_zero_at_zero_and_fits_as_well_elsewhere(tmp_path):
    # a convex law through the origin, like force against a Hall reading's change (F ~ dB^1.5), sampled
    # mostly under load: the plain network's output at zero is whatever its fit left there (here 0.0004)
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(0, 0.02, 20), rng.uniform(0, 1, 400)])
    y = np.abs(x) ** 1.5 + rng.normal(0, 0.01, len(x))
    plain = LMNetwork((6,), random_state=1).fit(x[:, None], y)
    anchored = LMNetwork((6,), anchored=True, random_state=1).fit(x[:, None], y)
    assert anchored.predict(np.zeros((1, 1)))[0] == pytest.approx(0.0, abs=1e-12)
    # the same hidden layer, one constraint more: its error does not grow here (measured: 0.00789 both)
    error = {name: np.mean(np.abs(model.predict(x[:, None]) - y)) for name, model in
             (("plain", plain), ("anchored", anchored))}
    assert error["anchored"] <= 1.05 * error["plain"]
    # its model file keeps the anchored layer: the live path reads zero at zero too
    path = save_model(tmp_path / "anchored.npz", anchored, input_channels=["b"], input_units="uT", target_names=["f"],
                      target_units="N")
    restored, _ = load_model(path)
    assert restored.get_params()["anchored"] is True
    assert restored.predict_one(np.zeros(1))[0] == pytest.approx(0.0, abs=1e-12)
