"""Error messages in the web user's words: command-line flags named in converter errors become form labels."""

from __future__ import annotations

import re
from collections.abc import Mapping

# The upload form's label of each option (templates/upload.html); a flag not listed reads as its plain words.
LABELS = {
    "to": "Output kind", "shading": "Shading", "size": "Size (px)", "fps": "Frames per second",
    "yaw": "Camera yaw", "pitch": "Camera pitch", "tolerance": "Tolerance (px)", "max-triangles": "Triangle budget",
    "fov": "Field of view", "start": "First frame", "end": "End frame", "neutral-frame": "Neutral frame",
    "frame": "Still of frame", "smooth": "Temporal smoothing", "occlusion": "Drop never-visible triangles",
    "no-occlusion": "Drop never-visible triangles", "depth-layers": "Depth-order layer copies",
    "rigid": "Factor rigid head motion", "ortho": "Orthographic camera", "raw": "Every frame, no keyframe reduction",
    "cache": "Point cache", "fap": "FAP stream", "fdp": "FDP file", "clone-target": "Clone onto face",
    "clone-method": "Cloning method", "clone-keys": "Key models", "correspondences": "Correspondences",
    "svgz": "SVGZ", "output": "output file", "o": "output file", "frame-on": "Frame on part or node",
    "animation": "Animation", "weights": "Take", "preset": "Preset", "color-tolerance": "Colour tolerance",
    "max-animations": "Animated element budget",
}
# A flag with its placeholder ("--frame-on NAME", "--end N"): the placeholder goes with the flag.
FLAG = re.compile(r"(?<![\w-])--?([a-z][a-z0-9]*(?:-[a-z0-9]+)*)\b(?: [A-Z]{1,5}(?:\|\w+)*\b(?![\w-]))?")
BARE = re.compile(r"\b(max-triangles|neutral-frame|clone-method|clone-target|clone-keys|depth-layers)\b")


def label(flag: str) -> str:
    """The form label for a flag name (without dashes in front)."""
    return LABELS.get(flag, flag.replace("-", " "))


def user_words(message: str) -> str:
    """The message with every --flag (and bare dashed option name) replaced by the form field's label in quotes."""
    text = FLAG.sub(lambda m: f"“{label(m.group(1))}”" if m.group(0).startswith("--") or m.group(1) in LABELS
                    else m.group(0), message)
    return BARE.sub(lambda m: f"“{label(m.group(1))}”", text)


def with_user_names(message: str, stored: Mapping[str, str], names: Mapping[str, str]) -> str:
    """The message with each upload's generated name (and any folder before it) replaced by the user's file name:
    a refused take is "“my take.csv”", not "weights.json"."""
    for role, generated in stored.items():
        name = names.get(role)
        if not name or not generated:
            continue
        pattern = re.compile(r"(?:[^\s'\"“”]*[/\\]|(?<![\w.-]))" + re.escape(generated) + r"(?![\w.])")
        quoted = re.compile(r"['\"“]" + pattern.pattern + r"['\"”]")
        shown = f"“{name}”".replace("\\", "\\\\")  # a replacement string: backslashes are escapes
        message = pattern.sub(shown, quoted.sub(shown, message))
    return message
