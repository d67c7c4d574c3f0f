"""System identification: linear models of a system from sampled input/output recordings."""
