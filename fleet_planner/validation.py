"""One declarative vocabulary for checking what comes in from outside: the scenario, warehouse,
robot-kind and fleet YAML files and the JSON wire records (docs/ARCHITECTURE.md, "Scenario and plan
files" and "Wire records").

A *check* is a function ``check(value, path)`` that returns the value normalised (ints as floats,
lists as tuples) or raises a :class:`ValidationError` whose message starts with the path of the
offending field and shows the value it got, e.g. ``robots[3].radius: must be a finite number > 0
(got -1)`` or ``schedule.links[2].M: must be a finite number (got NaN)``. Paths are built the same
way everywhere: ``parent.key`` for a mapping's field, ``parent[i]`` for a list's item.

A :class:`Vocabulary` builds the checks for one family of inputs. It fixes the error class they
raise (each family has its own, all subclasses of :class:`ValidationError`), how a bad value is
shown (``repr`` for YAML files, JSON spelling for records) and how the shape of a mapping is worded
(unknown keys, missing keys), so that every family keeps the messages its users know.

Pure: imports nothing of ours (it is part of the vocabulary floor); PyYAML only for :func:`read_yaml`.
"""
from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import MISSING, field, fields
from pathlib import Path
from typing import Any, Literal, NoReturn, TypeVar, cast

import yaml

T = TypeVar("T")
E = TypeVar("E", bound="ValidationError")

#: ``check(value, path)``: the value normalised, or a :class:`ValidationError` naming ``path``
Check = Callable[[Any, str], T]

_ROS_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class ValidationError(ValueError):
    """Input that does not fit its declaration; the message starts with the path of the field.

    ``path`` is that field path (``robots[3].radius``) and ``reason`` the rest of the message, when
    the error was raised by a check (:meth:`at`); errors built from a plain message have ``path``
    None and the whole message as ``reason``.
    """

    def __init__(self, message: str, path: str | None = None, reason: str | None = None) -> None:
        super().__init__(message)
        self.path = path
        self.reason = message if reason is None else reason

    @classmethod
    def at(cls: type[E], path: str, reason: str) -> E:
        """The error ``<path>: <reason>`` (just ``<reason>`` at the top, where ``path`` is empty)."""
        return cls(f"{path}: {reason}" if path else reason, path, reason)

    def within(self: E, prefix: str) -> E:
        """The same error with ``<prefix>: `` in front of its message (the file it was found in)."""
        return type(self)(f"{prefix}: {self}", self.path, self.reason)


def printable(text: str, limit: int | None = None) -> str:
    """``text`` safe to log and to encode: every character that is not printable (control
    characters, lone UTF-16 surrogates, ...) written as its Python escape (``\\ud800``), and,
    with ``limit``, cut to at most ``limit`` characters (ending in ``...`` where it was cut)."""
    if not text.isprintable():
        text = "".join(ch if ch.isprintable() else ascii(ch)[1:-1] for ch in text)
    if limit is not None and len(text) > limit:
        text = text[:max(0, limit - 3)] + "..."
    return text


def show_json(value: object) -> str:
    """A value as a JSON sender wrote it (``NaN``, ``true``, ``null``, ``'text'``; containers by
    type name), short enough for an error message and always printable (see :func:`printable`)."""
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, int) and abs(value) >= 10 ** 60:
        return f"an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits"
    if isinstance(value, str):
        return printable(repr(value[:80]), 60)
    text = repr(value) if isinstance(value, (int, float)) else type(value).__name__
    return printable(text, 60)


def check_ranges(instance: Any, ranges: dict[str, tuple[float, float]]) -> None:
    """Every dataclass field of ``instance`` is a number (not a bool) in ``ranges[name]``;
    ValueError naming the first that is not (the parameter blocks: dispatch, obstacles)."""
    for f in fields(instance):
        value = getattr(instance, f.name)
        lo, hi = ranges[f.name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
            raise ValueError(f"{f.name}: must be a number in [{lo:g}, {hi:g}] (got {value!r})")


def robot_id_problem(robot_id: object) -> str | None:
    """Why ``robot_id`` cannot name a robot (it must fit in a ROS topic name), or None if it can."""
    if not isinstance(robot_id, str):
        return f"must be a string (got {show_json(robot_id)})"
    if not _ROS_TOKEN.fullmatch(robot_id):
        return ("must be letters, digits and '_' only, not starting with a digit, so that it can be "
                f"part of a ROS topic name (got {show_json(robot_id)})")
    return None


def join(path: str, key: object) -> str:
    """The path of field ``key`` of the mapping at ``path`` (just the key at the top)."""
    return f"{path}.{key}" if path else str(key)


# -- checks that need no wording -------------------------------------------------------------------
def anything(value: Any, path: str) -> Any:
    """Any value, unchanged (a field whose value is checked elsewhere)."""
    return value


def optional(inner: Check[T]) -> Check[T | None]:
    """``None`` (absent, JSON null, YAML ``~``) or whatever ``inner`` accepts."""
    return lambda value, path: None if value is None else inner(value, path)


def all_of(*checks: Check[Any]) -> Check[Any]:
    """The checks one after the other, each on what the one before returned."""
    def check(value: Any, path: str) -> Any:
        for c in checks:
            value = c(value, path)
        return value
    return check


# -- checked dataclasses ---------------------------------------------------------------------------
def spec(check: Check[Any], default: Any = MISSING) -> Any:
    """Declare a dataclass field with its check, and its default if it is optional."""
    return field(default=default, metadata={"check": check})


def check_fields(instance: Any, prefix: str = "") -> None:
    """Check every field of a dataclass instance declared with :func:`spec`, in declaration order,
    and keep the normalised values (frozen dataclasses too). Paths are ``<prefix>.<field>``."""
    for f in fields(instance):
        check = f.metadata.get("check")
        if check is not None:
            object.__setattr__(instance, f.name, check(getattr(instance, f.name), join(prefix, f.name)))


# -- the vocabulary --------------------------------------------------------------------------------
class Vocabulary:
    """The checks of one family of inputs: they raise ``error`` and word their messages its way.

    * ``show`` - how a bad value appears in ``(got ...)``;
    * ``mappings``, ``lists`` - the types accepted as a mapping and as a list;
    * ``root`` - the name of the top level in a message about it (``scenario: must be a mapping``);
    * ``not_mapping`` - the reason for a value that is no mapping (``{type}``: its type name,
      ``{got}``: the value shown);
    * ``unknown`` - the reason for unknown keys (``{key}``: the first, ``{keys}``: all of them,
      ``{known}``: the known keys); given at the key's path (``unknown_in="key"``) or at the
      mapping's (``"mapping"``), the first key in the input's order or, with ``unknown_sorted``,
      in sorted order;
    * ``missing`` - the reason for a missing required key (``{key}``, ``{required}``: all the
      required keys), at the key's path or at the mapping's (``missing_in``).
    """

    def __init__(self, error: type[ValidationError] = ValidationError, *, show: Callable[[Any], str] = repr,
                 mappings: tuple[type, ...] = (dict,), lists: tuple[type, ...] = (list,), root: str = "",
                 not_mapping: str = "must be a mapping (got {type})",
                 unknown: str = "unknown key (allowed: {known})", unknown_in: Literal["key", "mapping"] = "key",
                 unknown_sorted: bool = False,
                 missing: str = "missing", missing_in: Literal["key", "mapping"] = "key") -> None:
        self.error = error
        self.show = show
        self.mappings = mappings
        self.lists = lists
        self.root = root
        self.not_mapping = not_mapping
        self.unknown = unknown
        self.unknown_in = unknown_in
        self.unknown_sorted = unknown_sorted
        self.missing = missing
        self.missing_in = missing_in
        self._finite = self.number()
        self._nonempty = self.string(min_len=1, strip=True)

    def fail(self, path: str, reason: str) -> NoReturn:
        """Raise ``<path>: <reason>`` as this vocabulary's error."""
        raise self.error.at(path, reason)

    def worded(self, check: Check[T], reason: str) -> Check[T]:
        """``check`` with one message for every way it fails, ``reason`` at the path it was given
        (``{got}`` in it: the value shown, ``{type}``: its type name)."""
        def reworded(value: Any, path: str) -> T:
            try:
                return check(value, path)
            except ValidationError:
                pass
            self.fail(path, reason.format(got=self.show(value), type=type(value).__name__))
        return reworded

    # -- scalars -----------------------------------------------------------------------------------
    def number(self, lo: float = -math.inf, hi: float = math.inf, *, above: float | None = None,
               infinite: bool = False) -> Check[float]:
        """A number in ``[lo, hi]`` (and ``> above`` if given), returned as a float. Ints are
        numbers, bools are not; NaN never is, infinities only with ``infinite``."""
        if above is not None:
            bounds = f"> {above:g}"
        elif hi == math.inf:
            bounds = f">= {lo:g}"
        else:
            bounds = f"in [{lo:g}, {hi:g}]"

        def check(value: Any, path: str) -> float:
            if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 2 ** 1023:
                self.fail(path, f"must be a finite number (got {show_json(value)})")  # float() overflows
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not (math.isfinite(value) or (infinite and not math.isnan(value)))):
                self.fail(path, f"must be a finite number (got {self.show(value)})")
            if not lo <= value <= hi or (above is not None and not value > above):
                self.fail(path, f"must be {bounds} (got {self.show(value)})")
            return float(value)
        return check

    def integer(self, lo: int | None = None, hi: int | None = None) -> Check[int]:
        """An int (not a bool), ``>= lo`` and ``<= hi`` if given."""
        def check(value: Any, path: str) -> int:
            if isinstance(value, bool) or not isinstance(value, int):
                self.fail(path, f"must be an integer (got {self.show(value)})")
            if lo is not None and value < lo:
                self.fail(path, f"must be >= {lo} (got {show_json(value)})")
            if hi is not None and value > hi:
                self.fail(path, f"must be <= {hi} (got {show_json(value)})")
            return value
        return check

    def string(self, *, min_len: int = 0, max_len: int | None = None, strip: bool = False,
               pattern: re.Pattern[str] | None = None, printable_only: bool = False) -> Check[str]:
        """A string of ``min_len`` to ``max_len`` characters (not counting the blanks around it if
        ``strip``: ``string(min_len=1, strip=True)`` refuses ``"  "``), matching ``pattern`` whole;
        with ``printable_only``, without control characters or lone surrogates (text that any log
        can take)."""
        what = ("a string" if min_len == 0 else "a non-empty string" if min_len == 1
                else f"a string of at least {min_len} characters")

        def check(value: Any, path: str) -> str:
            if not isinstance(value, str) or len(value.strip() if strip else value) < min_len:
                self.fail(path, f"must be {what} (got {self.show(value)})")
            if max_len is not None and len(value) > max_len:
                self.fail(path, f"must be at most {max_len} characters long (got {self.show(value)})")
            if pattern is not None and not pattern.fullmatch(value):
                self.fail(path, f"must match {pattern.pattern!r} (got {self.show(value)})")
            if printable_only and not value.isprintable():
                self.fail(path, f"must be printable text, no control characters (got {show_json(value)})")
            return value
        return check

    def ros_id(self, value: Any, path: str) -> str:
        """A robot id: a string that can be part of a ROS topic name (see :func:`robot_id_problem`)."""
        problem = robot_id_problem(value)
        if problem:
            self.fail(path, problem)
        return value

    def choice(self, options: Sequence[str]) -> Check[str]:
        """One of the strings ``options``."""
        def check(value: Any, path: str) -> str:
            if not isinstance(value, str) or value not in options:
                self.fail(path, f"must be one of {', '.join(options)} (got {self.show(value)})")
            return value
        return check

    def boolean(self, value: Any, path: str) -> bool:
        """``true`` or ``false`` (not 0 or 1)."""
        if not isinstance(value, bool):
            self.fail(path, f"must be true or false (got {self.show(value)})")
        return value

    def point(self, value: Any, path: str) -> tuple[float, float]:
        """A list ``[x, y]`` of two finite numbers, as a tuple of floats."""
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            self.fail(path, f"must be a list [x, y] (got {self.show(value)})")
        return self._finite(value[0], f"{path}[0]"), self._finite(value[1], f"{path}[1]")

    # -- containers --------------------------------------------------------------------------------
    def list_of(self, item: Check[T], *, unique: bool = False, min_len: int = 0, max_len: int | None = None,
                types: tuple[type, ...] | None = None) -> Check[tuple[T, ...]]:
        """A list (of the vocabulary's list types, or ``types``) of ``min_len`` to ``max_len`` items,
        each checked by ``item`` at ``<path>[i]``; with ``unique``, no item twice. Returns a tuple."""
        kinds = types or self.lists
        what = "a non-empty list" if min_len == 1 else f"a list of at least {min_len} items"

        def check(value: Any, path: str) -> tuple[T, ...]:
            if not isinstance(value, kinds):
                self.fail(path, f"must be a list (got {self.show(value)})")
            items = cast(Sequence[Any], value)
            if len(items) < min_len:
                self.fail(path, f"must be {what} (got {self.show(value)})")
            if max_len is not None and len(items) > max_len:
                self.fail(path, f"must have at most {max_len} items (got {len(items)})")
            out = tuple(item(v, f"{path}[{i}]") for i, v in enumerate(items))
            if unique and len(set(out)) != len(out):
                dup = next(v for i, v in enumerate(out) if v in out[:i])
                self.fail(path, f"{dup!r} appears more than once")
            return out
        return check

    def dict_of(self, item: Check[T], *, key: Check[str] | None = None,
                max_len: int | None = None) -> Check[dict[str, T]]:
        """A mapping with non-empty string keys (each checked by ``key`` if given) and at most
        ``max_len`` entries, each value checked by ``item`` at ``<path>['key']``."""
        key_check = key or self._nonempty

        def check(value: Any, path: str) -> dict[str, T]:
            out = {}
            data = self.as_mapping(value, path)
            if max_len is not None and len(data) > max_len:
                self.fail(path, f"must have at most {max_len} entries (got {len(data)})")
            for k, v in data.items():
                key_check(k, f"{path} key")
                out[k] = item(v, f"{path}[{show_json(k)}]")
            return out
        return check

    def as_mapping(self, value: Any, path: str, not_mapping: str | None = None) -> Mapping[Any, Any]:
        """``value`` if it is a mapping, else the vocabulary's (or this ``not_mapping``) error."""
        if not isinstance(value, self.mappings):
            reason = (not_mapping or self.not_mapping).format(type=type(value).__name__, got=self.show(value))
            self.fail(path or self.root, reason)
        return cast(Mapping[Any, Any], value)

    def keys(self, value: Any, path: str, known: Sequence[str], required: Sequence[str] = (), *,
             not_mapping: str | None = None) -> Mapping[Any, Any]:
        """``value`` if it is a mapping with no key outside ``known`` and every key of ``required``
        (reported in that order); the values are left to the caller."""
        data = self.as_mapping(value, path, not_mapping)
        unknown = [k for k in data if k not in known]
        if unknown:
            if self.unknown_sorted:
                unknown = sorted(unknown)
            first = printable(str(unknown[0]), 60)  # a key is input too: shown safe and short
            where = path if self.unknown_in == "mapping" else join(path, first)
            every = printable(", ".join(map(str, unknown)), 200) if "{keys}" in self.unknown else ""
            self.fail(where, self.unknown.format(key=first, keys=every, known=", ".join(known)))
        for name in required:
            if name not in data:
                where = path if self.missing_in == "mapping" else join(path, name)
                self.fail(where, self.missing.format(key=name, required=", ".join(required)))
        return data

    def mapping(self, fields: Mapping[str, Check[Any]], *, defaults: Mapping[str, Any] | None = None,
                known: Sequence[str] | None = None, not_mapping: str | None = None) -> Check[dict[str, Any]]:
        """A mapping with the keys of ``fields``, each value checked by its check (in the order of
        ``fields``) at ``<path>.<key>``; a key with a default may be absent (its default is checked
        in its place). ``known`` orders the keys in the messages (default: as ``fields``)."""
        defaults = dict(defaults or {})
        names = list(known or fields)
        required = [n for n in names if n not in defaults]

        def check(value: Any, path: str) -> dict[str, Any]:
            data = self.keys(value, path, names, required, not_mapping=not_mapping)
            return {k: c(data[k] if k in data else defaults[k], join(path, k)) for k, c in fields.items()}
        return check


# -- files -----------------------------------------------------------------------------------------
class _DuplicateKey(Exception):
    pass


class _UniqueKeyLoader(yaml.SafeLoader):
    """A safe YAML loader that refuses duplicate keys instead of keeping the last one."""


def _no_duplicates(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise _DuplicateKey(f"line {key_node.start_mark.line + 1}: duplicate key {key!r}")
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _no_duplicates)


def read_yaml(path: Path, error: type[ValidationError], *, what: str, invalid: str | None = "not valid YAML",
              unique_keys: bool = False) -> Any:
    """The content of the YAML file ``path`` (whatever it is: the caller checks its shape).

    A file that cannot be read raises ``error("<path>: cannot read <what> (<why>)")``, one that is
    not YAML ``"<path>: <invalid> (<why>)"`` (the cannot-read message if ``invalid`` is None). With
    ``unique_keys`` a key given twice in one mapping is ``"<path>: line <n>: duplicate key <key>"``
    (plain YAML keeps the last one).
    """
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read {what} ({exc})") from exc
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader if unique_keys else yaml.SafeLoader)
    except _DuplicateKey as exc:
        raise error(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise error(f"{path}: {invalid or f'cannot read {what}'} ({exc})") from exc


@contextmanager
def in_file(path: object, error: type[ValidationError]) -> Iterator[None]:
    """Re-raise the ``error`` raised inside with the file in front: ``<path>: <message>``."""
    try:
        yield
    except error as exc:
        raise exc.within(str(path)) from None


__all__ = ["Check", "ValidationError", "Vocabulary", "all_of", "anything", "check_fields", "check_ranges", "in_file",
           "join", "optional", "printable", "read_yaml", "robot_id_problem", "show_json", "spec"]
