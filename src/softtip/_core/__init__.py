"""Kernels shared by the physics and the data-driven stages, which depend on nothing in softtip."""
