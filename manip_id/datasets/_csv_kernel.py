"""numba kernel of :mod:`manip_id.datasets.csv`: lines of comma-separated decimal numbers
to float64, correctly rounded (imported only when numba is installed).

A cell ``[blanks][+-]digits[.digits][(e|E)[+-]digits][blanks]`` (at least one digit
before the exponent) is read as an integer ``w`` of at most 19 significant digits and a
power ``10^q``, and converted to the double nearest to ``w 10^q`` (ties to even), the
value Python's ``float`` and ``numpy.loadtxt`` give:

    w 10^q = w 5^q 2^q,    5^q = t 2^-s,   2^127 <= t < 2^128,

with ``T = floor(t)`` tabulated for ``q`` in [Q_MIN, Q_MAX] (exact for 0 <= q <= 55).
With ``w`` shifted left so that its top bit is set, the 192-bit product ``P = w T`` is
exact and the true ``w t`` lies in ``[P, P + w)``; both ends are rounded to 53 bits and
the value is accepted when they agree (rounding is monotonic, so every value between
them rounds alike), which fails with probability about 2^-74 a cell. Anything else (an
empty cell, ``nan``, more digits, a blank line, another field count, a comment, a value
outside the normal range of doubles, two ends that disagree) makes the whole block fail:
the caller parses it with numpy instead. Compiled code is cached on disk (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

Q_MIN = -342
Q_MAX = 308
_U = np.uint64
_ZERO = _U(0)
_ONE = _U(1)
_TEN = _U(10)
_MASK32 = _U(0xFFFFFFFF)
_S32 = _U(32)
_S63 = _U(63)
_TOP = _U(1 << 63)
_MANT_END = _U(1 << 53)
_POW10 = np.array([10.0**k for k in range(23)])  # exact doubles
#: m 2^e with 2^52 <= m < 2^53 is a normal double for e in [E_MIN, E_MAX]
E_MIN, E_MAX = -1074, 971
_POW2 = np.array([math.ldexp(1.0, e) for e in range(E_MIN, E_MAX + 1)])


def _powers() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(hi, lo, s, exact)`` of ``T(q) = floor(5^q 2^s)`` in [2^127, 2^128), q in
    [Q_MIN, Q_MAX] (exact integers: Python's)."""
    qs = range(Q_MIN, Q_MAX + 1)
    hi, lo = np.empty(len(qs), np.uint64), np.empty(len(qs), np.uint64)
    shift, exact = np.empty(len(qs), np.int64), np.empty(len(qs), np.bool_)
    for i, q in enumerate(qs):
        if q >= 0:
            p = 5**q
            s = 127 - (p.bit_length() - 1)
            t = p << s if s >= 0 else p >> -s
            ex = s >= 0
        else:
            d = 5**-q
            s = 127 + d.bit_length()
            t, ex = (1 << s) // d, False
        assert 1 << 127 <= t < 1 << 128
        hi[i], lo[i] = t >> 64, t & ((1 << 64) - 1)
        shift[i], exact[i] = s, ex
    return hi, lo, shift, exact


HI, LO, SHIFT, EXACT = _powers()


@numba.njit(cache=True, inline="always")
def _mul64(a, b):
    """``(high, low)`` 64-bit halves of the 128-bit product of two uint64."""
    a0, a1 = a & _MASK32, a >> _S32
    b0, b1 = b & _MASK32, b >> _S32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> _S32) + (p01 & _MASK32) + (p10 & _MASK32)
    return p11 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32), (p00 & _MASK32) | (mid << _S32)


@numba.njit(cache=True, inline="always")
def _round(p2, p1, p0):
    """``(m, e)``: the 192-bit ``p2 p1 p0`` (top bit 190 or 191) rounded to 53 bits (ties
    to even) as ``m 2^e``, ``2^52 <= m < 2^53``."""
    if p2 >> _S63:
        cut, e = _U(11), 139
    else:
        cut, e = _U(10), 138
    m = p2 >> cut
    half = (p2 >> (cut - _ONE)) & _ONE
    sticky = (p2 & ((_ONE << (cut - _ONE)) - _ONE)) | p1 | p0
    if half and (sticky or (m & _ONE)):
        m += _ONE
        if m == _MANT_END:
            m >>= _ONE
            e += 1
    return m, e


@numba.njit(cache=True, inline="always")
def _value(w, q, neg):
    """``(the double nearest to (-1)^neg w 10^q, ok)``; not ok: see the module docstring.
    (The tables are global: frozen into the compiled code.)"""
    if w == _ZERO:
        return (-0.0 if neg else 0.0), True
    if w < _MANT_END and -22 <= q <= 22:  # w and 10^|q| exact doubles: one rounding
        v = float(w) * _POW10[q] if q >= 0 else float(w) / _POW10[-q]
        return (-v if neg else v), True
    if q < Q_MIN or q > Q_MAX:
        return 0.0, False
    i = q - Q_MIN
    lz = 0
    while w < _TOP:  # shift w until its top bit is set
        w <<= _ONE
        lz += 1
    a1, p0 = _mul64(w, LO[i])
    b1, b0 = _mul64(w, HI[i])
    p1 = a1 + b0
    p2 = b1 + (_ONE if p1 < a1 else _ZERO)
    m, e = _round(p2, p1, p0)
    if not EXACT[i]:  # the true product is in [P, P + w): its upper end rounds alike?
        u0 = p0 + w
        c = _ONE if u0 < p0 else _ZERO
        u1 = p1 + c
        c = _ONE if (c and u1 == _ZERO) else _ZERO
        u2 = p2 + c
        if u2 < p2:
            return 0.0, False
        m2, e2 = _round(u2, u1, u0)
        if m2 != m or e2 != e:
            return 0.0, False
    exp2 = e + q - SHIFT[i] - lz
    if exp2 < E_MIN or exp2 > E_MAX:  # subnormal or overflowing: numpy decides
        return 0.0, False
    v = float(m) * _POW2[exp2 - E_MIN]  # exact: m < 2^53, the product a normal double
    return (-v if neg else v), True


@numba.njit(cache=True)
def _parse(buf, out):
    """Rows of ``out`` (rows, width) filled from the lines of ``buf``; -1 when a line
    does not hold ``width`` plain numbers (see the module docstring)."""
    n, width = buf.shape[0], out.shape[1]
    pos, row, col = 0, 0, 0
    while pos < n:
        while pos < n and (buf[pos] == 32 or buf[pos] == 9):
            pos += 1
        neg = pos < n and buf[pos] == 45
        if pos < n and (buf[pos] == 45 or buf[pos] == 43):
            pos += 1
        w, q, f0 = _ZERO, 0, pos
        while pos < n and buf[pos] == 48:  # leading zeros
            pos += 1
        s0 = pos
        while pos < n and 48 <= buf[pos] <= 57:
            w = w * _TEN + _U(buf[pos] - 48)
            pos += 1
        digits, seen = pos - s0, pos > f0
        if pos < n and buf[pos] == 46:  # the fraction
            pos += 1
            f0 = pos
            if digits == 0:  # no significant digit yet: the fraction's leading zeros
                while pos < n and buf[pos] == 48:
                    pos += 1
            s0 = pos
            while pos < n and 48 <= buf[pos] <= 57:
                w = w * _TEN + _U(buf[pos] - 48)
                pos += 1
            digits, q, seen = digits + pos - s0, f0 - pos, seen or pos > f0
        if digits > 19:  # w overflowed: numpy decides
            return -1
        if pos < n and (buf[pos] == 101 or buf[pos] == 69):  # the exponent
            pos += 1
            sign = -1 if pos < n and buf[pos] == 45 else 1
            if pos < n and (buf[pos] == 45 or buf[pos] == 43):
                pos += 1
            x, k = 0, 0
            while pos < n and 48 <= buf[pos] <= 57 and k < 6:
                x, k, pos = 10 * x + (buf[pos] - 48), k + 1, pos + 1
            if k == 0 or k == 6:
                return -1
            q += sign * x
        while pos < n and (buf[pos] == 32 or buf[pos] == 9):
            pos += 1
        v, ok = _value(w, q, neg)
        if not seen or not ok or col >= width or row >= out.shape[0]:
            return -1
        out[row, col] = v
        col += 1
        if pos < n and buf[pos] == 44:  # the next cell
            pos += 1
            if pos >= n:
                return -1
            continue
        if pos < n and buf[pos] == 13 and pos + 1 < n and buf[pos + 1] == 10:
            pos += 1
        if pos < n and buf[pos] != 10:
            return -1
        if col != width:
            return -1
        pos, row, col = pos + 1, row + 1, 0
    return row


#: The compiled functions of this module (the compile note asks numba's cache about them).
COMPILED = (_parse,)


def parse_lines(text: bytes, width: int | None) -> np.ndarray | None:
    """The lines ``text`` (comma-separated, ``width`` cells each; None: those of the first
    line) as a float64 table, shape (lines, width); None when the kernel cannot read them
    all (see the module docstring)."""
    if not text:
        return None
    if width is None:
        end = text.find(b"\n")
        width = (text if end < 0 else text[:end]).count(b",") + 1
    lines = text.count(b"\n") + (0 if text.endswith(b"\n") else 1)
    out = np.empty((lines, width))
    rows = _parse(np.frombuffer(text, dtype=np.uint8), out)
    return out if rows == lines else None


__all__ = ["Q_MAX", "Q_MIN", "parse_lines"]
