"""ConversionOptions (every knob the CLI and the web form expose) and Report (what a conversion measured)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any, NamedTuple

from converter.errors import InputError
from converter.playcost import describe as describe_playback

SHADINGS = {
    "flat": "Flat (smallest)",
    "gouraud": "Gouraud (smooth gradients)",
    "gouraud-chapter": "Gouraud, chapter method (three gradients)",
}
CLONE_METHODS = {
    "dense": "Dense (whole face)",
    "example": "Example-based (key models)",
    "frames": "Local frames",
}



class Preset(NamedTuple):
    """A named set of option values (CLI --preset, the web form's preset buttons, the API's preset field)."""

    label: str
    values: Mapping[str, Any]
    description: str


# Tuned by bench_playback (the capture-like face in Chromium under 4x CPU throttling, issue 18).
PRESETS = {
    "mobile": Preset("Mobile", {"size": 256, "max_triangles": 2500, "tolerance": 0.5, "color_tolerance": 255.0,
                                "max_animations": 300},
                     "256 px, the fewest triangles (at most 2,500) that move the face by at most 0.5 px on average "
                     "and 5 px anywhere and keep every visible part (hair, eyes, brows; --max-triangles sets the cap), "
                     "0.5 px tolerance, static colours, at most 300 animated paths: a light file that plays smoothly "
                     "on phones"),
}


class SimplifyBound(NamedTuple):
    """What a triangle budget may do to the face, in px at the output size over every frame, and to each part's
    silhouette at frame 0 (converter.simplify measures both and reports them against this bound)."""

    mean_px: float  # mean distance between the face's vertices and the simplified surface they hang on
    max_px: float  # the largest such distance (any vertex shown, any frame)
    coverage_kept: float  # share of a part's visible pixels at frame 0 it must keep
    slack_px: int  # pixels any part may lose (a small part's edges round either way): a smaller part may vanish

    def lost_px(self, shown: float) -> float:
        """The most pixels a part that shows this many at frame 0 may lose."""
        return max((1.0 - self.coverage_kept) * shown, float(self.slack_px))


# At 256 px (the mobile preset): 0.5 px on average and 5 px at worst keep lips, lids and brows where they are, and a
# part keeps 90% of its pixels at frame 0: hair, eyes, brows and lashes that show are never simplified away. The
# bundled sample and a Ready Player Me avatar driven by a Live Link Face take keep well under the cap for it; at the
# old count of 850 they moved by more than the bound, and lost much of an eye and of the avatar's top. The cap
# (2,500) keeps the file light where the bound would ask for more (the ICT head, for its lashes over its eyes): it
# warns then.
SIMPLIFY_BOUND = SimplifyBound(mean_px=0.5, max_px=5.0, coverage_kept=0.9, slack_px=2)
# Presets whose max_triangles is a cap, not a count: the fewest triangles that keep SIMPLIFY_BOUND, at most the cap
# (a max_triangles given with the preset is the cap; without such a preset it is the count).
BOUNDED_PRESETS = frozenset({"mobile"})
EXACT_FROM = 8.0  # the default colour tolerance, which --exact replaces
EXACT_LEVELS = 3.0  # --exact's: each triangle's own held steps within 3 levels (the exact shading, as rounded)

Progress = Callable[[str, float], None]
"""Progress callback: (stage name, fraction of the whole job done, 0..1)."""


def no_progress(stage: str, fraction: float) -> None:
    """A progress callback that ignores everything."""


def span(progress: Progress, start: float, end: float, stage: str | None = None) -> Progress:
    """A callback for one part of a job that maps its own 0..1 onto start..end of progress (renamed to stage when
    given): a part reports its own fraction without knowing its share of the whole."""
    if progress is no_progress:
        return no_progress
    width = end - start

    def part(name: str, fraction: float) -> None:
        progress(stage or name, start + width * min(max(fraction, 0.0), 1.0))

    return part


def seconds_left(elapsed: float, fraction: float, min_fraction: float = 0.05) -> float | None:
    """Seconds a job still needs, extrapolating its progress so far; None until it has done min_fraction."""
    if fraction < min_fraction:
        return None
    return max(elapsed / fraction * (1.0 - fraction), 0.0)


LOAD_STAGES = frozenset({"load", "weights"})  # reading the input: its share of the bar is a guess made before it


class Eta:
    """Seconds a conversion still needs from its progress calls (stage, fraction, now): extrapolated from the
    progress made since the input was read, whose time no share set before reading can foresee (driving the ICT
    head by a capture is a large share of a mobile-preset run, reading a small glTF next to nothing)."""

    def __init__(self) -> None:
        self.origin: tuple[float, float] | None = None  # (time, fraction) the extrapolation counts from
        self.loading = True

    def see(self, stage: str, fraction: float, now: float) -> tuple[float, float]:
        """Note a progress call (every one: where loading ended must not be missed); the origin so far."""
        if self.origin is None or (self.loading and stage not in LOAD_STAGES):
            self.origin = (now, fraction)
            self.loading = stage in LOAD_STAGES
        return self.origin

    def __call__(self, stage: str, fraction: float, now: float) -> float | None:
        return seconds_left_since(self.see(stage, fraction, now), fraction, now)


def seconds_left_since(origin: tuple[float, float], fraction: float, now: float) -> float | None:
    """seconds_left() of the progress made since origin (time, fraction); None when done or too little done."""
    t0, f0 = origin
    if fraction >= 1.0 or f0 >= 1.0:
        return None
    return seconds_left(now - t0, (fraction - f0) / (1.0 - f0))


@dataclass(frozen=True)
class Option:
    """What the CLI, the web form, the API and OpenAPI show and check for one ConversionOptions field."""

    help: str
    label: str = ""  # the web form's label
    choices: Mapping[str, str] | None = None  # value -> label, in the order offered
    output_kinds: bool = False  # the choices are the registered output kinds (converter.outputs)
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False  # the minimum itself is refused
    unit: str = ""
    unset: str = ""  # what leaving it unset (None) means
    path: bool = False  # a file the user names: a path on the command line, an upload on the web
    accept: str = ""  # the web form's file types for a path
    advanced: bool = False  # under "More options" in the web form
    form: bool = True  # offered by the web form (svgz is not: the web stores both SVG and SVGZ)

    def check(self, name: str, value) -> None:
        """InputError when value is not one of the choices or outside the range."""
        shown = name.replace("_", "-")
        if self.choices is not None and value not in self.choices:
            raise InputError(f"unknown {name.replace('_', ' ')} {value!r}; choose one of {', '.join(self.choices)}.")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return
        if value != value:
            raise InputError(f"{shown} must be a number, got {value}.")
        lo, hi = self.minimum, self.maximum
        low = lo is not None and (value <= lo if self.exclusive_minimum else value < lo)
        high = hi is not None and value > hi
        if not (low or high):
            return
        unit = f" {self.unit}" if self.unit else ""
        if lo is not None and hi is not None:
            above = f"above {lo:g}" if self.exclusive_minimum else f"between {lo:g}"
            joint = " and at most " if self.exclusive_minimum else " and "
            raise InputError(f"{shown} must be {above}{joint}{hi:g}{unit}, got {value:g}.")
        if lo is not None:
            bound = f"above {lo:g}" if self.exclusive_minimum else f"at least {lo:g}"
            raise InputError(f"{shown} must be {bound}{unit}, got {value:g}.")
        raise InputError(f"{shown} must be at most {hi:g}{unit}, got {value:g}.")


def option(default, help: str, **meta):
    """A ConversionOptions field with its Option metadata."""
    return field(default=default, metadata={"option": Option(help, **meta)})


@dataclass(frozen=True)
class ConversionOptions:
    """Every conversion knob, with defaults that give a good result."""

    preset: str | None = option(None, "a named set of option values; the options you do not set take the "
                                "preset's: " + "; ".join(f"{k}: {p.description}" for k, p in PRESETS.items()),
                                label="Preset", choices={k: p.label for k, p in PRESETS.items()}, unset="none",
                                form=False)
    to: str = option("svg", "the kind of file to write", label="Output kind", output_kinds=True)
    shading: str = option("flat", "how triangles are filled: flat colours, or exact (gouraud) or the chapter's "
                          "three-gradient (gouraud-chapter) smooth shading", label="Shading", choices=SHADINGS)
    frame: int | None = option(None, "write a still of this frame instead of the animation", label="Still of frame",
                               minimum=0, unset="animate", advanced=True)
    fps: float | None = option(None, "resample to this frame rate", label="Frames per second", minimum=0,
                               exclusive_minimum=True, maximum=240, unset="the source's rate, else 30")
    animation: str | None = option(None, "glTF animation to play: a clip's NAME or INDEX, or all",
                                   label="Animation", unset="the first take (clips that play together) or clip",
                                   advanced=True)
    size: int = option(512, "output viewport in pixels (square)", label="Size (px)", minimum=16, maximum=8192,
                       unit="px")
    yaw: float = option(0.0, "camera degrees around the vertical axis, 0 = front", label="Camera yaw (°)",
                        minimum=-180, maximum=180, unit="degrees")
    pitch: float = option(0.0, "camera degrees up or down", label="Camera pitch (°)", minimum=-89, maximum=89,
                          unit="degrees")
    frame_on: str | None = option(None, "frame only this part or glTF node/mesh (see `facesvg info`)",
                                  label="Frame on part or node",
                                  unset="everything, or the head of a full-body avatar", advanced=True)
    fov: float = option(30.0, "vertical field of view in degrees (perspective)", label="Field of view (°)",
                        minimum=1, maximum=150, unit="degrees", advanced=True)
    ortho: bool = option(False, "orthographic projection", label="Orthographic camera", advanced=True)
    neutral_frame: int = option(0, "the frame that serves as the neutral face", label="Neutral frame", minimum=0,
                                advanced=True)
    start: int = option(0, "first frame to convert", label="First frame", minimum=0, advanced=True)
    end: int | None = option(None, "one past the last frame to convert", label="End frame (exclusive)", minimum=1,
                             unset="the last frame", advanced=True)
    tolerance: float = option(0.25, "largest vertex deviation in output pixels the encoder may add",
                              label="Tolerance (px)", minimum=0, exclusive_minimum=True, maximum=50, unit="px")
    color_tolerance: float = option(8.0, "largest colour deviation (8-bit levels per channel) of the flat SVG: "
                                    "triangles whose shades stay within it of each other at every frame share one "
                                    "animated colour (and, in one group, one path); 255 keeps every colour static "
                                    "(the mobile preset); with --exact each triangle's own colour steps keep to it",
                                    label="Colour tolerance (levels)", minimum=0.6, maximum=255, advanced=True)
    exact: bool = option(False, "one path per triangle, each with its own colour steps within 3 levels (unless "
                         "--color-tolerance says otherwise): the exact shading, the largest file and the slowest "
                         "to play", label="Exact: one path per triangle", advanced=True)
    max_animations: int | None = option(None, "at most this many animated elements in the flat SVG: paths of one "
                                        "colour in one group are merged into one path of several triangles, keyed "
                                        "together (more bytes, far cheaper playback)",
                                        label="Animated element budget", minimum=1,
                                        unset="paths of one shared colour in one group merged", advanced=True)
    raw: bool = option(False, "write every frame, no keyframe reduction (the chapter's unoptimised encoding)",
                       label="Every frame, no keyframe reduction", advanced=True)
    max_triangles: int | None = option(None, "triangle budget (simplify once, shared by every frame)",
                                       label="Triangle budget", minimum=4, unset="no limit")
    occlusion: bool = option(True, "drop triangles never seen in any frame (triangle-id render)",
                             label="Drop never-visible triangles", advanced=True)
    depth_layers: bool = option(False, "experimental: extra layer copies of triangles whose depth order flips",
                                label="Depth-order layer copies (experimental)", advanced=True)
    rigid: bool = option(True, "factor rigid 2D motion per part into animated group transforms",
                         label="Factor rigid head motion", advanced=True)
    smooth: float = option(0.0, "temporal smoothing, Gaussian sigma in frames (0 = off)", label="Temporal smoothing",
                           minimum=0, advanced=True)
    svgz: bool = option(False, "gzip the SVG", label="Gzip the SVG", form=False)
    fap: str | None = option(None, "MPEG-4 FAP stream that drives the face", label="FAP stream", path=True,
                             advanced=True)
    fdp: str | None = option(None, "feature points of the face (JSON or Xface .fdp)", label="FDP file", path=True,
                             advanced=True)
    clone_target: str | None = option(None, "a glTF/GLB/OBJ face to put the animation onto before converting",
                                      label="Clone onto face", path=True, accept=".glb,.gltf,.vrm,.obj,.ply,.zip",
                                      advanced=True)
    clone_method: str = option("dense", "how the animation is put onto the clone target", label="Cloning method",
                               choices=CLONE_METHODS, advanced=True)
    clone_keys: str | None = option(None, "zip of key-model pairs, for example-based cloning", label="Key models",
                                    path=True, accept=".zip", advanced=True)
    correspondences: str | None = option(None, "your own point correspondences, for dense cloning",
                                         label="Correspondences", path=True, advanced=True)
    weights: str | None = option(None, "blendshape weight capture (Live Link Face, Face Cap, MediaPipe, "
                                 "Audio2Face, Rokoko, Rhubarb, ...: `facesvg info` names its layout) that "
                                 "drives the face's named morph targets", label="Weight capture", path=True,
                                 accept=".csv,.json,.jsonl,.tsv,.txt", advanced=True)

    def __post_init__(self) -> None:
        if self.preset is not None and self.preset in PRESETS:
            defaults = {f.name: f.default for f in fields(self)}
            for name, value in PRESETS[self.preset].values.items():
                if getattr(self, name) == defaults[name]:
                    object.__setattr__(self, name, value)
        if self.exact and self.color_tolerance == EXACT_FROM:  # the exact shading, unless a tolerance is given
            object.__setattr__(self, "color_tolerance", EXACT_LEVELS)
        for spec in option_fields():
            value = getattr(self, spec.name)
            if value is not None:
                spec.meta.check(spec.name, value)
        if self.end is not None and self.end <= self.start:
            raise InputError("the frame range is empty; --end must be greater than --start and --start >= 0.")

    @classmethod
    def given(cls, **values: Any) -> ConversionOptions:
        """Options from the values a caller set explicitly: a preset fills only the others, so a value given
        equal to its default stays (the constructor alone cannot tell it from one left unset)."""
        options = cls(**values)
        for name, value in values.items():  # only fields the preset moved off their default differ here
            object.__setattr__(options, name, value)
        return options

    def to_json(self) -> dict:
        """Plain dict of every option."""
        return asdict(self)

    @classmethod
    def from_mapping(cls, data: dict) -> ConversionOptions:
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
        return cls.given(**kwargs)


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


@dataclass(frozen=True)
class OptionField:
    """One ConversionOptions field as the CLI, the web form and OpenAPI see it."""

    name: str
    type: type  # bool, int, float or str
    default: Any  # None: unset unless given
    meta: Option

    @property
    def flag(self) -> str:
        """The command-line flag: --name, or --no-name for a switch that is on by default."""
        dashed = self.name.replace("_", "-")
        return f"--no-{dashed}" if self.type is bool and self.default else f"--{dashed}"


def _value_type(type_name: str) -> type:
    for t in (bool, int, float):
        if t.__name__ in type_name:
            return t
    return str


def option_fields() -> tuple[OptionField, ...]:
    """Every ConversionOptions field with its type, default and Option metadata, in declaration order."""
    return _OPTION_FIELDS


@dataclass
class Report:
    """What a conversion measured: counts, sizes, timings and fidelity figures.

    A triangle budget (converter.simplify) adds, in px at the output size: budget_deviation_mean_px and
    budget_deviation_px (mean and largest distance between the face and its simplified surface over every frame),
    budget_bound_mean_px and budget_bound_px (SIMPLIFY_BOUND's), budget_coverage_kept_<part label> (the share of the
    part's pixels at frame 0 it still shows), budget_within_bound (bool: deviation and every part within the bound),
    and a warning in words for each part that lost visible area and for a deviation past the bound."""

    counts: dict[str, int] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    figures: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        """Plain dict, rounded for display and metadata; strict JSON: a figure or timing that is not a finite
        number (one that could not be computed) is left out."""
        return {
            "counts": dict(self.counts),
            "sizes": dict(self.sizes),
            "timings": _finite_rounded(self.timings),
            "figures": _finite_rounded(self.figures),
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
        if "playback_ms_4x" in self.figures:
            parts.append(describe_playback(self.figures["playback_ms_4x"]))
        if "max_deviation_px" in self.figures:
            parts.append(f"max deviation {self.figures['max_deviation_px']:.3f} px")
        return ", ".join(parts)

    def dumps(self) -> str:
        """JSON text (strict: no NaN or Infinity)."""
        return json.dumps(self.to_json(), sort_keys=True, allow_nan=False)


def _finite_rounded(values: Mapping[str, Any]) -> dict:
    """values with floats rounded to 4 decimals and the non-finite ones (NaN, inf) left out."""
    return {k: round(v, 4) if isinstance(v, float) else v for k, v in values.items()
            if not isinstance(v, float) or math.isfinite(v)}


_OPTION_FIELDS = tuple(OptionField(f.name, _value_type(str(f.type)), f.default, f.metadata["option"])
                       for f in fields(ConversionOptions))
