"""Parameter schemas: every tunable value of every stage, declared once.

A stage declares its parameters in a :class:`Schema` (name, default, range,
step, unit, help). The GUI builds its sliders from the schema, config files
set values through it, and nodes take live updates through it; every update
is validated, and a bad one is refused with one sentence naming the
parameter and what it accepts.

Config files are YAML, one mapping per stage::

    recording:
      color_format: png
    detection:
      voxel_size: 0.06
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

from optrack.errors import UserError
from optrack.io.files import atomic_write_text

__all__ = [
    "REGISTRY",
    "Param",
    "ParamError",
    "Params",
    "Schema",
    "load_config",
    "register",
    "save_config",
]

Value = bool | int | float | str


class ParamError(UserError):
    """A parameter update or config file that cannot be accepted."""


def _format_number(value: float) -> str:
    return f"{value:g}"


@dataclasses.dataclass(frozen=True)
class Param:
    """One tunable value. Its type is the type of ``default``."""

    name: str
    default: Value
    min: float | None = None
    max: float | None = None
    step: float | None = None
    unit: str = ""
    help: str = ""
    choices: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"parameter name '{self.name}' must be an identifier.")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"parameter {self.name}: min {self.min} is above max {self.max}.")
        if self.choices and not isinstance(self.default, str):
            raise ValueError(f"parameter {self.name}: choices need a string default.")
        # The default itself must pass the checks.
        self.check(self.default, stage="(default)")

    @property
    def kind(self) -> type:
        return type(self.default)

    def describe_range(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.kind is bool:
            return "true or false"
        if self.min is not None and self.max is not None:
            return f"between {_format_number(self.min)} and {_format_number(self.max)}{unit}"
        if self.min is not None:
            return f"at least {_format_number(self.min)}{unit}"
        if self.max is not None:
            return f"at most {_format_number(self.max)}{unit}"
        return {int: "a whole number", float: "a number", str: "a text"}[self.kind] + unit

    def check(self, value: Any, stage: str) -> Value:
        """The value, converted to this parameter's type, or a :class:`ParamError`."""
        where = f"{stage}.{self.name}"
        wanted = self.describe_range()
        kind = self.kind
        if kind is bool:
            if not isinstance(value, bool):
                raise ParamError(f"{where} must be true or false; got {value!r}.")
            return value
        if kind in (int, float):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ParamError(f"{where} must be {wanted}; got {value!r}.")
            if kind is int:
                if isinstance(value, float) and not value.is_integer():
                    raise ParamError(f"{where} must be a whole number ({wanted}); got {value!r}.")
                value = int(value)
            else:
                value = float(value)
                if not math.isfinite(value):
                    raise ParamError(f"{where} must be {wanted}; got {value!r}.")
            if (self.min is not None and value < self.min) or (
                self.max is not None and value > self.max
            ):
                raise ParamError(f"{where} must be {wanted}; got {value!r}.")
            return value
        if not isinstance(value, str):
            raise ParamError(f"{where} must be {wanted}; got {value!r}.")
        if self.choices and value not in self.choices:
            raise ParamError(f"{where} must be {wanted}; got {value!r}.")
        return value


class Schema:
    """The parameters of one stage, in declaration order."""

    def __init__(self, stage: str, params: Iterable[Param], help: str = "") -> None:
        self.stage = stage
        self.help = help
        self._params: dict[str, Param] = {}
        for param in params:
            if param.name in self._params:
                raise ValueError(f"stage {stage} declares parameter '{param.name}' twice.")
            self._params[param.name] = param

    def __iter__(self) -> Iterator[Param]:
        return iter(self._params.values())

    def __len__(self) -> int:
        return len(self._params)

    def __contains__(self, name: object) -> bool:
        return name in self._params

    def __getitem__(self, name: str) -> Param:
        try:
            return self._params[name]
        except KeyError:
            raise ParamError(self._unknown(name)) from None

    def _unknown(self, name: str) -> str:
        close = difflib.get_close_matches(name, self._params, n=1)
        hint = f" Did you mean '{close[0]}'?" if close else ""
        known = ", ".join(self._params) or "none"
        return f"{self.stage} has no parameter '{name}' (it has: {known}).{hint}"

    def defaults(self) -> dict[str, Value]:
        return {p.name: p.default for p in self}

    def validate(self, updates: Mapping[str, Any]) -> dict[str, Value]:
        """Check every update; return them converted, or raise on the first bad one."""
        if not isinstance(updates, Mapping):
            raise ParamError(
                f"parameters for {self.stage} must be a mapping of name to value; "
                f"got {type(updates).__name__}."
            )
        checked: dict[str, Value] = {}
        for name, value in updates.items():
            checked[name] = self[str(name)].check(value, self.stage)
        return checked

    def create(self, values: Mapping[str, Any] | None = None) -> Params:
        return Params(self, values)


class Params:
    """Current values of one stage's parameters (attribute access)."""

    __slots__ = ("_schema", "_values")

    def __init__(self, schema: Schema, values: Mapping[str, Any] | None = None) -> None:
        object.__setattr__(self, "_schema", schema)
        object.__setattr__(self, "_values", schema.defaults())
        if values:
            self.update(values)

    @property
    def schema(self) -> Schema:
        return self._schema

    def __getattr__(self, name: str) -> Value:
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(self._schema._unknown(name)) from None

    def __setattr__(self, name: str, value: Any) -> None:
        self.update({name: value})

    def __getitem__(self, name: str) -> Value:
        return self._values[self._schema[name].name]

    def update(self, values: Mapping[str, Any]) -> dict[str, Value]:
        """Apply updates all-or-nothing; return what changed."""
        checked = self._schema.validate(values)
        changed = {k: v for k, v in checked.items() if self._values[k] != v}
        self._values.update(checked)
        return changed

    def as_dict(self) -> dict[str, Value]:
        return dict(self._values)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Params)
            and other._schema is self._schema
            and other._values == self._values
        )

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self._values.items())
        return f"Params[{self._schema.stage}]({inner})"


REGISTRY: dict[str, Schema] = {}


def register(schema: Schema) -> Schema:
    """Make a stage's schema known to config files and the GUI."""
    existing = REGISTRY.get(schema.stage)
    if existing is not None and existing is not schema:
        raise ValueError(f"a schema for stage '{schema.stage}' is already registered.")
    REGISTRY[schema.stage] = schema
    return schema


def _schemas(registry: Mapping[str, Schema] | None) -> Mapping[str, Schema]:
    return REGISTRY if registry is None else registry


def load_config(
    path: str | os.PathLike[str], registry: Mapping[str, Schema] | None = None
) -> dict[str, Params]:
    """Read a YAML config file: one Params per registered stage (defaults where absent)."""
    schemas = _schemas(registry)
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ParamError(
            f"config file {path} does not exist; check the path or create it with 'optrack' defaults."
        ) from None
    except OSError as error:
        raise ParamError(f"config file {path} cannot be read ({error.strerror}).") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ParamError(
            f"config file {path} is not valid YAML{where}; fix it or delete it to use defaults."
        ) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ParamError(f"config file {path} must be a mapping of stage names to parameters.")
    result = {stage: schema.create() for stage, schema in schemas.items()}
    for stage, values in data.items():
        if stage not in schemas:
            close = difflib.get_close_matches(str(stage), schemas, n=1)
            hint = f" Did you mean '{close[0]}'?" if close else ""
            raise ParamError(
                f"config file {path} names an unknown stage '{stage}' "
                f"(known: {', '.join(schemas) or 'none'}).{hint}"
            )
        try:
            result[stage].update(values or {})
        except ParamError as error:
            raise ParamError(f"config file {path}: {error}") from None
    return result


def save_config(
    path: str | os.PathLike[str],
    params: Mapping[str, Params | Mapping[str, Any]],
    registry: Mapping[str, Schema] | None = None,
) -> None:
    """Write a YAML config atomically (a crash never leaves a half-written file)."""
    schemas = _schemas(registry)
    data: dict[str, dict[str, Value]] = {}
    for stage, values in params.items():
        if isinstance(values, Params):
            data[stage] = values.as_dict()
        else:
            if stage not in schemas:
                raise ParamError(f"cannot save parameters of unknown stage '{stage}'.")
            data[stage] = schemas[stage].validate(values)
    atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))
