"""Lazy public names (PEP 562): the one mechanism behind every package's exports.

A package declares ``{public name: (submodule, attribute)}`` and gets a ``__getattr__``
that imports the submodule on first access, so ``import manip_id`` loads nothing heavy;
``attribute`` None exports the submodule itself. Used by :mod:`manip_id`,
:mod:`manip_id.estimators` and :mod:`manip_id.viz`.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any


class LazyExports:
    """The public names of package ``package``, each imported from its submodule on first use.

    Parameters
    ----------
    package : str
        the package's ``__name__`` (relative submodule names are resolved against it).
    where : Mapping[str, tuple[str, str | None]]
        public name -> (submodule, attribute); attribute None for the submodule itself.
    """

    def __init__(self, package: str, where: Mapping[str, tuple[str, str | None]]):
        self.package = package
        self.where = dict(where)
        self.names = sorted(self.where)

    def load(self, name: str, namespace: dict[str, Any]) -> Any:
        """The object exported as ``name``, cached in the package's ``namespace``."""
        try:
            module, attr = self.where[name]
        except KeyError:
            raise AttributeError(f"module {self.package!r} has no attribute {name!r}") from None
        value = importlib.import_module(module, self.package)
        if attr is not None:
            value = getattr(value, attr)
        namespace[name] = value  # later look-ups skip the package's __getattr__
        return value

    def listing(self, namespace: dict[str, Any]) -> list[str]:
        """``dir(package)``: what is loaded and what can be."""
        return sorted(set(namespace) | set(self.names))


def by_module(table: Mapping[str, tuple[str, ...]]) -> dict[str, tuple[str, str | None]]:
    """``{submodule: (name, ...)}`` -> ``{name: (submodule, name)}``."""
    return {name: (module, name) for module, names in table.items() for name in names}
