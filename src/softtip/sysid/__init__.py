"""System identification: continuous-time transfer-function and state-space models from sampled input/output data."""
