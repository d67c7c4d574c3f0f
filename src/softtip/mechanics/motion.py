"""Load histories: an indenter's motion as a chain of straight segments in time.

A :class:`Motion` starts at first touch (zero depth, zero tangential travel) and
is built step by step, each step ending where the next begins::

    cycle = Motion().push(3e-3, speed=0.25e-3).hold(1.0).release(speed=0.25e-3)
    times, depth, tangential = cycle.sample(rate_hz=100.0)

The state is (depth, tx, ty) in metres: the normal travel after first touch and
the tangential travel along x and y, the quantities of a
:class:`~softtip.mechanics.contact.LoadCase`. Steps:

``push(depth, speed)``      press a further ``depth`` deeper
``hold(seconds)``           stay put
``release(speed)``          lift straight up to zero depth; tangential travel is kept
``shear(dx, dy, speed)``    travel tangentially by (dx, dy) at constant depth
``move_to(depth, tx, ty, speed)``  go in a straight line to an absolute state
                            (omitted coordinates are kept)

Speeds are along the segment's straight path in (depth, tx, ty) space, so a
segment lasts its length divided by its speed. Between segment end points the
motion is linear in time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import KW_ONLY, MISSING, dataclass, field, fields
from typing import Any

import numpy as np

from softtip._core.config import Number, checked, number, schema

State = tuple[float, float, float]  # (depth, tx, ty) in m

# Clock samples this close to a segment end point (as a fraction of the sample
# period) are taken to sit on it: float round-off in length/speed must not shave
# the peak depth off a sample that lands on it.
_ON_CLOCK = 1e-6


Length = number("a positive length in m", gt=0)
Speed = number("a positive speed in m/s", gt=0)
Duration = number("a positive duration in s", gt=0)
Depth = number("a non-negative length in m", ge=0)
SampleRate = number("a positive sample rate in Hz", gt=0)


@schema(section="push")
class Push:
    depth: Length  # m, further normal travel
    speed: Speed  # m/s

    def end(self, start: State) -> State:
        return (start[0] + self.depth, start[1], start[2])


@schema(section="hold")
class Hold:
    seconds: Duration

    def end(self, start: State) -> State:
        return start


@schema(section="release")
class Release:
    speed: Speed  # m/s

    def end(self, start: State) -> State:
        return (0.0, start[1], start[2])


@schema(section="shear")
class Shear:
    dx: Number  # m
    dy: Number  # m
    speed: Speed  # m/s

    def end(self, start: State) -> State:
        return (start[0], start[1] + self.dx, start[2] + self.dy)


@schema(section="move_to")
class MoveTo:
    _: KW_ONLY
    speed: Speed  # m/s
    depth: Depth | None = None  # m; None keeps the current value
    tx: Number | None = None
    ty: Number | None = None

    def end(self, start: State) -> State:
        target = (self.depth, self.tx, self.ty)
        return tuple(float(s) if t is None else float(t) for s, t in zip(start, target))


Step = Push | Hold | Release | Shear | MoveTo
STEP_KINDS: dict[str, type] = {"push": Push, "hold": Hold, "release": Release, "shear": Shear, "move_to": MoveTo}
_KIND_OF = {cls: kind for kind, cls in STEP_KINDS.items()}


@dataclass(frozen=True)
class Motion:
    """An indenter's motion from first touch: a chain of steps, each linear in time.

    Build it with the chainable methods (each returns a new Motion) or from a
    list of tables with :meth:`from_dicts`.
    """

    steps: tuple[Step, ...] = ()
    # segment end points, computed once: times (M+1,) s and states (M+1, 3)
    _knot_times: np.ndarray = field(init=False, repr=False, compare=False)
    _knot_states: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        times, states = [0.0], [(0.0, 0.0, 0.0)]
        for index, step in enumerate(self.steps):
            if not isinstance(step, Step):
                raise ValueError(f"steps[{index}] = {step!r}: expected one of {', '.join(c.__name__ for c in _KIND_OF)}")
            start, end = states[-1], step.end(states[-1])
            if isinstance(step, Hold):
                duration = step.seconds
            else:
                length = math.dist(start, end)
                if length == 0:
                    # a move that goes nowhere has no duration: most likely a slip in a config
                    raise ValueError(f"steps[{index}] ({_KIND_OF[type(step)]}): already at {end}; use hold to pause")
                duration = length / step.speed
            times.append(times[-1] + duration)
            states.append(end)
        object.__setattr__(self, "_knot_times", np.array(times))
        object.__setattr__(self, "_knot_states", np.array(states))

    def _then(self, step: Step) -> Motion:
        return Motion(self.steps + (step,))

    def push(self, depth: float, speed: float) -> Motion:
        return self._then(Push(depth, speed))

    def hold(self, seconds: float) -> Motion:
        return self._then(Hold(seconds))

    def release(self, speed: float) -> Motion:
        return self._then(Release(speed))

    def shear(self, dx: float, dy: float, speed: float) -> Motion:
        return self._then(Shear(dx, dy, speed))

    def move_to(self, *, speed: float, depth: float | None = None, tx: float | None = None, ty: float | None = None) -> Motion:
        return self._then(MoveTo(speed=speed, depth=depth, tx=tx, ty=ty))

    @classmethod
    def from_dicts(cls, tables: Sequence[Mapping[str, Any]]) -> Motion:
        """A motion from tables such as ``[{kind = "push", depth = 3e-3, speed = 2.5e-4}, ...]``
        (SI units; the keys are the step's parameters). Unknown kinds and keys are refused."""
        if isinstance(tables, (str, Mapping)) or not isinstance(tables, Sequence):
            raise ValueError(f"motion = {tables!r}: expected a list of step tables")
        steps = []
        for index, table in enumerate(tables):
            where = f"motion[{index}]"
            if not isinstance(table, Mapping):
                raise ValueError(f"{where} = {table!r}: expected a table with a 'kind' key")
            kind = table.get("kind")
            if kind not in STEP_KINDS:
                raise ValueError(f"{where}.kind = {kind!r}: expected one of {', '.join(STEP_KINDS)}")
            step_class = STEP_KINDS[kind]
            parameters = {f.name for f in fields(step_class)}
            arguments = {key: value for key, value in table.items() if key != "kind"}
            for key in arguments:
                if key not in parameters:
                    raise ValueError(f"{where}.{key}: unknown key for {kind}; expected one of {', '.join(sorted(parameters))}")
            missing = [f.name for f in fields(step_class) if f.name not in arguments and f.default is MISSING]
            if missing:
                raise ValueError(f"{where}: {kind} needs {', '.join(missing)}")
            try:
                steps.append(step_class(**arguments))
            except ValueError as error:
                raise ValueError(f"{where}: {error}") from None
        return cls(tuple(steps))

    def to_dicts(self) -> list[dict[str, Any]]:
        """Plain tables that :meth:`from_dicts` turns back into an equal motion."""
        return [
            {"kind": _KIND_OF[type(step)]} | {f.name: getattr(step, f.name) for f in fields(step) if getattr(step, f.name) is not None}
            for step in self.steps
        ]

    @property
    def duration(self) -> float:
        """s, from first touch to the end of the last step."""
        return float(self._knot_times[-1])

    def sample(self, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The motion on the uniform clock t_i = i / rate_hz from 0, plus the end point
        if it falls between ticks: (times (N,) s, depth (N,) m, tangential (N, 2) m).

        Clock samples that fall on a segment end point take its state exactly;
        the others are interpolated linearly along their segment."""
        rate = checked(SampleRate, "rate_hz", rate_hz)
        tolerance = _ON_CLOCK / rate
        ticks = int(math.floor(self.duration * rate + _ON_CLOCK))
        times = np.arange(ticks + 1) / rate
        if self.duration - times[-1] > tolerance:
            times = np.append(times, self.duration)
        states = np.column_stack([np.interp(times, self._knot_times, column) for column in self._knot_states.T])
        nearest = np.searchsorted(times, self._knot_times).clip(max=len(times) - 1)
        for candidate in (nearest - 1, nearest):
            candidate = candidate.clip(min=0)
            on_clock = np.abs(times[candidate] - self._knot_times) <= tolerance
            states[candidate[on_clock]] = self._knot_states[on_clock]
        return times, states[:, 0], states[:, 1:]
