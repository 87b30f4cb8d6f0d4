"""JSON text of numpy arrays, written fast and exactly (the run log's encoder).

The recorder writes its messages as JSON text assembled from already-encoded parts. Integer,
boolean and low-cardinality arrays (every grid field, times, most rewards) are written by
numpy with no per-value Python work: each value is looked up as a fixed-width token, padded
with spaces (valid JSON). Other arrays (physics floats, continuous commands) go through
``orjson`` straight from numpy (``OPT_SERIALIZE_NUMPY``): its float text is the shortest
that reads back as the same float64, so every value reads back bit for bit, with any JSON
reader, as with ``json.dumps`` (Python's ``repr``) before it, about 50 times faster.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import orjson


def json_number(x: float) -> str:
    """A JSON number (exact: Python's shortest round-trip repr), ``null`` if not finite."""
    x = float(x)
    return repr(x) if math.isfinite(x) else "null"


def _dumps(x: np.ndarray) -> bytes:
    """JSON text of a finite numeric array by ``orjson`` (floats widened to float64 first,
    so that a float32 value is written as the float64 it equals, as ``tolist`` would)."""
    if x.dtype.kind == "f" and x.dtype != np.float64:
        x = x.astype(np.float64)
    return orjson.dumps(np.ascontiguousarray(x), option=orjson.OPT_SERIALIZE_NUMPY)


def _chars(x: np.ndarray) -> np.ndarray | None:
    """Each value of ``x`` ``(T, K)`` as a right-aligned fixed-width JSON token ``(T, K, w)``
    of ASCII codes, built in numpy; ``None`` if that is not possible (physics floats)."""
    if x.dtype.kind == "f" and np.all(np.abs(x) < 2**53) and np.all(x == np.floor(x)):
        x = x.astype(np.int64)  # integral floats (times, most rewards) print as integers
    if x.dtype.kind in "iu":
        lo, hi = int(x.min()), int(x.max())
        if lo >= 0 and hi <= 9:  # one digit: the common case on the grid
            return (x.astype(np.uint8) + 48)[..., None]
        if lo >= 0 and hi > 1024:
            width = len(str(hi))
            powers = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
            digits = x.astype(np.int64)[..., None] // powers
            chars = (digits % 10 + 48).astype(np.uint8)
            chars[(digits == 0) & (powers > 1)] = 32  # leading zeros -> spaces
            return chars
    if x.dtype == bool:
        tokens, index = ["false", "true"], x.view(np.uint8)
    elif x.dtype.kind in "iu" and hi - lo <= 1024:
        tokens, index = [str(v) for v in range(lo, hi + 1)], x - lo
    else:
        uniq, index = np.unique(x, return_inverse=True)
        if len(uniq) > 1024:
            return None
        fmt = json_number if x.dtype.kind == "f" else str
        tokens, index = [fmt(u) for u in uniq.tolist()], index.reshape(x.shape)
    width = max(map(len, tokens))
    table = np.frombuffer("".join(t.rjust(width) for t in tokens).encode(), dtype=np.uint8)
    return table.reshape(len(tokens), width)[index]


def _text(x: np.ndarray, sep: bytes, nested: bool) -> bytes:
    """JSON text of the rows of ``x`` ``(T, K)``: values joined by commas, rows by ``sep``,
    in brackets (``[[…],[…]]`` if ``nested``, else ``[…]``).

    Numpy writes the text when it can (every grid field, times, rewards, flags): each token
    padded with spaces (valid JSON) to one width, so there is no per-value Python work.
    Otherwise (physics floats) it is ``orjson`` (``json.dumps`` if a value is not finite,
    written as before: ``NaN``, ``Infinity``); exact either way.
    """
    chars = _chars(x)
    if chars is None:
        values = x if nested else x[:, 0]
        if x.dtype.kind != "f" or np.isfinite(x).all():
            return _dumps(values)
        return json.dumps(values.tolist(), separators=(",", ":")).encode()
    rows, cols, width = chars.shape
    cell = cols * (width + 1)
    out = np.empty((rows, cell - 1 + len(sep)), dtype=np.uint8)
    view = out[:, :cell].reshape(rows, cols, width + 1)
    view[:, :, :width] = chars
    view[:, :, width] = ord(",")
    out[:, cell - 1 :] = np.frombuffer(sep, dtype=np.uint8)
    body = memoryview(out.reshape(-1))[: -len(sep)]
    return b"".join((b"[[" if nested else b"[", body, b"]]" if nested else b"]"))


def json_array(values: np.ndarray) -> bytes:
    """A 1-D array as JSON text (uint64 as decimal strings: exact in any JSON reader)."""
    if len(values) == 0:
        return b"[]"
    if values.dtype == np.uint64:
        return orjson.dumps([str(v) for v in values.tolist()])
    return _text(values.reshape(-1, 1), b",", nested=False)


def json_rows(matrix: np.ndarray) -> bytes:
    """A 2-D array as JSON text: an array of rows."""
    if len(matrix) == 0:
        return b"[]"
    return _text(matrix, b"],[", nested=True)


def json_float_rows(matrix: np.ndarray) -> bytes:
    """A 2-D float array as JSON text, every value bit-exact as float64: the shortest
    round-trip repr, ``-0.0`` keeping its sign (never printed as the integer ``0``), a
    non-finite value as ``null`` (read back as NaN). For values that must replay exactly,
    such as continuous commands; float32 values are exact float64 values. (``orjson``
    writes a non-finite value as ``null`` itself.)"""
    return _dumps(np.asarray(matrix, dtype=np.float64))


def json_object(**fields: bytes) -> bytes:
    """A JSON object from already-encoded JSON values, in the given key order."""
    return b"{" + b",".join(b'"%s":%s' % (k.encode(), v) for k, v in fields.items()) + b"}"


def json_value(value: Any) -> Any:
    """A metric as a JSON value: numpy/torch scalars unwrapped, non-finite floats as null."""
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    value = float(value)
    return value if math.isfinite(value) else None
