"""Per-axis polynomial fit without cross terms (the published "PFM").

For channels x1 … xm and degree d (published: 3) the features are
[x1^d … x1² x1  x2^d … x2  …  xm^d … xm  1], and the outputs are features · A with A
solved by the pseudo-inverse. Before the pseudo-inverse each feature column is divided
by its largest magnitude (raw µT readings cubed span twelve orders of magnitude); this
leaves the least-squares solution unchanged while keeping the singular-value cut-off of
``pinv`` meaningful.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils.validation import check_is_fitted, validate_data

from softtip._core.config import integer, parse, schema
from softtip.calibration import checks


def _powers(values: np.ndarray, degree: int) -> np.ndarray:
    """values^degree … values^1 along a new last axis, by repeated products (a float power is far slower)."""
    powers = np.empty(values.shape + (degree,))
    powers[..., -1] = values
    for k in range(degree - 2, -1, -1):
        np.multiply(powers[..., k + 1], values, out=powers[..., k])
    return powers


def polynomial_features(inputs: np.ndarray, degree: int) -> np.ndarray:
    """Design matrix (n_samples, n_channels·degree + 1): per channel the powers degree…1, then 1."""
    return np.column_stack([_powers(inputs, degree).reshape(len(inputs), -1), np.ones(len(inputs))])


@schema
class PolynomialSettings:
    degree: integer(1)


class PolynomialFit(RegressorMixin, BaseEstimator):
    """Per-channel polynomial of ``degree`` without cross terms, least squares by pseudo-inverse.

    Fitted attributes: ``coef_`` (n_channels·degree + 1, n_outputs), rows in the feature
    order of :func:`polynomial_features`; ``n_outputs_``.
    """

    def __init__(self, degree=3):
        self.degree = degree

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    def _degree(self) -> int:
        """The degree, checked (scikit-learn stores it as given)."""
        return parse(PolynomialSettings, self.get_params(), type(self).__name__).degree

    def fit(self, X, y, groups=None):
        """Least squares by pseudo-inverse. ``groups`` (the trial of each sample) is accepted so that
        every softtip model is fitted the same way; a closed-form fit holds nothing out."""
        degree = self._degree()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        targets = y.reshape(len(y), -1).astype(np.float64)
        design = polynomial_features(X, degree)
        column_scale = np.abs(design).max(axis=0)
        column_scale[column_scale == 0] = 1.0
        self.coef_ = np.linalg.pinv(design / column_scale) @ targets / column_scale[:, None]
        self.n_outputs_ = targets.shape[1]
        return self

    def predict(self, X) -> np.ndarray:
        """Outputs for X; 1-D when the fit has one output."""
        check_is_fitted(self, "coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        outputs = polynomial_features(X, self.degree) @ self.coef_
        return outputs.ravel() if self.n_outputs_ == 1 else outputs

    def predict_one(self, x: np.ndarray) -> np.ndarray:
        """Outputs (1-D) for one sample (1-D, float64), without input checks: the real-time path."""
        return _powers(x, self.degree).ravel() @ self.coef_[:-1] + self.coef_[-1]

    def _export(self) -> tuple[dict[str, np.ndarray], dict]:
        """Fitted arrays and JSON-able fitted state, for saving without pickle."""
        check_is_fitted(self, "coef_")
        return {"coef": self.coef_}, {"n_features_in": int(self.n_features_in_), "n_outputs": int(self.n_outputs_)}

    @classmethod
    def _restore(cls, params: dict, arrays: dict[str, np.ndarray], state: dict) -> PolynomialFit:
        """A fitted polynomial from :meth:`_export` output; ValueError if the parts do not fit together."""
        fit = cls(**params)
        degree = fit._degree()
        fit.n_features_in_ = checks.stored_int(state, "n_features_in", 1)
        fit.n_outputs_ = checks.stored_int(state, "n_outputs", 1)
        fit.coef_ = checks.stored_array(arrays, "coef", (fit.n_features_in_ * degree + 1, fit.n_outputs_))
        return fit
