"""The design space: parameter ranges, their grid, and constraints between parameters.

Every search in :mod:`softtip.optimize` works on the same discrete candidate
set - the Cartesian product of each parameter's steps - so a grid sweep and a
sample-efficient search of one study are directly comparable.
"""

from __future__ import annotations

import ast
import itertools
import math
import operator
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from softtip.optimize.errors import StudyError

_DIGITS = 10  # grid values are rounded so 8.0 + 3 * 0.1 is 8.3, the number a user would write


@dataclass(frozen=True)
class ParameterRange:
    """A TOML-level design parameter (``"cavity.radius_mm"``) swept from ``minimum`` to ``maximum``."""

    name: str
    minimum: float
    maximum: float
    step: float
    integer: bool = False  # the design stores it as an integer (e.g. magnets.count)

    @property
    def count(self) -> int:
        """How many values the range holds, counted without making them."""
        return round((self.maximum - self.minimum) / self.step) + 1 if self.maximum > self.minimum else 1

    @property
    def values(self) -> tuple[float, ...]:
        values = (round(self.minimum + k * self.step, _DIGITS) for k in range(self.count))
        return tuple(int(v) for v in values) if self.integer else tuple(values)

    def normalise(self, values: np.ndarray) -> np.ndarray:
        """To [0, 1] over the range (a fixed parameter maps to 0)."""
        span = self.maximum - self.minimum
        return (np.asarray(values, dtype=float) - self.minimum) / span if span > 0 else np.zeros(np.shape(values))


def whole_steps(minimum: float, maximum: float, step: float) -> bool:
    steps = (maximum - minimum) / step
    return math.isclose(steps, round(steps), rel_tol=0, abs_tol=1e-6)


def grid_candidates(parameters: tuple[ParameterRange, ...]) -> list[dict[str, float]]:
    """Every combination of parameter values; the first parameter varies slowest."""
    names = [p.name for p in parameters]
    return [dict(zip(names, combination)) for combination in itertools.product(*(p.values for p in parameters))]


def normalised_points(parameters: tuple[ParameterRange, ...], candidates: list[dict[str, float]]) -> np.ndarray:
    """Candidates as rows of the unit cube, the inputs of the Gaussian process."""
    return np.column_stack([p.normalise([c[p.name] for c in candidates]) for p in parameters]) \
        if candidates else np.zeros((0, len(parameters)))


# --------------------------------------------------------------------------- constraints

_OPERATORS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.Pow: operator.pow, ast.USub: operator.neg, ast.UAdd: operator.pos,
    ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
}
_FUNCTIONS: dict[str, Callable[..., float]] = {"min": min, "max": max, "abs": abs, "sqrt": math.sqrt}


def _dotted(node: ast.AST) -> str | None:
    """``cavity.radius_mm`` parses as an attribute of a name: read it back as one dotted name."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return f"{base}.{node.attr}" if base else None
    return None


@dataclass(frozen=True)
class Constraint:
    """A comparison between arithmetic expressions of design parameters, e.g.
    ``"magnets.circle_radius_mm + magnets.diameter_mm / 2 <= cavity.radius_mm - 1"``.

    Allowed: numbers, TOML-level parameter names, + - * / **, min(), max(), abs(),
    sqrt() and a (possibly chained) comparison < <= > >=; several constraints are
    all required. Parameters not swept keep the base design's value.
    """

    text: str
    tree: ast.Compare
    names: frozenset[str]

    @classmethod
    def parse(cls, text: str, where: str) -> "Constraint":
        def bad(message: str) -> StudyError:
            return StudyError(f"{where} = {text!r}: {message}")

        try:
            tree = ast.parse(text, mode="eval").body
        except SyntaxError:
            raise bad("not an expression") from None
        if not isinstance(tree, ast.Compare):
            raise bad("expected a comparison such as 'a.x_mm + 1 <= b.y_mm'")
        names: set[str] = set()

        def check(node: ast.AST, top: bool = False) -> None:
            if isinstance(node, ast.Compare) and top:
                if any(type(op) not in _OPERATORS for op in node.ops):
                    raise bad("unsupported comparison (allowed: < <= > >=)")
                for child in (node.left, *node.comparators):
                    check(child)
            elif isinstance(node, (ast.BinOp, ast.UnaryOp)):
                if type(node.op) not in _OPERATORS:
                    raise bad("unsupported operator (allowed: + - * / **)")
                for child in ((node.left, node.right) if isinstance(node, ast.BinOp) else (node.operand,)):
                    check(child)
            elif isinstance(node, ast.Call):
                if not (isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS) or node.keywords \
                        or any(isinstance(a, ast.Starred) for a in node.args) or not node.args:
                    raise bad(f"unsupported call (allowed: {', '.join(f'{f}(...)' for f in _FUNCTIONS)})")
                for child in node.args:
                    check(child)
            elif isinstance(node, ast.Constant):
                if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                    raise bad(f"unsupported constant {node.value!r}")
            elif (name := _dotted(node)) is not None:
                names.add(name)
            else:
                raise bad(f"unsupported syntax ({type(node).__name__})")

        check(tree, top=True)
        return cls(text=text, tree=tree, names=frozenset(names))

    def holds(self, values: Mapping[str, float]) -> bool:
        return bool(self._evaluate(self.tree, values))

    def _evaluate(self, node: ast.AST, values: Mapping[str, float]) -> Any:
        if isinstance(node, ast.Compare):
            left = self._evaluate(node.left, values)
            for op, right_node in zip(node.ops, node.comparators):
                right = self._evaluate(right_node, values)
                if not _OPERATORS[type(op)](left, right):
                    return False
                left = right
            return True
        if isinstance(node, ast.BinOp):
            return _OPERATORS[type(node.op)](self._evaluate(node.left, values), self._evaluate(node.right, values))
        if isinstance(node, ast.UnaryOp):
            return _OPERATORS[type(node.op)](self._evaluate(node.operand, values))
        if isinstance(node, ast.Call):
            return _FUNCTIONS[node.func.id](*(self._evaluate(a, values) for a in node.args))
        if isinstance(node, ast.Constant):
            return node.value
        return values[_dotted(node)]
