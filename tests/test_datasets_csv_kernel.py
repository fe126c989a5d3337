"""The compiled CSV reader (manip_id.datasets._csv_kernel) against Python's ``float`` (the
correctly rounded reference numpy's reader uses), and CsvSource with it against numpy's."""

from __future__ import annotations

import math
import multiprocessing
from fractions import Fraction

import numpy as np
import pytest

pytest.importorskip("numba")

import manip_id.datasets.csv as csv_module  # noqa: E402
from manip_id.datasets._csv_kernel import parse_lines  # noqa: E402
from manip_id.errors import DataError  # noqa: E402


def _bits(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64).view(np.uint64)


def _check(cells: list[str]) -> int:
    """Each cell parsed alone: equal to ``float`` bit for bit when accepted; the number
    of refused cells."""
    refused = 0
    for s in cells:
        got = parse_lines(s.encode(), 1)
        if got is None:
            refused += 1
            continue
        assert _bits(got[0, 0]) == _bits(float(s)), s
    return refused


def _random_cells(rng, m: int) -> list[str]:
    out = []
    for _ in range(m):
        digits = "".join(map(str, rng.integers(0, 10, rng.integers(1, 20))))
        p = int(rng.integers(0, len(digits) + 1))
        kind = int(rng.integers(0, 4))
        if kind == 0:
            s = digits
        elif kind == 1:
            s = digits[:p] + "." + digits[p:]
        elif kind == 2:
            s = digits + "e" + str(rng.integers(-320, 300))
        else:
            s = "0." + "0" * int(rng.integers(0, 5)) + digits + "E" + str(rng.integers(-30, 30))
        out.append(str(rng.choice(["", "-", "+"])) + s)
    return out


def test_random_decimals_equal_float():
    rng = np.random.default_rng(0)
    cells = _random_cells(rng, 20000)
    refused = [s for s in cells if parse_lines(s.encode(), 1) is None]
    _check(cells)
    for s in refused:  # only values outside the normal doubles, or exact ties
        v = abs(float(s))
        assert v == 0 or v < 2.3e-308 or v > 1.7e308 or "." in s or "e" in s.lower()
    assert len(refused) < 0.03 * len(cells)


def test_the_shortest_and_17_digit_forms_of_random_doubles():
    rng = np.random.default_rng(1)
    x = rng.standard_normal(5000) * 10.0 ** rng.integers(-30, 30, 5000)
    cells = [repr(float(v)) for v in x] + [f"{v:.17g}" for v in x] + [f"{v:.16e}" for v in x]
    assert _check(cells) < 5


def test_near_ties_round_like_float():
    """Decimals at, just below and just above the midpoint of two neighbouring doubles
    (19 significant digits: the kernel either rounds them as float does or refuses)."""
    rng = np.random.default_rng(2)
    cells = []
    for v in rng.uniform(1e-5, 1e5, 3000):
        mid = (Fraction(float(v)) + Fraction(math.nextafter(float(v), math.inf))) / 2
        e = math.floor(math.log10(mid)) - 18
        k = mid / Fraction(10) ** e  # 19 digits before the point
        for n in (math.floor(k), math.ceil(k), round(k)):
            cells.append(f"{n}e{e}")
    assert _check(cells) < 0.05 * len(cells)


@pytest.mark.parametrize(
    "cell",
    [
        "0",
        "-0",
        "-0.0",
        "+5",
        ".5",
        "5.",
        "9007199254740993",
        "2.2250738585072014e-308",
        "1.7976931348623157e308",
        "1e22",
        "1e23",
        "  3.25\t",
        "0.1",
        "123456789012345678",
        "1234567890123456789",
    ],
)
def test_edge_cells(cell):
    got = parse_lines(cell.encode(), 1)
    assert got is not None
    assert _bits(got[0, 0]) == _bits(float(cell))


@pytest.mark.parametrize(
    "text",
    [
        "",
        "nan",
        "inf",
        "1e",
        "--1",
        "1,,2",
        "1;2",
        "# c",
        "1\n\n2",
        "1,2\n3",
        "0x10",
        "1_0",
        "1.2.3",
        "12345678901234567890",
        "1e-400",
        "1e400",
        "1,",
        "1\r2",
    ],
)
def test_cells_refused_to_numpy(text):
    width = None if "," in text else 1
    assert parse_lines(text.encode(), width) is None


def _write(path, text: str):
    path.write_bytes(text.encode())
    return path


def _force(monkeypatch, reader: str) -> None:
    """Files read by ``reader`` ("numpy", "compiled" here, "forked" in a child) where the
    compiled reader applies (whatever their size)."""
    choose = csv_module._reader_of
    monkeypatch.setattr(csv_module, "COMPILED_BYTES", 0)
    monkeypatch.setattr(
        csv_module, "_reader_of", lambda p, d: "numpy" if choose(p, d) == "numpy" else reader
    )


def _chunks(path, monkeypatch, reader: str, columns=None):
    with monkeypatch.context() as m:
        _force(m, reader)
        src = csv_module.CsvSource(path, columns)
        return list(src.chunks(4)), dict(src.malformed)


HEAD = "t,q_a,q_b,dq_a,dq_b,tau_a,tau_b\n"
ROWS = [f"{0.01 * k!r},{0.1 * k},-{k}e-3,0.5,{k},-1.25,{7 * k}" for k in range(11)]


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("plain", HEAD + "\n".join(ROWS) + "\n"),
        ("no final newline", HEAD + "\n".join(ROWS)),
        ("crlf", (HEAD + "\n".join(ROWS) + "\n").replace("\n", "\r\n")),
        ("lone cr", (HEAD + "\n".join(ROWS) + "\n").replace("\n", "\r")),
        ("blank lines", HEAD + "\n".join(ROWS[:3]) + "\n\n  \n" + "\n".join(ROWS[3:]) + "\n"),
        ("nan cell", HEAD + "\n".join(ROWS[:5] + [ROWS[5].replace("0.5", "nan")] + ROWS[6:])),
        ("empty cell", HEAD + "\n".join(ROWS[:5] + [ROWS[5].replace("0.5", "")] + ROWS[6:])),
        ("malformed", HEAD + "\n".join(ROWS[:6] + ["1,2,x,4,5,6,7", "1,2"] + ROWS[6:])),
        ("blanks", HEAD + "\n".join(" " + r.replace(",", " , ") for r in ROWS) + "\n"),
    ],
)
@pytest.mark.parametrize("reader", ["compiled", "forked"])
def test_compiled_source_equals_numpy(tmp_path, monkeypatch, name, text, reader):
    path = _write(tmp_path / "f.csv", text)
    want, want_bad = _chunks(path, monkeypatch, "numpy")
    got, got_bad = _chunks(path, monkeypatch, reader)
    assert got_bad == want_bad
    assert len(got) == len(want) > 1
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(_bits(a), _bits(b))


@pytest.mark.parametrize("reader", ["compiled", "forked"])
def test_compiled_source_without_header_and_derived_dq(tmp_path, monkeypatch, reader):
    body = "\n".join(",".join(r.split(",")[i] for i in (0, 1, 2, 5, 6)) for r in ROWS) + "\n"
    path = _write(tmp_path / "g.csv", body)
    cols = {"t": 0, "q": [1, 2], "tau": [3, 4]}
    want, _ = _chunks(path, monkeypatch, "numpy", columns=cols)
    got, _ = _chunks(path, monkeypatch, reader, columns=cols)
    assert len(got) == len(want) > 1
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(_bits(a), _bits(b))


@pytest.mark.parametrize("reader", ["compiled", "forked"])
def test_a_header_that_does_not_fit_is_refused_alike(tmp_path, monkeypatch, reader):
    path = _write(tmp_path / "h.csv", HEAD.replace("\n", ",x\n") + "\n".join(ROWS) + "\n")
    messages = []
    for r in ("numpy", reader):
        with pytest.raises(DataError) as err:
            _chunks(path, monkeypatch, r)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "the header has 8 columns but rows have 7" in messages[0]


def test_a_forked_read_stopped_early_ends_its_child(tmp_path, monkeypatch):
    """A child a pass stopped early (its pipe full: it waits) is ended with the pass."""
    path = _write(tmp_path / "f.csv", HEAD + "\n".join(ROWS * 2000) + "\n")
    with monkeypatch.context() as m:
        _force(m, "forked")
        blocks = csv_module.CsvSource(path).chunks(4)
        first = next(blocks)
        assert multiprocessing.active_children()
        blocks.close()
    assert not multiprocessing.active_children()
    assert np.array_equal(first, _chunks(path, monkeypatch, "numpy")[0][0])
