"""``manip-id show`` once it runs: a saved result printed again, the one rendering of
:func:`manip_id.identification.result_text` (the options are declared in :mod:`.show`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from ..identification import load_result, result_text


def run(args: argparse.Namespace) -> int:
    path = Path(args.result)
    if path.is_dir():
        path = path / "result.json"
    if args.rows is not None and args.rows < 1:
        raise InputError(f"--rows must be >= 1, got {args.rows}")
    doc = load_result(path).to_dict()  # read through the result type: the one schema
    print(result_text(doc, max_rows=args.rows))
    return 0
