"""Strict JSON for the web app: no NaN or infinity is ever written, whatever a stored record or report holds.

Python's json writes a non-finite float as a bare `NaN`/`Infinity`, which is not JSON: a browser's
`response.json()` and every strict parser refuse the whole answer. Here such a figure becomes null.
"""

from __future__ import annotations

import json
import math
from typing import Any

from flask.json.provider import DefaultJSONProvider


def finite(value: Any) -> Any:
    """A copy of value in which every non-finite float (NaN, +-inf), however deeply nested, is None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def _finite_float(text: str) -> float | None:
    number = float(text)
    return number if math.isfinite(number) else None


def loads(text: str | bytes) -> Any:
    """Parse JSON as stored by older code: a bare NaN/Infinity, or a number too large for a float, reads as None."""
    return json.loads(text, parse_constant=lambda _: None, parse_float=_finite_float)


def dumps(value: Any, **kwargs: Any) -> str:
    """json.dumps that writes non-finite floats as null (never a bare NaN)."""
    try:
        return json.dumps(value, allow_nan=False, **kwargs)
    except ValueError:  # a NaN or infinity somewhere: the rare case pays for the copy
        return json.dumps(finite(value), allow_nan=False, **kwargs)


class StrictJSONProvider(DefaultJSONProvider):
    """Flask's JSON (jsonify, the tojson filter) with non-finite numbers written as null."""

    def dumps(self, obj: Any, **kwargs: Any) -> str:
        """Serialize obj to strict JSON."""
        kwargs["allow_nan"] = False
        try:
            return super().dumps(obj, **kwargs)
        except ValueError:
            return super().dumps(finite(obj), **kwargs)
