"""NPZ datasets: the interchange format, read whole or in row chunks, written in chunks.

Layout (what :func:`~manip_id.datasets.save_dataset` writes)::

    t            float (N,)      time stamps [s]
    q            float (N, nq)   positions [rad or m]
    dq           float (N, nv)   velocities [rad/s or m/s]
    tau          float (N, nv)   torques [N m or N]
    ddq          float (N, nv)   accelerations, optional
    temp         float (N, nv)   temperatures [degC or K], optional; (N,) or (N, 1): one
                                 for every joint (the ``temperature`` friction law)
    joint_names  str   (nv,)     optional

Streaming. An NPZ is a zip of ``.npy`` members. :func:`inspect_npz` reads only
each member's ``.npy`` header (shape, dtype, order) and checks the shapes
against each other, the declared sizes against the zip directory (a truncated
or inconsistent member is refused) and, when asked, the total against a memory
budget, all before any data is decompressed. :class:`NpzSource` then reads rows
``start:stop`` of every member side by side, a chunk at a time (compressed
members decompress as a stream), so memory is O(chunk) whatever N.
"""

from __future__ import annotations

import struct
import zipfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from ..errors import DataError
from .core import Dataset, check_shapes
from .csv import derive_velocity, time_rate
from .layout import FIELDS, Layout

REQUIRED = ("q", "tau")  # t: or a rate; dq: or differentiated


@dataclass(frozen=True)
class NpyMember:
    """One ``.npy`` member of an NPZ, from its header alone."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype
    fortran_order: bool
    header_size: int  # bytes before the data
    data_size: int  # bytes of data, prod(shape) * itemsize

    @property
    def row_bytes(self) -> int:
        """Bytes per row (first axis) of a C-order member."""
        width = int(np.prod(self.shape[1:], dtype=np.int64)) if len(self.shape) > 1 else 1
        return width * self.dtype.itemsize


def _member_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path) -> NpyMember:
    name = info.filename[:-4]
    try:
        with zf.open(info) as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version in ((2, 0), (3, 0)):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            header = fh.tell()
    except (
        ValueError, OSError, zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError,
        RuntimeError,
    ) as exc:  # fmt: skip
        raise DataError(f"cannot read {path} as NPZ: member {info.filename}: {exc}") from exc
    dtype = np.dtype(dtype)
    if dtype.hasobject:  # a pickle: never loaded (its size is not the array's either)
        raise DataError(
            f"{path}: member {info.filename} holds Python objects ({dtype}), a pickle that "
            "manip-id never loads: save numeric arrays (np.savez with float arrays)"
        )
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if header + size != info.file_size:
        raise DataError(
            f"{path}: member {info.filename} declares shape {shape} of {dtype} "
            f"({size} bytes) but holds {info.file_size - header} bytes of data: "
            "the file is truncated or corrupt"
        )
    return NpyMember(name, tuple(int(s) for s in shape), dtype, bool(fortran), header, size)


def inspect_npz(path: Path, max_bytes: int | None = None) -> tuple[dict[str, NpyMember], Layout]:
    """Headers of the members of the NPZ dataset ``path``, checked, and its column layout.

    Checks: a zip of ``.npy`` members; t, q, dq, tau present and nothing but
    t, q, dq, tau, ddq, temp, joint_names; real numeric data (complex, object and
    string arrays refused; strings only for joint_names); t of shape (N,), the
    others (N, width) with one row per stamp, dq, tau, ddq of equal width;
    declared sizes equal to the zip's; with ``max_bytes``, the numeric data as
    float64 within that budget. Nothing is decompressed beyond the headers.
    """
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, NotImplementedError, RuntimeError, ValueError) as exc:
        raise DataError(f"cannot read {path} as NPZ: {exc}") from exc
    with zf:
        infos = zf.infolist()
        members = {}
        for info in infos:
            if not info.filename.endswith(".npy"):
                raise DataError(
                    f"{path} holds unexpected member {info.filename!r}; "
                    "expected .npy arrays t, q, dq, tau, ddq, temp, joint_names"
                )
            m = _member_header(zf, info, path)
            members[m.name] = m
    missing = [k for k in REQUIRED if k not in members]
    if missing:
        raise DataError(
            f"{path} lacks array(s) {', '.join(missing)}; an NPZ dataset holds q, tau, t (or "
            "a sampling rate), dq (or it is differentiated) and optionally ddq, temp, "
            "joint_names "
            f"(found {', '.join(sorted(members)) or 'none'})"
        )
    # a closed-loop log's reference arrays (qref, dqref: manip_id.controller) are not read
    unknown = sorted(n for n in set(members) - {*FIELDS, "joint_names"} if not n.endswith("ref"))
    if unknown:
        raise DataError(
            f"{path} holds unexpected array(s) {', '.join(unknown)}; "
            "expected t, q, dq, tau, ddq, temp, joint_names (and reference arrays *ref)"
        )
    for name, m in members.items():
        kind = m.dtype.kind
        if name == "joint_names":
            if kind not in "US" or len(m.shape) > 1:
                raise DataError(
                    f"{path}: joint_names must be a 1-D string array, got {m.dtype} {m.shape}"
                )
            continue
        if kind == "c":
            raise DataError(f"{path}: {name} holds complex numbers ({m.dtype}); expected real")
        if kind not in "fiu":
            raise DataError(f"{path}: {name} must be numeric, got dtype {m.dtype}")
        want = 1 if name == "t" else 2
        if len(m.shape) != want and not (name == "temp" and len(m.shape) == 1):
            raise DataError(
                f"{path}: {name} must have {want} dimension(s), got {name}.shape={m.shape}"
            )
    check_shapes({name: members[name].shape for name in FIELDS if name in members}, f"{path}: ")
    n, nv = members["q"].shape[0], members["tau"].shape[1]
    if "dq" not in members and members["q"].shape[1] != nv:
        raise DataError(
            f"{path}: no dq array, and q ({members['q'].shape[1]} columns) cannot be "
            f"differentiated into {nv} velocities"
        )
    temp = members["temp"].shape if "temp" in members else None
    n_temp = 0 if temp is None else (temp[1] if len(temp) == 2 else 1)
    layout = Layout(nq=members["q"].shape[1], nv=nv, has_ddq="ddq" in members, n_temp=n_temp)
    if "joint_names" in members and members["joint_names"].shape != (nv,):
        raise DataError(
            f"{path}: {members['joint_names'].shape[0] if members['joint_names'].shape else 1} "
            f"joint_names for nv={nv} velocity columns"
        )
    if max_bytes is not None:
        need = n * layout.width * 8
        if need > max_bytes:
            raise DataError(
                f"{path}: {n} samples of {layout.width} columns need {need / 2**20:.0f} MiB "
                f"in memory, more than the budget of {max_bytes / 2**20:.0f} MiB; read it in "
                "chunks (manip_id.datasets.open_source) instead"
            )
    return members, layout


def _read_names(zf: zipfile.ZipFile, member: NpyMember, path: Path) -> tuple[str, ...]:
    with zf.open(member.name + ".npy") as fh:
        try:
            arr = np.lib.format.read_array(fh, allow_pickle=False)
        except ValueError as exc:
            raise DataError(f"{path}: cannot read joint_names: {exc}") from exc
    return tuple(str(s) for s in np.atleast_1d(arr))


def _stored_offsets(zf: zipfile.ZipFile, infos, path: Path) -> dict[str, int]:
    """Byte offset in the file of each stored (uncompressed, unencrypted) member's data.

    Such a member is read with plain file reads, without the zip layer's buffering
    and CRC pass (the scan and the accumulation read every byte once each).
    """
    out: dict[str, int] = {}
    fp = zf.fp
    if fp is None:
        return out
    for info in infos:
        if info.compress_type != zipfile.ZIP_STORED or info.flag_bits & 0x1:
            continue
        fp.seek(info.header_offset)
        local = fp.read(30)
        if len(local) != 30 or local[:4] != b"PK\x03\x04":
            raise DataError(f"cannot read {path} as NPZ: bad local header of {info.filename}")
        name_len, extra_len = struct.unpack("<HH", local[26:30])
        out[info.filename[:-4]] = info.header_offset + 30 + name_len + extra_len
    return out


class NpzSource:
    """Rows of an NPZ dataset read in chunks (see the module docstring).

    Attributes: ``path``, ``format`` ("npz"), ``layout``, ``joint_names``,
    ``n_rows`` (N, from the headers), ``compressed`` (any member deflated).
    """

    format = "npz"

    def __init__(self, path: Path, fortran_budget: int = 256 * 2**20, rate: float | None = None):
        self.path = Path(path)
        self.members, self.layout = inspect_npz(self.path)
        self.n_rows = self.members["q"].shape[0]
        #: the rate [Hz] stamping a file without ``t`` (``t_k = k / rate``), else None
        self.rate = time_rate(self.path, "t" in self.members, rate)
        #: whether dq is differentiated from q (the file has none)
        self.derive_dq = "dq" not in self.members
        self.joint_names = None
        with zipfile.ZipFile(self.path) as zf:  # deflated members cost a decompression per pass
            infos = zf.infolist()
            self.compressed = any(i.compress_type != zipfile.ZIP_STORED for i in infos)
            self._offsets = _stored_offsets(zf, infos, self.path)
        self._whole: dict[str, np.ndarray] = {}
        with zipfile.ZipFile(self.path) as zf:
            if "joint_names" in self.members:
                self.joint_names = _read_names(zf, self.members["joint_names"], self.path)
            for name, m in self.members.items():  # rare: Fortran order cannot be read by rows
                if name != "joint_names" and m.fortran_order and len(m.shape) > 1:
                    if m.data_size > fortran_budget:
                        raise DataError(
                            f"{self.path}: {name} is stored in Fortran order "
                            f"({m.data_size / 2**20:.0f} MiB), which cannot be read by rows "
                            f"within {fortran_budget / 2**20:.0f} MiB; save it in C order"
                        )
                    with zf.open(name + ".npy") as fh:
                        self._whole[name] = np.lib.format.read_array(fh, allow_pickle=False)

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        """Packed float64 rows ``start:stop`` (columns of :class:`Layout`), ``chunk`` at a time.

        Without ``t``: ``t_k = k / rate``; without ``dq``: ``numpy.gradient(q, t)`` across
        blocks, as for a CSV file (read from one row before ``start``)."""
        stop = self.n_rows if stop is None else min(stop, self.n_rows)
        if not self.derive_dq:
            yield from self._chunks(chunk, start, stop)
            return
        chunk = max(int(chunk), 3)
        lo = max(start - 1, 0)  # one row before: the central difference of row ``start``
        hi = min(stop + 1, self.n_rows)
        blocks = derive_velocity(self._chunks(chunk, lo, hi), self.layout, self.path)
        row = lo
        for block in blocks:
            k = block.shape[0]
            a, b = max(start - row, 0), min(stop - row, k)
            row += k
            if b > a:
                yield block[a:b]

    def _chunks(self, chunk: int, start: int, stop: int) -> Iterator[np.ndarray]:
        """The stored rows ``start:stop`` packed (t and dq filled or left NaN)."""
        names = [f for f in FIELDS if f in self.members]
        with zipfile.ZipFile(self.path) as zf:
            handles: dict[str, IO[bytes]] = {}
            try:
                for name in names:
                    if name in self._whole:
                        continue
                    m = self.members[name]
                    if name in self._offsets:  # stored: plain reads at the member's offset
                        plain = open(self.path, "rb")  # noqa: SIM115 (closed in finally)
                        handles[name] = plain
                        plain.seek(self._offsets[name] + m.header_size + start * m.row_bytes)
                        continue
                    fh = zf.open(name + ".npy")
                    handles[name] = fh
                    fh.seek(m.header_size + start * m.row_bytes)
                for s in range(start, stop, chunk):
                    k = min(chunk, stop - s)
                    out = np.full((k, self.layout.width), np.nan)
                    if self.rate is not None:
                        out[:, 0] = np.arange(s, s + k) / self.rate
                    for name in names:
                        cols = self.layout.slices[name]
                        if name in self._whole:
                            block = self._whole[name][s : s + k]
                        else:
                            m = self.members[name]
                            raw = handles[name].read(k * m.row_bytes)
                            if len(raw) != k * m.row_bytes:
                                raise DataError(f"{self.path}: member {name}.npy ends early")
                            block = np.frombuffer(raw, dtype=m.dtype)
                        out[:, cols] = np.asarray(block, dtype=np.float64).reshape(k, -1)
                    yield out
            except (
                zipfile.BadZipFile, OSError, EOFError, zlib.error, NotImplementedError, RuntimeError
            ) as exc:  # fmt: skip
                raise DataError(f"cannot read {self.path} as NPZ: {exc}") from exc
            finally:
                for fh in handles.values():
                    fh.close()


def load_npz(path: Path, max_bytes: int | None = None, rate: float | None = None) -> Dataset:
    """The NPZ dataset ``path`` in memory (headers checked first, see :func:`inspect_npz`);
    ``rate`` [Hz] stamps a file without ``t`` (a file without ``dq`` has it differentiated)."""
    members, layout = inspect_npz(path, max_bytes)
    if "t" not in members or "dq" not in members:
        src = NpzSource(path, rate=rate)
        f = layout.unpack(np.vstack(list(src.chunks(1 << 16))))
        ds = Dataset(
            t=f["t"],
            q=f["q"],
            dq=f["dq"],
            tau=f["tau"],
            ddq=f.get("ddq"),
            temp=f.get("temp"),
            joint_names=src.joint_names,
            meta={"source": str(path)},
        )
        if src.derive_dq:
            ds.meta["dq"] = "central differences of q"
        return ds
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:
        raise DataError(f"cannot read {path} as NPZ: {exc}") from exc
    names = arrays.pop("joint_names", None)
    if names is not None:
        names = tuple(str(n) for n in np.atleast_1d(names))
    try:
        return Dataset(**arrays, joint_names=names, meta={"source": str(path)})
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from exc


def write_npz(fh, blocks, n: int, layout: Layout, joint_names=None) -> None:
    """Write an NPZ dataset to the open binary file ``fh`` from packed row blocks.

    ``blocks`` yields float64 arrays of shape (k, layout.width) totalling ``n``
    rows; each member's ``.npy`` header is written with the known shape, then
    the rows as they come (uncompressed, ZIP64), so memory is O(block).
    Members are written one after the other, so ``blocks`` is a callable
    returning a fresh iterator (called once per field).
    """
    with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name in layout.fields:
            cols = layout.slices[name]
            width = cols.stop - cols.start
            shape = (n,) if name == "t" else (n, width)
            with zf.open(name + ".npy", "w", force_zip64=True) as out:
                np.lib.format.write_array_header_1_0(
                    out, {"descr": "<f8", "fortran_order": False, "shape": shape}
                )
                written = 0
                for block in blocks():
                    part = np.ascontiguousarray(block[:, cols], dtype="<f8")
                    out.write(part.tobytes())
                    written += part.shape[0]
                if written != n:
                    raise DataError(f"write_npz: expected {n} rows, got {written}")
        if joint_names is not None:
            with zf.open("joint_names.npy", "w") as out:
                np.lib.format.write_array(out, np.array(joint_names, dtype=str))
