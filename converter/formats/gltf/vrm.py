"""VRM avatars' expressions (VRM 0.x blendShapeGroups, VRM 1.0 VRMC_vrm.expressions) as weighted morph target binds.

Read as the specifications define them (vrm-c/vrm-specification) and as three-vrm loads them:
- VRM 1.0: `extensions.VRMC_vrm.expressions.preset` {happy, angry, sad, relaxed, surprised, aa, ih, ou, ee, oh,
  blink, blinkLeft, blinkRight, lookUp, lookDown, lookLeft, lookRight, neutral} and `.custom` {name: ...}, each
  with `morphTargetBinds` [{node, index, weight 0..1 (default 1)}], `isBinary`, `overrideBlink/LookAt/Mouth`
  (none, block, blend), `materialColorBinds`, `textureTransformBinds`. An unknown preset name, or a custom one
  named like a preset, is ignored (the spec forbids it; three-vrm skips it).
- VRM 0.x: `extensions.VRM.blendShapeMaster.blendShapeGroups` [{name, presetName, binds [{mesh, index,
  weight 0..100}], isBinary, materialValues}]. A bind names a mesh: it moves every node drawing that mesh. Preset
  names become 1.0's (a->aa, i->ih, u->ou, e->ee, o->oh, joy->happy, sorrow->sad, fun->relaxed, blink_l->blinkLeft,
  blink_r->blinkRight, lookup->lookUp, ...); "unknown" or no preset is a custom expression named by `name`; a
  later group with a name already taken is ignored (three-vrm does the same). 0.x has no overrides.
An expression's value v (clamped to 0..1; with isBinary, 1 when v > 0.5 else 0) moves each bound target by
v x weight. The spec's override rules (a non-procedural expression's value blocks or attenuates blink, lookAt
and mouth presets) are applied where the face is driven (converter.blendshapes). Material colour and texture
transform binds change no vertex: they are counted and reported, not drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

PRESETS = ("happy", "angry", "sad", "relaxed", "surprised", "aa", "ih", "ou", "ee", "oh", "blink", "blinkLeft",
           "blinkRight", "lookUp", "lookDown", "lookLeft", "lookRight", "neutral")
V0_PRESETS = {"a": "aa", "i": "ih", "u": "ou", "e": "ee", "o": "oh", "joy": "happy", "angry": "angry",
              "sorrow": "sad", "fun": "relaxed", "blink": "blink", "blink_l": "blinkLeft", "blink_r": "blinkRight",
              "lookup": "lookUp", "lookdown": "lookDown", "lookleft": "lookLeft", "lookright": "lookRight",
              "neutral": "neutral"}
# The procedural presets each override property acts on (VRM 1.0 expressions.md, "Procedural override").
PROCEDURAL = {"blink": ("blink", "blinkLeft", "blinkRight"), "lookAt": ("lookUp", "lookDown", "lookLeft", "lookRight"),
              "mouth": ("aa", "ih", "ou", "ee", "oh")}
OVERRIDES = ("none", "block", "blend")


@dataclass(frozen=True)
class Expression:
    """One VRM expression: its (1.0) name, its morph binds (node, target slot, weight 0..1) and how it applies."""

    name: str
    preset: bool
    binds: tuple[tuple[int, int, float], ...]
    binary: bool = False
    overrides: tuple[tuple[str, str], ...] = ()  # (kind in PROCEDURAL, "block" | "blend") for each it sets
    material_binds: int = 0  # material colour and texture transform binds: nothing we draw


def version(doc: dict) -> str | None:
    """'1.0' or '0.x' when the document carries a VRM extension (1.0 first, as three-vrm reads them), else None."""
    ext = doc.get("extensions") if isinstance(doc.get("extensions"), dict) else {}
    if isinstance(ext.get("VRMC_vrm"), dict):
        return "1.0"
    if isinstance(ext.get("VRM"), dict):
        return "0.x"
    return None


def read_expressions(doc: dict) -> tuple[list[Expression], list[str]]:
    """The document's VRM expressions (in file order) and notes on what was skipped or is not drawn."""
    v = version(doc)
    notes: list[str] = []
    if v == "1.0":
        out = _v1(doc["extensions"]["VRMC_vrm"], doc, notes)
    elif v == "0.x":
        out = _v0(doc["extensions"]["VRM"], doc, notes)
    else:
        return [], []
    material = [e.name for e in out if e.material_binds]
    if material:
        notes.append(f"VRM expressions {', '.join(material)} also change materials (colour or texture binds), which "
                     "are not drawn: only their morph targets move.")
    return out, notes


def _v1(ext: dict, doc: dict, notes: list[str]) -> list[Expression]:
    table = ext.get("expressions") if isinstance(ext.get("expressions"), dict) else {}
    out = []
    for group in ("preset", "custom"):
        entries = table.get(group) if isinstance(table.get(group), dict) else {}
        for name, e in entries.items():
            if not isinstance(e, dict):
                continue
            if (name in PRESETS) != (group == "preset"):
                notes.append(f"VRM expression {name!r} is ignored: " + (
                    "not a preset name." if group == "preset" else "a custom expression may not take a preset name."))
                continue
            binds = []
            for b in _list(e.get("morphTargetBinds")):
                node, index, weight = (b.get("node"), b.get("index"), b.get("weight", 1.0)) if isinstance(b, dict) \
                    else (None, None, None)
                bind = _bind(doc, node, index, weight, 1.0)
                if bind is None:
                    notes.append(f"VRM expression {name!r}: a morph bind (node {node}, index {index}) names no morph "
                                 "target; it is skipped.")
                    continue
                binds.append(bind)
            overrides = tuple((kind, e.get(key)) for kind, key in (("blink", "overrideBlink"),
                                                                   ("lookAt", "overrideLookAt"),
                                                                   ("mouth", "overrideMouth"))
                              if e.get(key) in ("block", "blend") and name not in PROCEDURAL[kind])
            materials = len(_list(e.get("materialColorBinds"))) + len(_list(e.get("textureTransformBinds")))
            out.append(Expression(str(name), group == "preset", tuple(binds), e.get("isBinary") is True, overrides,
                                  materials))
    return out


def _v0(ext: dict, doc: dict, notes: list[str]) -> list[Expression]:
    master = ext.get("blendShapeMaster") if isinstance(ext.get("blendShapeMaster"), dict) else {}
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    out: list[Expression] = []
    taken: set[str] = set()
    for g in _list(master.get("blendShapeGroups")):
        if not isinstance(g, dict):
            continue
        preset = V0_PRESETS.get(str(g.get("presetName") or "").lower())
        name = preset or (str(g["name"]) if g.get("name") not in (None, "") else None)
        if name is None:
            notes.append("a VRM blend shape group with no name and no preset is ignored.")
            continue
        if name in taken:
            notes.append(f"VRM blend shape group {name!r} is ignored: an earlier group has that name.")
            continue
        taken.add(name)
        binds = []
        for b in _list(g.get("binds")):
            mesh, index, weight = (b.get("mesh"), b.get("index"), b.get("weight", 100)) if isinstance(b, dict) \
                else (None, None, None)
            users = [i for i, n in enumerate(nodes) if isinstance(n, dict) and isinstance(mesh, int)
                     and not isinstance(mesh, bool) and n.get("mesh") == mesh]
            found = [bind for i in users if (bind := _bind(doc, i, index, weight, 100.0)) is not None]
            if not found:
                notes.append(f"VRM blend shape group {name!r}: a bind (mesh {mesh}, index {index}) names no morph "
                             "target; it is skipped.")
            binds += found
        out.append(Expression(name, preset is not None, tuple(binds), g.get("isBinary") is True, (),
                              len(_list(g.get("materialValues")))))
    return out


def _bind(doc: dict, node, index, weight, divisor: float) -> tuple[int, int, float] | None:
    """(node, slot, weight / divisor) when node draws a mesh with a target at index and weight is a finite number."""
    if not all(isinstance(x, int) and not isinstance(x, bool) for x in (node, index)):
        return None
    if not isinstance(weight, (int, float)) or isinstance(weight, bool) or not math.isfinite(weight):
        return None
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    n = nodes[node] if 0 <= node < len(nodes) and isinstance(nodes[node], dict) else {}
    m = n.get("mesh")
    mesh = meshes[m] if isinstance(m, int) and 0 <= m < len(meshes) and isinstance(meshes[m], dict) else {}
    prims = [p for p in _list(mesh.get("primitives")) if isinstance(p, dict)]
    count = len(_list(prims[0].get("targets"))) if prims else 0
    if not 0 <= index < count:
        return None
    return node, index, float(weight) / divisor


def _list(x) -> list:
    return x if isinstance(x, list) else []
