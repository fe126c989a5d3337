"""The types of a saved identification result, checked before any field is used.

:func:`check_result_document` walks the keys :func:`~manip_id.identification.result_from_dict`
reads (through :class:`~manip_id._io.fields.Fields`) and refuses a tampered or foreign
document with one :class:`~manip_id.errors.DataError` line naming the field: ``warnings``
a list of strings, ``base_parameters`` a list of objects whose ``name`` is a string and
whose ``value`` / ``std`` are finite numbers or null, ``relative_error`` / ``base`` /
``rank_analysis`` objects, ``n_base`` / ``n_samples`` / ``rank`` integers >= 0, ``robot``
and ``method`` strings, ``joints`` / ``outputs`` lists of strings.
"""

from __future__ import annotations

from typing import Any

from .._io.fields import Fields

_OBJECTS = ("relative_error", "base", "rank_analysis")
_OPTIONAL_OBJECTS = ("relative_error_raw", "noise_variance", "timings", "thresholds")
_COUNTS = ("n_base", "n_samples", "n_parameters", "rank", "n_validation_samples")
_TEXTS = ("method", "robot", "model", "solver")
_TEXT_LISTS = ("warnings", "joints", "outputs", "data_warnings")


def _count(f: Fields, value: Any, field: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise f.fail(field, "an integer >= 0", value)


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
                    f.number(row[key], f"base_parameters[{k}].{key}")
    if doc.get("covariance") is not None:
        for k, row in enumerate(f.list(doc["covariance"], "covariance")):
            for j, v in enumerate(f.list(row, f"covariance[{k}]")):
                if v is not None:
                    f.number(v, f"covariance[{k}][{j}]")
    return doc
