"""Morph target names of a glTF mesh, wherever exporters put them.

glTF 2.0 has no field for them; tools agree on `mesh.extras.targetNames` (the spec's implementation note, Blender,
three.js, Babylon, FBX2glTF, UniVRM 1.0). UniVRM 0.x (VRM 0.x avatars, VRoid Studio's 0.x exports) wrote them per
primitive, `primitives[i].extras.targetNames`; UniVRM before 0.36 wrote one per target,
`primitives[i].targets[k].extra.name` (sic: `extra`; its 0.36 notes moved them because glTF allows no extras on a
target), which some tools spell `extras`. The scene reader (animation, framing) and the morph-face reader both read
them here.
"""

from __future__ import annotations


def target_names(mesh: dict, count: int | None = None) -> list[str]:
    """The name of each of a mesh's morph targets ("" where unnamed): mesh.extras.targetNames, else the first
    primitive's extras.targetNames that names any, else per-target extras names; count entries (default: the first
    primitive with targets has)."""
    prims = [p for p in (mesh.get("primitives") or []) if isinstance(p, dict)] if isinstance(mesh, dict) else []
    if count is None:
        count = next((len(p["targets"]) for p in prims if isinstance(p.get("targets"), list) and p["targets"]), 0)
    if not count:
        return []
    sources = [_listed(mesh)] + [_listed(p) for p in prims] + [_per_target(p) for p in prims]
    chosen = next((s for s in sources if any(s)), [])
    return (chosen + [""] * count)[:count]


def _listed(owner: dict) -> list[str]:
    extras = owner.get("extras")
    names = extras.get("targetNames") if isinstance(extras, dict) else None
    return [n if isinstance(n, str) else "" if n is None else str(n) for n in names] if isinstance(names, list) else []


def _per_target(prim: dict) -> list[str]:
    targets = prim.get("targets")
    if not isinstance(targets, list):
        return []
    out = []
    for t in targets:
        name = ""
        for key in ("extras", "extra"):
            extras = t.get(key) if isinstance(t, dict) else None
            if isinstance(extras, dict) and isinstance(extras.get("name"), str):
                name = extras["name"]
                break
        out.append(name)
    return out
