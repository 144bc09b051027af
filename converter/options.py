"""ConversionOptions (every knob the CLI and the web form expose) and Report (what a conversion measured)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from typing import Callable

from converter.errors import InputError

OUTPUT_KINDS = ("svg", "fap2d")
SHADINGS = ("flat", "gouraud", "gouraud-chapter")

Progress = Callable[[str, float], None]
"""Progress callback: (stage name, fraction of the whole job done, 0..1)."""


def no_progress(stage: str, fraction: float) -> None:
    """A progress callback that ignores everything."""


@dataclass(frozen=True)
class ConversionOptions:
    """Every conversion knob, with defaults that give a good result."""

    to: str = "svg"  # output kind: svg | fap2d
    shading: str = "flat"  # flat | gouraud (exact gradients) | gouraud-chapter (three-gradient filters)
    frame: int | None = None  # write a still of this frame instead of the animation
    fps: float | None = None  # resample to this rate; None keeps the source's rate (else 30)
    size: int = 512  # output viewport in pixels (square)
    yaw: float = 0.0  # camera degrees around the vertical axis, 0 = front
    pitch: float = 0.0  # camera degrees up/down
    fov: float = 30.0  # vertical field of view in degrees (perspective)
    ortho: bool = False  # orthographic projection
    neutral_frame: int = 0  # the frame that serves as the neutral face
    start: int = 0  # first frame to convert
    end: int | None = None  # one past the last frame to convert
    tolerance: float = 0.25  # max vertex deviation in output pixels the encoder may introduce
    raw: bool = False  # every frame written, no keyframe reduction (the chapter's unoptimised encoding)
    max_triangles: int | None = None  # triangle budget (simplify once, shared by every frame)
    occlusion: bool = True  # drop triangles never seen in any frame (triangle-id render)
    depth_layers: bool = False  # experimental: extra layer copies of triangles whose depth order flips
    rigid: bool = True  # factor rigid 2D motion per part into animated group transforms
    smooth: float = 0.0  # temporal smoothing strength (0 = off)
    svgz: bool = False  # gzip the SVG
    fap: str | None = None  # MPEG-4 FAP stream driving the input face
    fdp: str | None = None  # feature-point definition (JSON or Xface .fdp) for the input face
    clone_target: str | None = None  # put the animation onto this face before conversion
    clone_method: str = "dense"  # example | frames | dense
    clone_keys: str | None = None  # key-model pairs (zip) for example-based cloning
    correspondences: str | None = None  # user correspondences for dense cloning
    weights: str | None = None  # blendshape weight capture (Live Link Face CSV, ARKit weight JSON) driving the face's morph targets

    def __post_init__(self) -> None:
        if self.to not in OUTPUT_KINDS:
            raise InputError(f"unknown output kind {self.to!r}; choose one of {', '.join(OUTPUT_KINDS)}.")
        if self.shading not in SHADINGS:
            raise InputError(f"unknown shading {self.shading!r}; choose one of {', '.join(SHADINGS)}.")
        if self.fps is not None and not (0 < self.fps <= 240):
            raise InputError(f"fps must be between 0 and 240, got {self.fps}.")
        if not (16 <= self.size <= 8192):
            raise InputError(f"size must be between 16 and 8192 pixels, got {self.size}.")
        if not (0 < self.tolerance <= 50):
            raise InputError(f"tolerance must be between 0 and 50 px, got {self.tolerance}.")
        if self.max_triangles is not None and self.max_triangles < 4:
            raise InputError(f"max-triangles must be at least 4, got {self.max_triangles}.")
        if self.start < 0 or (self.end is not None and self.end <= self.start):
            raise InputError("the frame range is empty; --end must be greater than --start and --start >= 0.")
        if self.smooth < 0:
            raise InputError("smooth must be 0 (off) or positive.")

    def to_json(self) -> dict:
        """Plain dict of every option."""
        return asdict(self)

    @classmethod
    def from_mapping(cls, data: dict) -> "ConversionOptions":
        """Build from strings or values (web form, JSON); unknown keys are refused with a clear error."""
        known = {f.name: f for f in fields(cls)}
        kwargs = {}
        for key, value in data.items():
            key = key.replace("-", "_")
            if key not in known:
                raise InputError(f"unknown option {key!r}.")
            if value is None or value == "":
                continue
            kwargs[key] = _coerce(key, known[key].type, value)
        return cls(**kwargs)


def _coerce(name: str, type_name: str, value):
    """Turn a form string into the option's type."""
    try:
        if "bool" in type_name:
            if isinstance(value, bool):
                return value
            return str(value).lower() in ("1", "true", "yes", "on")
        if "int" in type_name:
            return int(value)
        if "float" in type_name:
            return float(value)
        return str(value)
    except (TypeError, ValueError):
        raise InputError(f"option {name} must be a {type_name.split()[0]}, got {value!r}.") from None


@dataclass
class Report:
    """What a conversion measured: counts, sizes, timings and fidelity figures."""

    counts: dict[str, int] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    figures: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        """Plain dict, rounded for display and metadata."""
        return {
            "counts": dict(self.counts),
            "sizes": dict(self.sizes),
            "timings": {k: round(v, 4) for k, v in self.timings.items()},
            "figures": {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.figures.items()},
            "warnings": list(self.warnings),
        }

    def summary(self) -> str:
        """One line for the CLI."""
        c, s = self.counts, self.sizes
        parts = [
            f"{c.get('frames', 0)} frames",
            f"{c.get('triangles_kept', c.get('triangles', 0))}/{c.get('triangles', 0)} triangles kept",
            f"{s.get('output', 0) / 1024:.1f} KB",
            f"{sum(self.timings.values()):.2f} s",
        ]
        if "max_deviation_px" in self.figures:
            parts.append(f"max deviation {self.figures['max_deviation_px']:.3f} px")
        return ", ".join(parts)

    def dumps(self) -> str:
        """JSON text."""
        return json.dumps(self.to_json(), sort_keys=True)
