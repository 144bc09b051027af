"""The web UI (Flask): upload, convert, preview, download. The app itself is in webapp.app; `create_app` and the
other names are loaded from there on first use, so that importing a light part of the package (the `facesvg`
command registers `serve` and `worker` through webapp.cli) does not load Flask, which would slow every
`facesvg convert`."""

from __future__ import annotations

import importlib
from typing import Any

_APP_NAMES = {"create_app", "DEFAULTS", "ENV_KEYS", "ROOT", "RetentionSweeper", "wants_json"}


def __getattr__(name: str) -> Any:
    """webapp.create_app and the other names of webapp.app, imported when first asked for."""
    if name in _APP_NAMES:
        return getattr(importlib.import_module("webapp.app"), name)
    raise AttributeError(f"module 'webapp' has no attribute {name!r}")
