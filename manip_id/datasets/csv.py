"""CSV datasets: the default header or a column map, read whole or in row chunks.

Default layout (comma-separated, one sample per row)::

    t,q_<joint>...,dq_<joint>...,tau_<joint>...[,ddq_<joint>...][,temp_<joint>...]

Columns are found by prefix (``t`` or ``time``; ``q_``, ``dq_``, ``tau_``,
``ddq_``, ``temp_``: the temperature [degC or K], one column per joint or one for every
joint) in header order, so any column order works; joint names come from
the ``dq_`` columns. Other layouts load with a column map (field -> header
names, a glob such as ``"pos*"``, or 0-based indices). Without dq columns, dq is
the central-difference derivative of q (``numpy.gradient``, second order, also
at the ends); the streamed reader computes it with one row of overlap between
chunks, which gives the same values as on the whole file.
"""

from __future__ import annotations

import fnmatch
import importlib.util
import io
import itertools
import multiprocessing
import signal
import sys
import threading
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._numba import note_compile
from ..errors import DataError, InputError, shorten
from .core import Dataset, check_time
from .layout import FIELDS, Layout


@dataclass(frozen=True)
class CsvColumns:
    """Where each field sits in a CSV file."""

    delimiter: str | None
    header: list[str] | None
    index: dict[str, list[int]]
    joint_names: tuple[str, ...] | None
    derive_dq: bool

    @property
    def layout(self) -> Layout:
        n_temp = len(self.index.get("temp", ()))
        return Layout(len(self.index["q"]), len(self.index["tau"]), "ddq" in self.index, n_temp)


def _head(path: Path) -> tuple[str | None, list[str] | None]:
    try:
        with open(path, encoding="utf-8-sig") as fh:  # a byte-order mark is not a column name
            first = fh.readline()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read {path} as CSV: {exc}") from exc
    delimiter = "," if "," in first else None
    cells = [c.strip() for c in (first.split(delimiter) if delimiter else first.split())]
    try:
        [float(c) for c in cells]
        header = None
    except ValueError:
        header = cells
    return delimiter, header


def _column_index(spec, header: list[str] | None, path: Path, field_name: str) -> int:
    if isinstance(spec, (int, np.integer)):
        return int(spec)
    if header is None:
        raise DataError(
            f"{path} has no header row, so column {spec!r} of {field_name!r} must be "
            "given as a 0-based index"
        )
    try:
        return header.index(str(spec))
    except ValueError:
        raise DataError(
            f"column {shorten(spec)!r} of {field_name!r} is not in {path} "
            f"(columns: {_listed(header)})"
        ) from None


def _columns_for(spec, header, path, field_name) -> list[int]:
    if isinstance(spec, str) and header is not None and any(ch in spec for ch in "*?["):
        idx = [i for i, h in enumerate(header) if fnmatch.fnmatchcase(h, spec)]
        if not idx:
            raise DataError(
                f"pattern {shorten(spec)!r} of {field_name!r} matches no column of {path} "
                f"(columns: {_listed(header)})"
            )
        return idx
    specs = [spec] if isinstance(spec, (str, int, np.integer)) else list(spec)
    return [_column_index(s, header, path, field_name) for s in specs]


def resolve_columns(path: Path, columns: Mapping | None, width: int | None = None) -> CsvColumns:
    """The columns of each field of the CSV file ``path`` (header and column map)."""
    delimiter, header = _head(path)
    columns = dict(columns or {})
    unknown = sorted(set(columns) - {*FIELDS, "joint_names"})
    if unknown:
        raise DataError(
            f"column map has unknown field(s) {', '.join(unknown)}; "
            f"expected some of {', '.join(FIELDS)}, joint_names"
        )
    idx: dict[str, list[int]] = {}
    for name in FIELDS:
        if name in columns:
            idx[name] = _columns_for(columns[name], header, path, name)
        elif header is not None:
            if name == "t":
                found = [i for i, h in enumerate(header) if h.lower() in ("t", "time")]
            else:
                found = [i for i, h in enumerate(header) if h.startswith(name + "_")]
            if found:
                idx[name] = found
    missing = [n for n in ("q", "tau") if n not in idx]  # no t: the source's rate
    if missing:
        layout = (
            "header t,q_<joint>...,dq_<joint>...,tau_<joint>..."
            if header is not None
            else "no header row: give a column map with 0-based indices"
        )
        raise DataError(
            f"{path}: cannot find column(s) for {', '.join(missing)} ({layout})"
            + ("" if header is None else _column_hint(header))
        )
    if "t" in idx and len(idx["t"]) != 1:
        raise DataError(f"{path}: 't' must be one column, got {len(idx['t'])}")
    if width is None:
        width = len(header) if header is not None else None
    if width is not None:
        for name, cols in idx.items():
            bad = [c for c in cols if not -width <= c < width]
            if bad:
                raise DataError(
                    f"column map: {name!r} refers to column {bad[0]} but {path} has {width} columns"
                )
    names = columns.get("joint_names")
    if names is None and header is not None and "dq" in idx and "dq" not in columns:
        names = [header[i][3:] for i in idx["dq"]]
    elif names is None and header is not None and "tau" not in columns:
        names = [header[i][4:] for i in idx["tau"]]
    derive = "dq" not in idx
    if derive and len(idx["q"]) != len(idx["tau"]):
        raise DataError(
            f"{path}: no dq columns, and q ({len(idx['q'])} columns) cannot be "
            f"differentiated into {len(idx['tau'])} velocities"
        )
    for name in ("dq", "ddq"):
        if name in idx and len(idx[name]) != len(idx["tau"]):
            raise DataError(
                f"{path}: {len(idx[name])} {name} columns but {len(idx['tau'])} tau columns"
            )
    if "temp" in idx and "temp" not in columns and len(idx["temp"]) not in (1, len(idx["tau"])):
        del idx["temp"]  # found by the temp_ prefix alone, not a temperature per joint: not ours
    if "temp" in idx and len(idx["temp"]) not in (1, len(idx["tau"])):
        raise DataError(
            f"{path}: {len(idx['temp'])} temp columns but {len(idx['tau'])} tau columns: give "
            "one temperature column per joint or one for every joint"
        )
    return CsvColumns(
        delimiter, header, idx, tuple(str(n) for n in names) if names else None, derive
    )


#: CSV files of at least this many bytes are parsed by the compiled reader
#: (:mod:`._csv_kernel`) when numba is installed: below it, importing numba and loading
#: the compiled code (~0.5 s, ~120 MB) costs more than it saves (~2 us a row of 19
#: numbers). Once numba is imported, every comma-separated file is.
COMPILED_BYTES = 32 << 20
#: Whether a child process may be forked to run the compiled reader (Linux).
CAN_FORK = sys.platform.startswith("linux")


def _reader_of(path: Path, delimiter: str | None) -> str:
    """How the lines of ``path`` are parsed: ``"compiled"`` (here), ``"forked"`` (the
    compiled reader in a forked child while this process takes the rows: numba is not
    imported here, its memory stays out of this process), or ``"numpy"``."""
    loaded = "numba" in sys.modules
    if delimiter != "," or (not loaded and path.stat().st_size < COMPILED_BYTES):
        return "numpy"
    if not loaded and importlib.util.find_spec("numba") is None:
        return "numpy"
    with open(path, "rb") as fh:  # universal newlines: a lone CR also ends a line
        head = fh.read(1 << 16)
    if head.count(b"\r") != head.count(b"\r\n"):
        return "numpy"
    # a fork only from a plain single-threaded process (a pool's daemonic worker may not
    # have children; a fork copies no other thread, whatever locks they hold)
    alone = threading.active_count() == 1 and not multiprocessing.current_process().daemon
    return "forked" if CAN_FORK and alone and not loaded else "compiled"


def _compiled_parser():
    """The compiled reader of comma-separated lines (``bytes, width -> table or None``),
    or None (numba cannot be imported)."""
    try:
        from ._csv_kernel import COMPILED, parse_lines  # imports numba (optional, heavy)
    except ImportError:
        return None
    note_compile(*COMPILED)
    return parse_lines


def _child(conn, source: CsvSource, chunk: int) -> None:
    """In a forked child: ``source``'s tables (compiled reader) sent through ``conn``:
    ``(first line, shape, new malformed lines)`` then the table's bytes; None at the end,
    ``"error"`` when the reading failed (the parent reads again, to raise it)."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # ended by the parent (terminate)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    try:
        known = 0
        for first, table in source._tables(chunk, "compiled"):
            bad = dict(itertools.islice(source.malformed.items(), known, None))
            known = len(source.malformed)
            conn.send((first, table.shape, bad))
            conn.send_bytes(np.ascontiguousarray(table, dtype=np.float64).tobytes())
        conn.send(None)
    except BaseException:
        conn.send("error")
    finally:
        conn.close()


def _decoded(raw: list[bytes]) -> list[str]:
    """Lines read as bytes, as text mode reads them (default encoding, universal newlines)."""
    return list(io.TextIOWrapper(io.BytesIO(b"".join(raw))))


def _parse(
    lines: list[str], delimiter, path: Path, first_line: int, width: int | None
) -> tuple[np.ndarray, dict[int, str]]:
    """The lines as a float table, and the malformed ones: ``{k: message}``.

    A malformed line (a cell that is not a number, a field count other than ``width``,
    e.g. a truncated last line) becomes a row of NaN; empty cells read as NaN. ``width``
    None: the first line's field count.
    """
    try:
        table = np.loadtxt(lines, delimiter=delimiter, ndmin=2, dtype=np.float64)
        if width is None or table.shape[1] == width:
            return table, {}
    except ValueError:
        pass
    rows: list[list[float] | None] = []  # slow path: find the bad lines
    bad: dict[int, str] = {}
    for k, line in enumerate(lines):
        cells = line.strip().split(delimiter) if delimiter else line.split()
        try:
            rows.append([float(c) if c.strip() else np.nan for c in cells])
        except ValueError as exc:
            rows.append(None)
            bad[k] = f"cannot read {path} as a numeric CSV table: line {first_line + k + 1}: {exc}"
    if width is None:
        width = next((len(r) for r in rows if r is not None), 0)
        first = next((k for k, r in enumerate(rows) if r is not None), 0)
    else:
        first = None
    for k, r in enumerate(rows):
        if r is not None and len(r) != width:
            where = f"line {first_line + first + 1} has" if first is not None else "the file has"
            bad[k] = f"{path}: line {first_line + k + 1} has {len(r)} cells but {where} {width}"
    table = np.full((len(rows), width), np.nan)
    for k, r in enumerate(rows):
        if k not in bad and r is not None:
            table[k] = r
    return table, bad


#: The message of a malformed last line without a line end (a log cut short) starts so;
#: the streamed reader drops such a line with a note instead of refusing the file.
TRUNCATED = "truncated last line"


def _mark_truncated(bad: dict[int, str], raw: list, lines: list, line_no: int) -> None:
    """Say so in ``bad`` when the chunk's last line is malformed and has no line end."""
    k = len(lines) - 1
    last = raw[-1] if raw else ""
    ended = last.endswith(b"\n") if isinstance(last, bytes) else str(last).endswith("\n")
    if k in bad and raw and not ended:
        bad[k] = f"{TRUNCATED} {line_no + k + 1} (no line end; {bad[k]})"


class CsvSource:
    """Rows of a CSV dataset read ``chunk`` lines at a time (see the module docstring).

    Attributes: ``path``, ``format`` ("csv"), ``layout``, ``joint_names``,
    ``n_rows`` (None: known after one pass).
    """

    format = "csv"
    n_rows = None

    def __init__(self, path: Path, columns: Mapping | None = None, rate: float | None = None):
        self.path = Path(path)
        self.columns = resolve_columns(self.path, columns)
        #: the sampling rate [Hz] of a file without a time column: ``t_k = k / rate``
        self.rate = time_rate(self.path, "t" in self.columns.index, rate)
        #: whether dq is differentiated from q (the file has none)
        self.derive_dq = self.columns.derive_dq
        self.layout = self.columns.layout
        self.joint_names = self.columns.joint_names
        #: data row (0-based) -> why it could not be read; such rows are NaN
        self.malformed: dict[int, str] = {}

    def _tables(self, chunk: int, reader: str | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """``(first line, table)`` of each ``chunk`` lines; ``reader``: see
        :func:`_reader_of` (None: chosen for the file)."""
        c = self.columns
        reader = _reader_of(self.path, c.delimiter) if reader is None else reader
        if reader == "forked":
            yield from self._forked_tables(chunk)
            return
        fast = _compiled_parser() if reader == "compiled" else None
        skip = 0 if c.header is None else 1
        width = None
        with open(self.path, "rb" if fast is not None else "r") as fh:
            for _ in range(skip):
                fh.readline()
            line_no = skip
            row = 0
            while True:
                raw = list(itertools.islice(fh, chunk))
                table = None if fast is None or not raw else fast(b"".join(raw), width)
                bad: dict[int, str] = {}
                if table is not None:
                    lines = raw
                else:  # numpy's reader (the text of the same lines)
                    lines = [ln for ln in (_decoded(raw) if fast else raw) if ln.strip()]
                    if not lines:
                        return
                    table, bad = _parse(lines, c.delimiter, self.path, line_no, width)
                    _mark_truncated(bad, raw, lines, line_no)
                self.malformed.update({row + k: msg for k, msg in bad.items()})
                row += len(lines)
                line_no += len(lines)
                if width is None:
                    width = table.shape[1]
                    self._check_width(width)
                yield line_no - len(lines), table

    def _forked_tables(self, chunk: int) -> Iterator[tuple[int, np.ndarray]]:
        """The tables parsed by a forked child (:func:`_child`), taken as they come; when
        it fails, this process reads the file again after the tables received (its error
        is raised here)."""
        ctx = multiprocessing.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, args=(send, self, chunk), daemon=True)
        try:
            proc.start()
        except OSError:  # no process to be had: the compiled reader here
            recv.close()
            send.close()
            yield from self._tables(chunk, "compiled")
            return
        send.close()
        n = 0
        try:
            while (msg := recv.recv()) not in (None, "error"):
                first, shape, bad = msg
                table = np.frombuffer(recv.recv_bytes(), dtype=np.float64).reshape(shape)
                self.malformed.update(bad)
                n += 1
                yield first, table
        except EOFError:  # the child died
            msg = "error"
        finally:
            recv.close()
            proc.terminate()
            proc.join()
        if msg == "error":
            yield from itertools.islice(self._tables(chunk, "numpy"), n, None)

    def _check_width(self, width: int) -> None:
        """The first rows' field count against the header and the column map."""
        c = self.columns
        if c.header is not None and width != len(c.header):
            raise DataError(
                f"{self.path}: the header has {len(c.header)} columns but rows have {width}"
            )
        for name, cols in c.index.items():
            outside = [i for i in cols if not -width <= i < width]
            if outside:
                raise DataError(
                    f"column map: {name!r} refers to column {outside[0]} but "
                    f"{self.path} has {width} columns"
                )

    def _pack(self, table: np.ndarray) -> np.ndarray:
        lay, idx = self.layout, self.columns.index
        out = np.empty((table.shape[0], lay.width))
        for name, s in lay.slices.items():
            if name in idx:
                out[:, s] = table[:, idx[name]]
        return out

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        """Packed float64 rows ``start:stop``, about ``chunk`` at a time."""
        chunk = max(int(chunk), 3)
        packed: Iterator[np.ndarray] = (self._pack(tab) for _, tab in self._tables(chunk))
        if self.rate is not None:
            packed = stamped(packed, self.rate)
        if self.columns.derive_dq:
            packed = derive_velocity(packed, self.layout, self.path)
        row = 0
        for block in packed:
            k = block.shape[0]
            lo, hi = max(start - row, 0), k if stop is None else min(stop - row, k)
            row += k
            if hi > lo:
                yield block[lo:hi]
            if stop is not None and row >= stop:
                return


def time_rate(path: Path, has_time: bool, rate: float | None) -> float | None:
    """The rate [Hz] that stamps a file without a time field, None for one with it; a file
    with neither is refused with one line saying so."""
    if has_time:
        return None
    if rate is None:
        raise DataError(
            f"{path} has no time column (t or time): give its sampling rate "
            "(--rate HZ on the command line, FileSpec(rate=HZ))"
        )
    rate = float(rate)
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"the sampling rate must be a positive number [Hz], got {rate}")
    return rate


def stamped(blocks: Iterator[np.ndarray], rate: float) -> Iterator[np.ndarray]:
    """``blocks`` with the time column set to ``t_k = k / rate`` [s] (k: the row from the
    first of the file)."""
    row = 0
    for block in blocks:
        block[:, 0] = np.arange(row, row + block.shape[0]) / rate
        row += block.shape[0]
        yield block


def derive_velocity(
    blocks: Iterator[np.ndarray], layout: Layout, path: Path
) -> Iterator[np.ndarray]:
    """Fill the dq columns with ``numpy.gradient(q, t, edge_order=2)`` across blocks.

    Each block is differentiated with the last row of the previous block and
    the first row of the next one attached: the central differences inside and
    the one-sided ones at the two ends of the file are those of the whole file.
    """
    sq, sdq = layout.slices["q"], layout.slices["dq"]
    prev: np.ndarray | None = None  # last row of the previous block
    offset = 0
    cur = next(blocks, None)
    if cur is None:
        return
    for nxt in itertools.chain(blocks, [None]):
        if nxt is not None and nxt.shape[0] < 3:  # keep >= 3 rows for the end formula
            cur = np.vstack([cur, nxt])
            continue
        parts = (
            ([prev] if prev is not None else []) + [cur] + ([nxt[:1]] if nxt is not None else [])
        )
        ext = np.vstack(parts)
        if ext.shape[0] < 3:
            raise DataError(
                f"{path}: need at least 3 samples to differentiate q, got {ext.shape[0]}"
            )
        try:
            check_time(ext[:, 0], offset - (1 if prev is not None else 0))
        except DataError as exc:
            raise DataError(f"{path}: {exc}") from exc
        g = np.gradient(ext[:, sq], ext[:, 0], axis=0, edge_order=2)
        lo = 1 if prev is not None else 0
        cur = cur.copy()
        cur[:, sdq] = g[lo : lo + cur.shape[0]]
        yield cur
        offset += cur.shape[0]
        prev = cur[-1:]
        if nxt is None:
            return
        cur = nxt


def load_csv(path: Path, columns: Mapping | None = None, rate: float | None = None) -> Dataset:
    """The CSV dataset ``path`` in memory (see the module docstring); ``rate`` [Hz] stamps a
    file without a time column."""
    src = CsvSource(path, columns, rate)
    blocks = list(src.chunks(1 << 16))
    if src.malformed:  # read whole: refused (the streamed reader may drop them)
        raise DataError(src.malformed[min(src.malformed)])
    if not blocks:
        raise DataError(f"{path} holds no data rows")
    rows = np.vstack(blocks)
    f = src.layout.unpack(rows)
    try:
        ds = Dataset(
            t=f["t"],
            q=f["q"],
            dq=f["dq"],
            tau=f["tau"],
            ddq=f.get("ddq"),
            joint_names=src.joint_names,
            meta={"source": str(path)},
            temp=f.get("temp"),
        )
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from exc
    if src.columns.derive_dq:
        ds.meta["dq"] = "central differences of q"
    return ds


def csv_header(layout: Layout, joint_names) -> list[str]:
    """The default header for ``layout`` (q columns named by index when nq != nv)."""
    names = list(joint_names) if joint_names else [f"j{i}" for i in range(layout.nv)]
    qnames = names if layout.nq == layout.nv else [str(i) for i in range(layout.nq)]
    head = ["t", *(f"q_{n}" for n in qnames), *(f"dq_{n}" for n in names)]
    head += [f"tau_{n}" for n in names]
    if layout.has_ddq:
        head += [f"ddq_{n}" for n in names]
    head += [f"temp_{n}" for n in (names if layout.n_temp == layout.nv else ["all"])][
        : layout.n_temp
    ]
    return head


def write_csv(fh, blocks, layout: Layout, joint_names=None) -> None:
    """Write packed row blocks to the open text file ``fh`` with the default header."""
    fh.write(",".join(csv_header(layout, joint_names)) + "\n")
    for block in blocks:
        np.savetxt(fh, block, delimiter=",", fmt="%.17g")


def _listed(header: Sequence[str], n: int = 10) -> str:
    """The first ``n`` column names, each cut to a bounded length (:func:`.shorten`)."""
    more = f", ... ({len(header)} columns)" if len(header) > n else ""
    return ", ".join(shorten(h) for h in header[:n]) + more


def _column_hint(header: Sequence[str]) -> str:
    """What to do about a CSV whose header is not ours: its columns, and how to map them
    (``--column FIELD=COLUMNS`` on the command line, ``columns=`` in the API)."""
    shown = _listed(header)
    first = shorten(header[0]) if header else "stamp"
    return (
        f"; this file's columns are {shown}: map them with --column FIELD=COLUMNS "
        f"(columns={{...}} in the API), e.g. --column t={first} --column q='pos*' "
        "--column dq='vel*' --column tau='eff*'"
    )
