"""Blendshape weight captures: the names older callers import, kept on top of the capture-layout registry.

The readers live in `converter.formats.captures` (one module per layout, recognised by content); this module
re-exports what the loaders, the weights stage, the bench and the tests have imported from here.
"""

from __future__ import annotations

from converter.formats.captures import extensions, is_capture, parse_capture, read_capture
from converter.formats.captures.base import DEFAULT_FPS, MAX_FRAMES, WeightTrack

read_weights = read_capture
parse_weights = parse_capture

__all__ = ["DEFAULT_FPS", "MAX_FRAMES", "WeightTrack", "extensions", "is_capture", "parse_capture", "parse_weights",
           "read_capture", "read_weights"]
