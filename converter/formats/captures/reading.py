"""Checked readers the H1b capture layouts add to `_util`: several JSON documents in one file, numeric matrices."""

from __future__ import annotations

import json

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util


def json_docs(data: bytes, name: str, what: str) -> list:
    """One JSON document, or several written one after another (newline-delimited chunks), as a list of values."""
    body = _util.text(data, name, what)
    decoder = json.JSONDecoder()
    docs, pos = [], 0
    while True:
        while pos < len(body) and body[pos].isspace():
            pos += 1
        if pos == len(body):
            return docs
        try:
            doc, pos = decoder.raw_decode(body, pos)
        except (json.JSONDecodeError, RecursionError) as exc:
            raise InputError(f"{name} is not valid JSON ({str(exc)[:60]}); the {what} is truncated or edited.") \
                from None
        docs.append(doc)


def matrix(rows, width: int, name: str, what: str) -> np.ndarray:
    """A non-empty (T, width) float64 array from nested JSON lists; InputError on ragged rows, non-numbers, NaN."""
    if not isinstance(rows, list) or not rows:
        raise InputError(f"{name}: {what} must be a non-empty list of frames.")
    _util.frame_count(len(rows), name)
    bad = next((k for k, r in enumerate(rows) if not isinstance(r, list) or len(r) != width), None)
    if bad is not None:
        got = len(rows[bad]) if isinstance(rows[bad], list) else type(rows[bad]).__name__
        raise InputError(f"{name}: {what} frame {bad} has {got} values, expected {width}; the file is truncated "
                         "or edited.")
    try:
        mat = np.array(rows, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: {what} holds values that are not numbers.") from None
    if mat.ndim != 2:
        raise InputError(f"{name}: {what} holds nested lists where numbers belong.")
    if not np.isfinite(mat).all():
        r, c = np.argwhere(~np.isfinite(mat))[0]
        raise InputError(f"{name}: {what} frame {r}, value {c} is NaN or infinite.")
    return mat
