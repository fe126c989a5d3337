"""How a report folder is drawn: the samples it draws and its options.

The run's JSON document is the result's own
(:meth:`~manip_id.identification.IdentificationResult.to_dict`, its run context made by
:mod:`manip_id.identification.run_context`); this module only says what to draw.
"""

from __future__ import annotations

import posixpath
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ReportSamples:
    """The samples a report draws: ``t``, ``q``, ``dq``, ``ddq``, ``tau`` of each part.

    Attributes
    ----------
    train : object
        The (preprocessed) training samples.
    valid : object or None
        The (preprocessed) validation samples.
    full : object or None
        The whole record before the split (animated in the scene; a simulation's
        trajectory is drawn against the limits).
    """

    train: Any
    valid: Any = None
    full: Any = None


@dataclass(frozen=True)
class ReportOptions:
    """How a report is drawn.

    Attributes
    ----------
    source : str
        The data in words (file names, ``simulated``, ``3 files``).
    simulated : bool
        A simulation: its trajectory is drawn against the position limits.
    chunk : int
        Samples per regressor chunk of the predictions.
    scene_assets : str
        ``inline`` (scene.html stands alone) or ``external``.
    force : bool
        Replace a report folder manip_id wrote.
    rollout : RolloutReport or None
        The rollout validation (``identify --rollout``) whose traces are drawn
        (:class:`~manip_id.identification.rollout.RolloutReport`).
    """

    source: str
    simulated: bool = False
    chunk: int = 1024
    scene_assets: str = "inline"
    force: bool = False
    rollout: Any = None


def data_in_words(paths) -> str:
    """The data of a run in a few words, for titles: one file's path, else how many files,
    their folder when they share one and the first and last names
    (``"12 files in logs/ (run_0.npz ... run_11.npz)"``); the JSON keeps every path."""
    paths = [str(p) for p in paths]
    if len(paths) == 1:
        return paths[0]
    folders = {posixpath.dirname(p) for p in paths}
    names = [posixpath.basename(p) for p in paths]
    where = f" in {folders.pop() or '.'}/" if len(folders) == 1 else ""
    listed = ", ".join(names) if len(names) <= 3 else f"{names[0]} ... {names[-1]}"
    return f"{len(paths)} files{where} ({listed})"
