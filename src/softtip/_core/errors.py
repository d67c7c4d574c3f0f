"""Errors shared by softtip's numerical stages."""


class NotConverged(ArithmeticError):
    """An iterative computation reached its iteration cap before meeting its convergence criterion."""
