"""Checks of the ``hrlp`` command's options while click parses them, before a command runs (and before torch is
imported): bounded counts and seeds, finite numbers in their intervals, directories to write into and run directories
to read. Each failure is a :class:`BoundError` whose message names the option, the bound and, for an upper bound, why
(:mod:`hrlp.bounds`); ``hrlp``'s top-level handler prints it as one line."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer

from hrlp import bounds

Check = Callable[[typer.CallbackParam, Any], Any]


class BoundError(typer.BadParameter):
    """An option's value outside what hrlp accepts; the message names the option."""


def _flag(param: typer.CallbackParam) -> str:
    if param.param_type_name == "argument":
        return str(param.metavar or param.name).upper()
    return max(param.opts, key=len) if param.opts else f"--{str(param.name).replace('_', '-')}"


def count(
    low: int | None = 1,
    high: int | Callable[[], int] | None = None,
    why: str | Callable[[], str] = "",
    unit: str = "integer",
) -> Check:
    """An integer option (or None) in ``[low, high]`` (None: unbounded, e.g. when the config's own check of the lower
    bound says it better); ``high`` and ``why`` may be computed when the option is parsed; ``unit`` names what a
    positive value counts (``must be a positive UNIT``)."""

    def check(param: typer.CallbackParam, value: Any) -> Any:
        for v in value if isinstance(value, list | tuple) else [value]:
            if v is None:
                continue
            hi = high() if callable(high) else high
            if (problem := bounds.count_problem(v, low, hi, why() if callable(why) else why, unit)) is not None:
                raise BoundError(f"{_flag(param)} {problem}")
        return value

    return check


def seed() -> Check:
    """A seed: an integer in ``[0, 2**32 - 1]``."""
    return count(0, bounds.MAX_SEED, "seeds are 32-bit")


def workers(low: int = 1) -> Check:
    """A number of worker processes: at least ``low`` (0 where it means one per core), at most
    :func:`hrlp.bounds.max_processes`."""
    return count(low, bounds.max_processes, bounds.why_processes)


def real(low: float | None = None, high: float | None = None, low_open: bool = False, high_open: bool = False) -> Check:
    """A finite number option (or None; each item of a repeated option) in the interval."""

    def check(param: typer.CallbackParam, value: Any) -> Any:
        for v in value if isinstance(value, list | tuple) else [value]:
            if v is not None and (problem := bounds.real_problem(v, low, high, low_open, high_open)) is not None:
                raise BoundError(f"{_flag(param)} {problem}")
        return value

    return check


def choice(names: tuple[str, ...]) -> Check:
    """An option whose value is one of ``names``."""

    def check(param: typer.CallbackParam, value: Any) -> Any:
        if value is not None and value not in names:
            raise BoundError(f"{_flag(param)} must be one of {', '.join(names)}, got {value!r}")
        return value

    return check


def widths(param: typer.CallbackParam, value: Any) -> Any:
    """Layer widths written ``64,64`` (a string, as the option is given) -> ``(64, 64)``: positive integers."""
    if not isinstance(value, str):
        return value
    try:
        out = tuple(int(w) for w in value.split(","))
    except ValueError:
        out = ()
    if not out or any(w < 1 for w in out):
        raise BoundError(f"{_flag(param)} must be positive layer widths separated by commas, e.g. 64,64, got {value!r}")
    return out


def config_field(config: type, name: str, first: Check | None = None) -> Check:
    """The option that sets field ``name`` of the dataclass ``config`` (one whose fields are checked each on its own,
    as :class:`~hrlp.config.TRPOConfig`'s are): ``first`` (e.g. :func:`real`'s bounds, in their words), then the
    dataclass's own check, ``config(name=value)``, so that no value the config refuses gets past the parser."""

    def check(param: typer.CallbackParam, value: Any) -> Any:
        if first is not None:
            value = first(param, value)
        try:
            config(**{name: value})
        except (ValueError, TypeError) as e:
            message = str(e)
            if message.startswith(f"{name} "):  # "max_kl must be ..." -> "--max-kl must be ..."
                raise BoundError(f"{_flag(param)}{message[len(name) :]}") from None
            raise BoundError(f"{_flag(param)}: {message}") from None
        return value

    return check


def out_dir(param: typer.CallbackParam, value: Path | None) -> Path | None:
    """A directory hrlp writes into (created if missing): neither it nor any directory above it may be a file."""
    if value is None:
        return value
    for p in (value, *value.parents):
        if p.exists() or p.is_symlink():
            if not p.is_dir():
                what = "is" if p == value else f"lies under {p}, which is"
                raise BoundError(f"{_flag(param)} {value} {what} a file, not a directory")
            break
    return value


def library(param: typer.CallbackParam, value: Path | None) -> Path | None:
    """A skill library: a directory, or a path where one may be made (nothing above it a file); a file is refused."""
    if value is not None and (value.exists() or value.is_symlink()) and not value.is_dir():
        raise BoundError(f"{_flag(param)} {value} is a file, not a skill library (a directory)")
    return out_dir(param, value)


def run_dir(param: typer.CallbackParam, value: Path | None) -> Path | None:
    """An existing run directory to read."""
    if value is None:
        return value
    if not value.exists():
        raise BoundError(f"{_flag(param)} {value}: no such run directory (no checkpoint to read)")
    if not value.is_dir():
        raise BoundError(f"{_flag(param)} {value} is a file, not a run directory")
    return value


def existing_dir(param: typer.CallbackParam, value: Path | None) -> Path | None:
    """An existing directory to read (e.g. a skill library)."""
    if value is None:
        return value
    if not value.is_dir():
        raise BoundError(f"{_flag(param)} {value}: {'not a directory' if value.exists() else 'no such directory'}")
    return value


def skill_ref(param: typer.CallbackParam, value: str | None) -> str | None:
    """A skill to start from: a skill directory (holding ``meta.json``) or a plain skill name, looked up in the libraries
    when the run is built (a path that is no skill directory is refused here)."""
    if value is None:
        return value
    path = Path(value)
    if (path / "meta.json").is_file():
        return value
    if "/" in value or value in ("", ".", ".."):  # a plain name is looked up as a name, whatever lies in the cwd
        raise BoundError(f"{_flag(param)} {value}: neither a skill directory (with meta.json) nor a skill name")
    return value
