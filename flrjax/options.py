"""Flags as dataclass fields: what a field of :class:`flrjax.config.TrainConfig` or of a
method's options class says about itself (its ``--help`` line, its group, how its text is
parsed, whether it sweeps, which values it takes), so that the command line, the checks and the
sweeps are generated from the classes that hold the values."""

from __future__ import annotations

import argparse
import dataclasses
import decimal
from collections.abc import Callable
from typing import Any


class ConfigError(ValueError):
    """A bad flag or combination of flags; shown as one line, without a traceback."""


@dataclasses.dataclass(frozen=True)
class Sweepable:
    """A flag that may hold a tuple of values, swept inside one vmapped run: a number the step
    only multiplies, compares or selects with, so every value shares the compiled chunk. Its
    metrics.csv column is its name."""

    label: str  # in plots and messages
    # The value an unset (None) field means, where None is allowed: a value, or a function of
    # the run's config where it depends on the run (the env's graph settings).
    default: float | str | Callable[[Any], float | str] | None = None
    # Whether the agents' states carry it (gc_td3.Hparams: the method's init puts each run's
    # value there); else the method's config does, with each run's traced value in the chunk.
    in_state: bool = False
    # A word's traced form inside the chunk (e.g. a bool); None: the value as a number.
    traced: Callable[[Any], Any] | None = None


@dataclasses.dataclass(frozen=True)
class Flag:
    """A field as a command-line flag ``--name-with-dashes``."""

    help: str
    group: str  # its --help section
    type: type = float  # one value's type on the command line: int, float, str or bool
    sweep: Sweepable | None = None  # None: one value per run
    # (test, what a value must be) for every value it takes, sweep values too
    check: tuple[Callable[[Any], bool], str] | None = None
    choices: tuple[str, ...] | None = None
    # Parses the flag's text where the type's own parsing does not (e.g. --sweep's points).
    parse: Callable[[str], Any] | None = None


def at_least(n: int) -> tuple[Callable[[Any], bool], str]:
    """A :attr:`Flag.check`: every value ``>= n``."""
    return (lambda v: v >= n, f">= {n}")


POSITIVE = (lambda v: v > 0, "> 0")


def flag(default: Any, help: str, group: str, **kw: Any) -> Any:
    """A dataclass field that is also a flag (:class:`Flag`'s fields as keywords)."""
    return dataclasses.field(default=default, metadata={"flag": Flag(help, group, **kw)})


def flags_of(cls: type) -> dict[str, Flag]:
    """The flags of a dataclass (its fields made by :func:`flag`), in field order."""
    return {f.name: f.metadata["flag"] for f in dataclasses.fields(cls) if "flag" in f.metadata}


def dashed(name: str) -> str:
    """``--flr-alpha`` for the field ``flr_alpha``."""
    return "--" + name.replace("_", "-")


def values(v: Any) -> tuple:
    """A field's values: its tuple (a sweep), or the one value."""
    return v if isinstance(v, tuple) else (v,)


def int_value(text: str) -> int:
    """An integer flag's value in any notation that names an integer exactly (``1920000``,
    ``1.92e6``, ``1e9``); anything else (``1.5e0``, ``two``) is refused in one line."""
    try:
        value = decimal.Decimal(text.strip())
    except decimal.InvalidOperation:
        value = None
    if value is None or not value.is_finite() or value != value.to_integral_value():
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer")
    return int(value)


def parse_one(typ: type) -> Callable[[str], Any]:
    """One value's parser for a flag of type ``typ``."""
    return {int: int_value, str: str.strip}.get(typ, typ)


def parser(f: Flag) -> Callable[[str], Any]:
    """The flag's text to its value: a sweepable flag's comma list to a tuple (a sweep)."""
    if f.parse is not None:
        return f.parse
    one = parse_one(f.type)
    if f.sweep is None:
        return one

    def many(text: str):
        vals = tuple(one(x) for x in text.split(","))
        return vals if "," in text else vals[0]

    many.__name__ = {int: "integer list", str: "word list"}.get(f.type, "number list")
    return many
