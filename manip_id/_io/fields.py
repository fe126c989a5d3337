"""Typed fields of a parsed JSON or TOML input: one small reader used by every file reader.

A document read by :func:`~manip_id._io.reading.read_json` is plain Python (dict, list,
str, int, float, bool, None) of any shape. Each reader of the package takes the values
it uses through these functions, which check the type, shape, finiteness and range and
raise one :class:`~manip_id.errors.DataError` line naming the file, the field and what
came instead (a JSON ``true`` is no number, ``"abc"`` is no gain, ``{}`` is no matrix).
"""

from __future__ import annotations

import builtins
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from ..errors import DataError, ManipIdError


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class Fields:
    """Typed access to the fields of one document; ``where`` (the file) starts each message.

    Parameters
    ----------
    where : str or os.PathLike
        The file, or what the document is, as the messages name it.
    error : type
        The exception class raised (:class:`~manip_id.errors.DataError` for data files;
        a reader of options, such as a robot profile, gives
        :class:`~manip_id.errors.InputError`).
    """

    def __init__(self, where: object, error: type[ManipIdError] = DataError):
        self.where = str(where)
        self.error = error

    def fail(self, field: str, expected: str, got: Any) -> ManipIdError:
        """The error of a field that is not what it must be."""
        return self.error(f"{self.where}: {field} must be {expected}, got {_shown(got)}")

    def object(self, value: Any, field: str) -> dict:
        """A JSON object (dict)."""
        if not isinstance(value, dict):
            raise self.fail(field, "an object", value)
        return value

    def list(self, value: Any, field: str, *, nonempty: bool = False) -> list:
        """A JSON array (list), non-empty when asked."""
        if not isinstance(value, list) or (nonempty and not value):
            raise self.fail(field, "a non-empty list" if nonempty else "a list", value)
        return value

    def text(self, value: Any, field: str) -> str:
        """A string."""
        if not isinstance(value, str):
            raise self.fail(field, "a string", value)
        return value

    def texts(self, value: Any, field: str) -> builtins.list[str]:
        """A list of strings."""
        items = self.list(value, field)
        for k, item in enumerate(items):
            self.text(item, f"{field}[{k}]")
        return list(items)

    def number(
        self,
        value: Any,
        field: str,
        *,
        minimum: float | None = None,
        positive: bool = False,
        maximum: float | None = None,
    ) -> float:
        """A finite real number (not a bool, not a string), within the range given."""
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if not ok or not math.isfinite(value):
            raise self.fail(field, "a finite number", value)
        x = float(value)
        if positive and not x > 0:
            raise self.fail(field, "a positive number", value)
        if minimum is not None and x < minimum:
            raise self.fail(field, f"a number >= {minimum:g}", value)
        if maximum is not None and x > maximum:
            raise self.fail(field, f"a number <= {maximum:g}", value)
        return x

    def optional_number(self, value: Any, field: str, **limits) -> float | None:
        """None, or a number as :meth:`number` takes it."""
        return None if value is None else self.number(value, field, **limits)

    def boolean(self, value: Any, field: str) -> bool:
        """A JSON ``true`` or ``false``."""
        if not isinstance(value, bool):
            raise self.fail(field, "true or false", value)
        return value

    def matrix(self, value: Any, field: str, shape: tuple[int, int]) -> np.ndarray:
        """A list of ``shape[0]`` lists of ``shape[1]`` finite numbers, as a float array."""
        rows = self.list(value, field)
        if len(rows) != shape[0]:
            raise self.fail(field, f"a {shape[0]} x {shape[1]} matrix", f"{len(rows)} rows")
        out = np.empty(shape)
        for i, row in enumerate(rows):
            row = self.list(row, f"{field}[{i}]")
            if len(row) != shape[1]:
                raise self.fail(f"{field}[{i}]", f"a row of {shape[1]} numbers", row)
            out[i] = [self.number(v, f"{field}[{i}][{j}]") for j, v in enumerate(row)]
        return out

    def known_names(self, names: Iterable[str], known: Iterable[str], what: str) -> None:
        """Refuse names (joints, parameters) that ``known`` does not hold, by name."""
        allowed = set(known)
        unknown = [n for n in names if n not in allowed]
        if unknown:
            raise self.error(
                f"{self.where}: unknown {what} {', '.join(map(repr, unknown[:4]))} "
                f"(expected of {', '.join(sorted(allowed)[:8]) or 'none'})"
            )
