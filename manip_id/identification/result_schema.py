"""The types of a saved identification result, checked before any field is used.

:func:`check_result_document` walks the keys :func:`~manip_id.identification.result_from_dict`
reads (through :class:`~manip_id._io.fields.Fields`) and refuses a tampered or foreign
document with one :class:`~manip_id.errors.DataError` line naming the field: ``warnings``
a list of strings, ``base_parameters`` a list of objects whose ``name`` is a string and
whose ``value`` / ``std`` are finite numbers or null, ``relative_error`` / ``base`` /
``rank_analysis`` objects, ``n_base`` / ``n_samples`` / ``rank`` integers >= 0, ``robot``
and ``method`` strings, ``joints`` / ``outputs`` lists of strings.

Rows are matched by name, not position (issue 41): :func:`rows_in_base_order` puts the
``base_parameters`` rows in the order of ``base.independent`` (row ``i`` is named after
parameter ``base.names[independent[i]]``, with an ``R`` when regrouped), so a reordered
list reads as the same result and a renamed, missing or repeated row is refused by name.
:func:`check_covariance` refuses a covariance that is not symmetric positive semidefinite
(a negative variance would give a drift test ``chi2 0 on 0, p = nan``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._io.fields import Fields
from ..errors import DataError

_OBJECTS = ("relative_error", "base", "rank_analysis")
_OPTIONAL_OBJECTS = ("relative_error_raw", "noise_variance", "timings", "thresholds")
_COUNTS = ("n_base", "n_samples", "n_parameters", "rank", "n_validation_samples")
_TEXTS = ("method", "robot", "model", "solver")
_ERROR_KEYS = {
    "train",
    "train_per_joint",
    "validation",
    "per_joint_validation",
    "nominal_train",
    "nominal_train_per_joint",
    "nominal_validation",
    "nominal_per_joint_validation",
    "train_moving",
    "validation_moving",
    "validation_per_file",
}
_TEXT_LISTS = ("warnings", "joints", "outputs", "data_warnings")


def _count(f: Fields, value: Any, field: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise f.fail(field, "an integer >= 0", value)


def _check_errors(f: Fields, errors: dict, field: str) -> None:
    """Relative errors: each a number >= 0, null, or a list of them (per joint); a list of
    objects for ``validation_per_file``."""
    for key, value in errors.items():
        if key not in _ERROR_KEYS:
            continue  # not read
        where = f"{field}.{key}"
        if value is None or key == "validation_per_file":
            if value is not None:
                for k, item in enumerate(f.list(value, where)):
                    f.object(item, f"{where}[{k}]")
            continue
        if isinstance(value, list):
            for k, v in enumerate(value):
                if v is not None:
                    f.number(v, f"{where}[{k}]", minimum=0.0)
        else:
            f.number(value, where, minimum=0.0)


def check_result_document(doc: Any, where: str = "the result") -> dict:
    """``doc`` when its fields have the types of a saved result (module docstring)."""
    f = Fields(where)
    doc = f.object(doc, "the document")
    for key in _TEXTS:
        if key in doc and not (key == "solver" and doc[key] is None):
            f.text(doc[key], key)
    for key in _TEXT_LISTS:
        if doc.get(key) is not None:
            f.texts(doc[key], key)
    for key in _OBJECTS:
        if key in doc:
            f.object(doc[key], key)
    for key in _OPTIONAL_OBJECTS:
        if doc.get(key) is not None:
            f.object(doc[key], key)
    for key in _COUNTS:
        if doc.get(key) is not None:
            _count(f, doc[key], key)
    if "base_parameters" in doc:
        for k, row in enumerate(f.list(doc["base_parameters"], "base_parameters")):
            row = f.object(row, f"base_parameters[{k}]")
            f.text(row.get("name"), f"base_parameters[{k}].name")
            for key in ("value", "std", "std_percent", "nominal"):
                if row.get(key) is not None:
                    minimum = 0.0 if key.startswith("std") else None
                    f.number(row[key], f"base_parameters[{k}].{key}", minimum=minimum)
    for key in ("relative_error", "relative_error_raw"):
        if isinstance(doc.get(key), dict):
            _check_errors(f, doc[key], key)
    if doc.get("covariance") is not None:
        for k, row in enumerate(f.list(doc["covariance"], "covariance")):
            for j, v in enumerate(f.list(row, f"covariance[{k}]")):
                if v is not None:
                    f.number(v, f"covariance[{k}][{j}]")
    return doc


def rows_in_base_order(doc: dict, where: str = "the result") -> list[dict]:
    """The ``base_parameters`` rows of ``doc`` in the order of ``base.independent``, by name.

    Raises :class:`~manip_id.errors.DataError` naming the row that does not match.
    """
    f = Fields(where)
    rows = f.list(doc["base_parameters"], "base_parameters")
    b = f.object(doc["base"], "base")
    names = f.texts(b.get("names"), "base.names")
    independent = f.list(b.get("independent"), "base.independent")
    for k, j in enumerate(independent):
        if isinstance(j, bool) or not isinstance(j, int) or not 0 <= j < len(names):
            raise f.fail(f"base.independent[{k}]", f"an index in 0..{len(names) - 1}", j)
    if len(rows) != len(independent):
        raise DataError(
            f"{where}: {len(rows)} base_parameters rows but base.independent lists "
            f"{len(independent)} parameters"
        )
    by_name: dict[str, dict] = {}
    for k, row in enumerate(rows):
        name = f.text(
            f.object(row, f"base_parameters[{k}]").get("name"), f"base_parameters[{k}].name"
        )
        regrouped = name.endswith("R") and name not in names and name[:-1] in names
        root = name[:-1] if regrouped else name
        if root in by_name:
            raise DataError(f"{where}: base parameter {name!r} is listed twice")
        by_name[root] = row
    ordered = []
    for j in independent:
        row = by_name.get(names[j])
        if row is None:
            raise DataError(
                f"{where}: no base_parameters row for {names[j]!r} (base.independent names "
                "it); the rows are matched by name"
            )
        ordered.append(row)
    return ordered


def check_covariance(cov: np.ndarray, field: str, where: str = "the result") -> np.ndarray:
    """``cov`` when it is a symmetric positive semidefinite matrix (NaN rows allowed: not
    determined); else one :class:`~manip_id.errors.DataError` naming ``field``."""
    diag = np.diag(cov)
    known = np.isfinite(diag)
    bad = np.flatnonzero(known & (diag < 0))
    if bad.size:
        k = int(bad[0])
        raise DataError(f"{where}: {field}[{k}][{k}] is a negative variance ({diag[k]:.3g})")
    sub = cov[np.ix_(known, known)]
    if not np.isfinite(sub).all():
        return cov
    scale = max(float(np.max(np.abs(sub), initial=0.0)), np.finfo(float).tiny)
    if not np.allclose(sub, sub.T, rtol=1e-6, atol=1e-9 * scale):
        raise DataError(f"{where}: {field} is not symmetric")
    if sub.size and np.linalg.eigvalsh(0.5 * (sub + sub.T))[0] < -1e-8 * scale:
        raise DataError(f"{where}: {field} is not positive semidefinite (a variance < 0)")
    return cov
