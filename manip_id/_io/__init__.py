"""File output shared by the package: checked before the work, published together at the end.

The modules, used by every command and by the API writers:

- :mod:`.files`: checks before the work (:func:`check_output_file`,
  :func:`check_output_dir`), staged files and atomic writers (:class:`StagedFile`,
  :func:`atomic_write`, :func:`write_json`), and the registry of temporaries that an
  interrupted command removes (:func:`register_temporary`, :func:`remove_temporaries`).
- :mod:`.report_folder`: report folders claimed atomically before the work, built in a
  temporary sibling and swapped into place, replaced only when manip_id wrote them
  (:func:`claim_report`, :class:`ReportFolder`, :func:`check_report_target`).
- :mod:`.reading`: the one door for every file read (regular files only, a size budget
  per kind, decoding errors as one line; :func:`~.reading.read_json`,
  :func:`~.reading.read_toml`, :func:`~.reading.check_readable`), and :mod:`.fields`,
  the typed fields of the JSON and TOML inputs.
- :mod:`.outputs`: the outputs of one command, checked at once and published together
  (:class:`OutputSet`).
"""

from .files import (
    StagedFile,
    atomic_write,
    atomic_write_text,
    check_output_dir,
    check_output_file,
    json_text,
    jsonable,
    register_temporary,
    remove_temporaries,
    unregister_temporary,
    write_json,
)
from .outputs import OutputSet, Pending
from .report_folder import (
    CLAIM,
    MANIFEST,
    ReportFolder,
    check_report_target,
    check_report_target_claimed,
    claim_report,
)

__all__ = [
    "CLAIM",
    "MANIFEST",
    "OutputSet",
    "Pending",
    "ReportFolder",
    "StagedFile",
    "atomic_write",
    "atomic_write_text",
    "check_output_dir",
    "check_output_file",
    "check_report_target",
    "check_report_target_claimed",
    "claim_report",
    "json_text",
    "jsonable",
    "register_temporary",
    "remove_temporaries",
    "unregister_temporary",
    "write_json",
]
