"""What every output's metadata says about its source: the frames, the camera and the options, so the verifier
can re-project the input and check the output."""

from __future__ import annotations

from converter.options import ConversionOptions
from converter.sheet import Sheet


def source_fields(sheet: Sheet, options: ConversionOptions) -> dict:
    """Frames, fps, duration, viewport, camera, source file hash and frame range, options and counts."""
    return {
        "frames": sheet.n_frames,
        "fps": sheet.fps,
        "duration": sheet.duration,
        "viewport": [sheet.camera.width, sheet.camera.height],
        "camera": sheet.camera.to_json(),
        "source_sha256": sheet.info.get("source_sha256", ""),
        "source_frames": sheet.info.get("source_frames", [0, sheet.n_frames]),
        "options": options.to_json(),
        "counts": {k: v for k, v in sheet.info.items() if isinstance(v, int)},
    }
