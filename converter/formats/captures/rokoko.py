"""Rokoko Studio face data: Studio Live JSON packets (v3, and the older v2), one or a recorded stream of them.

Layout (as Rokoko's own Blender plugin, rokoko-studio-live-blender core/live_data_manager.py and animations.py,
reads it):
- v3: `{"version": 3, "fps": 60, "scene": {"timestamp": t, "actors": [{"name", "meta": {"hasFace": true, ...},
  "face": {"faceId": .., "eyeBlinkLeft": w, ...}, "body": ...}], "props": [...]}}`;
- v2 (and Studio 1's "v2.5", which says version 3 but carries `trackers`): `{"version": 2, "timestamp": t,
  "faces": [{"faceId", "profileName", "eyeBlinkLeft": w, ...}], "actors": [...], "props", "trackers"}`.
Face weights are the 52 ARKit names in lowerCamel spelling on a 0-100 scale (the plugin divides by 100); here
they become 0..1. A take is one packet per frame: a JSON list of packets, or one packet per line as a stream
recorder saves them.

The first face found (the first actor with `meta.hasFace`, or the first entry of `faces`) is followed through the
take by its faceId; every packet must carry it with the same blendshapes. Times: the packets' timestamps (scene
timestamp in v3) in seconds, or milliseconds when the steps are longer than half a second, when they increase;
otherwise (a single packet, missing or repeated timestamps) frame k is at k / fps. The rate is the packets' `fps`,
else the timestamps' spacing (`_util.spacing_rate`), else 60.
"""

from __future__ import annotations

import numpy as np

from converter.errors import InputError
from converter.formats.captures import _util, reading
from converter.formats.captures.arkit import NAME_SET
from converter.formats.captures.base import DEFAULT_FPS, CaptureLayout, WeightTrack

WHAT = "Rokoko Studio face JSON"
SCALE = 100.0  # Rokoko face weights run 0..100


def sniff(data: bytes) -> bool:
    """True for JSON with a Rokoko face (faceId) inside Studio Live's actors or faces."""
    head = _util.head(data)
    return head[:1] in (b"{", b"[") and b'"faceId"' in head and (b'"actors"' in head or b'"faces"' in head)


def parse(data: bytes, name: str = "rokoko.json") -> WeightTrack:
    """Rokoko Studio Live packets as a WeightTrack of the first face's weights, scaled to 0..1."""
    docs = reading.json_docs(data, name, WHAT)
    packets = [p for d in docs for p in (d if isinstance(d, list) else [d])]
    if not packets:
        raise InputError(f"{name} holds no Rokoko Studio packets.")
    _util.frame_count(len(packets), name)
    first = _faces(packets[0], name, 0)
    if not first:
        raise InputError(f"{name}: the first packet has no face (no actor with meta.hasFace and a face, no faces "
                         "entry); record the take with face capture on.")
    face_id = first[0].get("faceId")
    names = [k for k in first[0] if k in NAME_SET]
    if not names:
        raise InputError(f"{name}: face {face_id!r} has no ARKit blendshape weights (eyeBlinkLeft ... tongueOut).")
    values = np.empty((len(packets), len(names)), np.float64)
    for k, packet in enumerate(packets):
        face = next((f for f in _faces(packet, name, k) if f.get("faceId") == face_id), None)
        if face is None:
            raise InputError(f"{name}: packet {k} has no face {face_id!r}; the take is cut or mixes recordings.")
        missing = next((n for n in names if n not in face), None)
        if missing is not None:
            raise InputError(f"{name}: packet {k}, face {face_id!r} has no {missing!r} weight.")
        values[k] = [_util.number(face[n], name, f"packet {k}, weight {n!r}") for n in names]
    times, fps = _times(packets, name)
    return WeightTrack(names, times, (values / SCALE).astype(np.float32), fps, source=LAYOUT.name)


def _faces(packet, name: str, k: int) -> list[dict]:
    """The face objects of one packet (v3 actors' faces, or v2 faces), in file order."""
    if not isinstance(packet, dict):
        raise InputError(f"{name}: packet {k} is not a JSON object; a {WHAT} is Studio Live packets.")
    scene = packet.get("scene")
    if isinstance(scene, dict) and isinstance(scene.get("actors"), list):
        out = []
        for actor in (a for a in scene["actors"] if isinstance(a, dict)):
            meta = actor.get("meta")
            has_face = meta.get("hasFace", True) if isinstance(meta, dict) else True
            if has_face and isinstance(actor.get("face"), dict):
                out.append(actor["face"])
        return out
    faces = packet.get("faces")
    if isinstance(faces, list):
        return [f for f in faces if isinstance(f, dict)]
    raise InputError(f"{name}: packet {k} has neither scene.actors (Studio Live JSON v3) nor faces (v2).")


def _times(packets: list[dict], name: str) -> tuple[np.ndarray, float]:
    """Seconds from the first packet and the frame rate (see the module docstring)."""
    fps_field = packets[0].get("fps")
    fps = _util.fps_value(fps_field, name) if fps_field is not None else None
    stamps = [p["scene"].get("timestamp") if isinstance(p.get("scene"), dict) else p.get("timestamp")
              for p in packets]
    usable = len(packets) > 1 and all(isinstance(s, (int, float)) and not isinstance(s, bool) for s in stamps)
    if usable:
        t = np.array(stamps, np.float64)
        usable = bool(np.isfinite(t).all() and np.all(np.diff(t) > 0))
    if not usable:
        rate = fps or DEFAULT_FPS
        return np.arange(len(packets)) / rate, rate
    t = t - t[0]
    if np.median(np.diff(t)) > 0.5:
        t = t / 1000.0  # millisecond stamps: no face stream runs below 2 frames a second
    return t, fps or _util.spacing_rate(t)


LAYOUT = CaptureLayout(
    name="rokoko-json",
    label="Rokoko Studio face JSON",
    extensions=(".json", ".jsonl"),
    sniff=sniff,
    parse=parse,
    doc="Rokoko Studio Live JSON v3/v2 packets (faces: ARKit names, 0-100), as rokoko-studio-live-blender reads them",
)
