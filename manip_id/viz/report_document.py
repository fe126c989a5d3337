"""How a report folder is drawn: the samples it draws and its options.

The run's JSON document is the result's own
(:meth:`~manip_id.identification.IdentificationResult.to_dict`, its run context made by
:mod:`manip_id.identification.run_context`); this module only says what to draw.
"""

from __future__ import annotations

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
    """

    source: str
    simulated: bool = False
    chunk: int = 1024
    scene_assets: str = "inline"
    force: bool = False
