"""Config files and settings: one TOML reader, and declarative schemas that refuse mistakes in one line.

A schema is a frozen dataclass whose field types say what each key may hold::

    @schema
    class SearchSettings:
        budget: integer(minimum=1) = 25
        ei_tolerance: NonNegativeNumber = 1e-3

    parse(SearchSettings, table, "study.toml", "search")
    # study.toml: search.budget = 0: expected an integer >= 1

Every error is one line naming the file (or the object), the dotted key and what was expected; a key
the schema does not declare is refused with the list of those it does. Checks between keys go in
``__post_init__`` and raise :class:`Refusal` naming the key at fault. Constructing a schema directly
validates the same way, located by the ``section`` given to :func:`schema`
(``MLX90393Settings(gain_sel=9)``: ``sensor.gain_sel = 9: expected an integer 0..7``).
The arguments of a class that is not a schema are checked with the same types, one at a time:
``checked(PositiveNumber, "rate_hz", rate_hz)`` (``rate_hz = 0: expected a positive number``).

The validation is pydantic's (v2), on its dataclasses: they stay ordinary frozen dataclasses
(``dataclasses.replace``, ``asdict``, positional arguments), its strict mode refuses ``true`` for a
number and ``1.5`` for an integer, nested tables are located key by key, and ``Annotated``
constraints keep a schema as short as the documentation of its table. Only the wording is softtip's.
"""

from __future__ import annotations

import functools
import re
import tomllib
import types
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import numpy as np

from softtip._core.files import not_a_file
from pydantic import BeforeValidator, ConfigDict, Field, InstanceOf, Strict, TypeAdapter, ValidationError, WrapValidator
from pydantic.dataclasses import dataclass as pydantic_dataclass
from pydantic_core import ArgsKwargs, PydanticCustomError


class ConfigError(ValueError):
    """A config file or setting that cannot describe what it should."""


# ---------------------------------------------------------------------------------------------- files


def read_toml(path: str | Path, what: str, error: type[ConfigError] = ConfigError) -> dict:
    """The table in the TOML file ``path``, a ``what`` file ("design", "study" ...); a missing or
    unreadable file, bytes that are not UTF-8 and text that is not TOML raise ``error`` naming the file."""
    path = Path(path)
    problem = not_a_file(path)
    if problem:
        raise error(f"{what} file {path} {problem}")
    try:
        return tomllib.loads(path.read_bytes().decode("utf-8"))
    except OSError as problem:
        raise error(f"{what} file {path}: cannot be read ({problem.strerror})") from None
    except UnicodeDecodeError as problem:
        raise error(f"{what} file {path}: not UTF-8 text ({problem.reason} at byte {problem.start})") from None
    except tomllib.TOMLDecodeError as problem:
        raise error(f"{what} file {path}: not valid TOML ({problem})") from None


# ---------------------------------------------------------------------------------------------- messages

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_ABSENT = object()  # a key that was not given: its refusal shows no value


def where(source: str, *path: str | int) -> str:
    """``source: a.b[0]."c.d"`` - a place in a config, as TOML would spell its key."""
    dotted = ""
    for part in path:
        if isinstance(part, int):
            dotted += f"[{part}]"
        else:
            key = part if _BARE_KEY.fullmatch(part) else f'"{part}"'
            dotted = f"{dotted}.{key}" if dotted else key
    return f"{source}: {dotted}" if source and dotted else source or dotted


def refused(message: str, source: str, *path: str | int, value: Any = _ABSENT,
            error: type[ConfigError] = ConfigError) -> ConfigError:
    """The one-line error ``source: key = value: message`` (without ``= value`` if none is given)."""
    place = where(source, *path)
    return error(f"{place}: {message}" if value is _ABSENT or not path else f"{place} = {value!r}: {message}")


class Refusal(ValueError):
    """A check between keys refusing one of them.

    Raised in a schema's ``__post_init__`` it is located like a type error; raised on a table that was
    already parsed, :meth:`locate` places it. ``key`` is a key of the table, a path of keys and list
    indices into its nested tables (``("sensor", "positions_mm", 0)``), or None for the whole table.
    """

    def __init__(self, key: str | int | tuple | None, message: str):
        super().__init__(message)
        self.path: tuple = () if key is None else (key,) if isinstance(key, (str, int)) else tuple(key)

    def locate(self, table: Any, source: str, *path: str | int,
               error: type[ConfigError] = ConfigError) -> ConfigError:
        """The error for ``table``, found at ``path`` of ``source``."""
        return refused(str(self), source, *path, *self.path, value=_value_at(table, self.path), error=error)


def _value_at(table: Any, path: tuple) -> Any:
    for part in path:
        try:
            table = table[part]
        except (KeyError, IndexError, TypeError):
            return _ABSENT
    return table


# ---------------------------------------------------------------------------------------------- value types


def _plain(value: Any) -> Any:
    return value.tolist() if isinstance(value, (np.generic, np.ndarray)) else value


# ``Annotated`` metadata: numpy scalars and arrays as the Python values they hold (settings are often built from numpy)
from_numpy = BeforeValidator(_plain)


def expect(text: str) -> WrapValidator:
    """``Annotated`` metadata: a failure of the value is reported as ``expected <text>``, unless an
    inner ``expect`` said what was expected first (``a number`` before ``a positive number``)."""

    def check(value: Any, handler: Any) -> Any:
        try:
            return handler(value)
        except ValidationError as problem:
            inner = problem.errors(include_url=False)[0]
            said = inner["ctx"]["expected"] if inner["type"] == "expected" and not inner["loc"] else text
            raise PydanticCustomError("expected", "expected {expected}", {"expected": said}) from None

    return WrapValidator(check)


# building blocks, without a message of their own
Real = Annotated[float, from_numpy, Strict(), Field(allow_inf_nan=False)]
Whole = Annotated[int, from_numpy, Strict()]


def number(expected: str = "a number", *, gt: float | None = None, ge: float | None = None,
           lt: float | None = None, le: float | None = None) -> Any:
    """A finite number (an integer is one too; true/false is not) within the given bounds."""
    return Annotated[Real, expect("a number"), Field(gt=gt, ge=ge, lt=lt, le=le), expect(expected)]


def integer(minimum: int = 0, maximum: int | None = None, expected: str | None = None) -> Any:
    """An integer from ``minimum`` (to ``maximum``); not a float, not true/false."""
    if expected is None:
        expected = f"an integer >= {minimum}" if maximum is None else f"an integer {minimum}..{maximum}"
    return Annotated[Whole, expect("an integer"), Field(ge=minimum, le=maximum), expect(expected)]


def choice(*options: Any, expected: str | None = None) -> Any:
    """One of ``options``, of the same type (12.0 and true are not the option 12)."""
    kinds = {type(option) for option in options}

    def same_kind(value: Any) -> Any:
        value = _plain(value)
        if type(value) not in kinds:
            raise ValueError("not an option")
        return value

    return Annotated[Literal[options], BeforeValidator(same_kind),
                     expect(expected or f"one of {', '.join(map(str, options))}")]


def instance(kind: type, expected: str | None = None) -> Any:
    """An instance of the class ``kind`` as it is (a table is not turned into one)."""
    return Annotated[InstanceOf[kind], expect(expected or kind.__name__)]


Number = number()
PositiveNumber = number("a positive number", gt=0)
NonNegativeNumber = number("a number >= 0", ge=0)
Fraction = number("a number from 0 to 1", ge=0, le=1)
OpenFraction = number("a number strictly between 0 and 1", gt=0, lt=1)
PositiveInteger = integer(1, expected="a positive integer")
Flag = Annotated[bool, from_numpy, Strict(), expect("true or false")]
Text = Annotated[str, Strict(), Field(min_length=1), expect("a non-empty string")]
Numbers = Annotated[list[Real], from_numpy, Field(min_length=1), expect("a non-empty list of numbers")]


# ---------------------------------------------------------------------------------------------- arguments


@functools.lru_cache(maxsize=256)  # kinds are module constants: each is built once
def _validator(kind: Any) -> TypeAdapter:
    return TypeAdapter(kind)


def checked(kind: Any, name: str, value: Any, error: type[ValueError] = ConfigError) -> Any:
    """``value`` validated as the type ``kind`` (``PositiveNumber``, ``integer(1)`` ...): an argument of a
    class that is not a schema. A mistake raises ``error`` in one line, ``name = value: expected ...``."""
    try:
        return _validator(kind).validate_python(value)
    except ValidationError as problem:
        raise error(f"{name} = {value!r}: {problem.errors(include_url=False)[0]['msg']}") from None


# ---------------------------------------------------------------------------------------------- schemas

_SCHEMA_CONFIG = ConfigDict(extra="forbid", arbitrary_types_allowed=True)


def schema(cls: type | None = None, /, *, section: str = "", error: type[ConfigError] = ConfigError) -> Any:
    """Decorator: ``cls`` as a frozen dataclass validated by its field types (see the module notes).

    Constructing it raises ``error`` located at ``section`` (``sensor.gain_sel = 9: ...``); a table
    read from a file is validated with :func:`parse`, which locates it there.
    """

    def make(cls: type) -> type:
        made = pydantic_dataclass(cls, frozen=True, config=_SCHEMA_CONFIG)
        validate = made.__init__

        @functools.wraps(validate)
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            try:
                validate(self, *args, **kwargs)
            except ValidationError as problem:
                raise error(_one_line(problem, made, "", (section,) if section else ())) from None

        made.__init__ = __init__
        return made

    return make if cls is None else make(cls)


def parse(kind: type, table: Any, source: str, *path: str | int, error: type[ConfigError] = ConfigError) -> Any:
    """``table`` validated as the schema ``kind``; ``source`` (a file) and ``path`` (the table's keys in
    it) locate every error."""
    try:
        return kind.__pydantic_validator__.validate_python(table)
    except ValidationError as problem:
        raise error(_one_line(problem, kind, source, path)) from None


_MISSING = {"missing", "missing_argument", "missing_keyword_only_argument", "missing_positional_only_argument"}
_UNKNOWN = {"extra_forbidden", "unexpected_keyword_argument"}
_NOT_A_TABLE = {"dataclass_type", "dataclass_exact_type", "dict_type", "model_type"}


def _one_line(problem: ValidationError, kind: type, source: str, path: tuple) -> str:
    """pydantic's first error in softtip's words."""
    first = problem.errors(include_url=False)[0]
    loc, code, given = first["loc"], first["type"], first["input"]
    if loc and isinstance(loc[0], int) and _fields(kind):  # a positional constructor argument: its field
        loc = (list(_fields(kind))[loc[0]], *loc[1:])
    place = (*path, *loc)
    if code in _MISSING:
        return f"{where(source, *place)} is missing"
    if code in _UNKNOWN:
        expected = ", ".join(sorted(_fields(_member_type(kind, loc[:-1]))))
        return f"{where(source, *place)}: unknown key (expected one of {expected})"
    if code in _NOT_A_TABLE:
        return str(refused("expected a table", source, *place, value=given))
    cause = (first.get("ctx") or {}).get("error")
    if isinstance(cause, Refusal):
        table = _as_table(given, _member_type(kind, loc))
        return str(cause.locate(table, source, *place))
    if code == "value_error":  # a check that refuses the table as a whole
        return str(refused(str(cause), source, *place))
    return str(refused(first["msg"], source, *place, value=given))


def _fields(kind: Any) -> dict:
    return getattr(kind, "__pydantic_fields__", {})


def _member_type(kind: Any, loc: tuple) -> Any:
    """The type found at ``loc`` (field names, dict keys, list indices) inside the type ``kind``."""
    for part in loc:
        kind = _member(kind, part)
    return kind


def _member(kind: Any, part: str | int) -> Any:
    fields = _fields(kind)
    if fields:
        return fields[part].annotation if part in fields else Any
    origin, args = get_origin(kind), get_args(kind)
    if origin is Annotated:
        return _member(args[0], part)
    if origin in (Union, types.UnionType):
        return next((found for arm in args if (found := _member(arm, part)) is not Any), Any)
    if origin is dict:
        return args[1]
    if origin in (list, tuple):
        return args[0]
    return Any


def _as_table(given: Any, kind: Any) -> Any:
    """A schema's input as a table: constructor arguments by field name."""
    if isinstance(given, ArgsKwargs):
        return dict(zip(_fields(kind), given.args or ())) | dict(given.kwargs or {})
    return given
