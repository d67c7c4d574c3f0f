"""Calibration: models from sensor readings to what a robot needs, and their files.

* :class:`PolynomialFit` — per-channel polynomial without cross terms, by pseudo-inverse
  (the published "PFM");
* :class:`LMNetwork` — tanh feedforward regression trained by Levenberg–Marquardt with
  validation early stopping (the toolbox's ``feedforwardnet``/``trainlm``);
* :class:`SoftmaxClassifier` — tanh network with softmax output trained by scaled
  conjugate gradient (``patternnet``/``trainscg``).

All three are scikit-learn estimators with an unchecked ``predict_one`` for real time.
:mod:`softtip.calibration.validation` decides what the network's early stopping holds out
(whole trials, or time blocks of every trial when there are few, different trials), warns of a
validation set outside the calibration range, cross-validates by trial and scores scikit-learn
baselines beside softtip's models. :mod:`softtip.metrics` holds the papers' metrics; :func:`save_model` and
:func:`load_model` store fitted models as ``.npz`` + JSON, never pickle; :func:`fitted` keeps a fit in
the cache as such a file.
"""

from softtip.calibration.classifier import SoftmaxClassifier
from softtip.calibration.network import LMNetwork
from softtip.calibration.persistence import ModelFileError, ModelMetadata, fitted, load_model, save_model
from softtip.calibration.polynomial import PolynomialFit

__all__ = [
    "LMNetwork",
    "ModelFileError",
    "ModelMetadata",
    "PolynomialFit",
    "SoftmaxClassifier",
    "fitted",
    "load_model",
    "save_model",
]
