"""Key-model pairs for example-based cloning, read from a zip: manifest.json plus OBJ meshes.

manifest.json:
    {"keys": [{"name": "smile", "source": "src/smile.obj", "target": "tgt/smile.obj",
               "kind": "emotional" | "verbal" | "other"}, ...],
     "base": {"source": "src/neutral.obj", "target": "tgt/neutral.obj"},   (optional: else frame 0 of each)
     "feature_points": [source vertex ids]}                                (optional: else picked automatically)
Every OBJ keeps its base's vertex order (only `v` lines are read).
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

from converter.cloning.example_based import KeyPairs
from converter.errors import InputError
from converter.formats.obj import parse_obj_vertices
from converter.userfiles import read_bytes

KINDS = ("emotional", "verbal", "other")


def read(path: str | Path, source_base: np.ndarray, target_base: np.ndarray) -> KeyPairs:
    """KeyPairs from a zip file; source_base / target_base are used when the manifest names no base."""
    path = Path(path)
    raw = read_bytes(path, "key-model file")
    try:
        zf = zipfile.ZipFile(io.BytesIO(raw))
    except (zipfile.BadZipFile, OSError):
        raise InputError(
            f"{path.name} is not a zip file; pack manifest.json and the key-model OBJs into a zip."
        ) from None
    with zf:
        try:
            manifest = json.loads(zf.read("manifest.json"))
        except KeyError:
            raise InputError(f"{path.name} has no manifest.json; add one listing the key-model pairs.") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"manifest.json in {path.name} is not valid JSON ({exc}).") from None
        keys = manifest.get("keys") if isinstance(manifest, dict) else None
        if not isinstance(keys, list) or not keys:
            raise InputError(f"manifest.json in {path.name} lists no \"keys\"; add at least one key-model pair.")

        def mesh(name: object, expected: int, what: str) -> np.ndarray:
            if not isinstance(name, str):
                raise InputError(f"{what} in manifest.json must be a file name inside the zip.")
            try:
                text = zf.read(name).decode("utf-8", "replace")
            except KeyError:
                raise InputError(f"{what} {name!r} is named in manifest.json but missing from {path.name}.") from None
            v = parse_obj_vertices(text, name)
            if len(v) != expected:
                raise InputError(f"{what} {name} has {len(v)} vertices but its base has {expected}; key-models "
                                 "must be deformed copies of their base with the same vertex order.")
            return v.astype(np.float64)

        base = manifest.get("base") or {}
        if not isinstance(base, dict):
            raise InputError("\"base\" in manifest.json must be {\"source\": file, \"target\": file}.")
        s_base = mesh(base["source"], len(source_base), "source base") if "source" in base else source_base
        t_base = mesh(base["target"], len(target_base), "target base") if "target" in base else target_base
        if len(s_base) != len(source_base):
            raise InputError("the key-models' source base does not match the animation's vertex count.")
        src, tgt, names, kinds = [], [], [], []
        for i, k in enumerate(keys):
            if not isinstance(k, dict) or "source" not in k or "target" not in k:
                raise InputError(f"key {i} in manifest.json needs \"source\" and \"target\" file names.")
            kind = k.get("kind", "other")
            if kind not in KINDS:
                raise InputError(f"key {i} has kind {kind!r}; use one of {', '.join(KINDS)}.")
            src.append(mesh(k["source"], len(s_base), f"source key {i}"))
            tgt.append(mesh(k["target"], len(t_base), f"target key {i}"))
            names.append(str(k.get("name", f"key{i}")))
            kinds.append(kind)
        fp = manifest.get("feature_points")
        ids = None
        if fp is not None:
            ids = np.asarray(fp)
            if ids.ndim != 1 or not len(ids) or ids.dtype.kind not in "iu" or ids.min() < 0 or ids.max() >= len(s_base):
                raise InputError(f"feature_points must be source vertex ids in 0..{len(s_base) - 1}.")
    return KeyPairs(np.asarray(s_base, np.float64), np.asarray(t_base, np.float64), np.stack(src), np.stack(tgt),
                    tuple(names), tuple(kinds), ids)


def write(path: str | Path, pairs: KeyPairs, source_faces: np.ndarray | None = None,
          target_faces: np.ndarray | None = None) -> None:
    """Write KeyPairs as a zip (for tests, benchmarks and users preparing keys); deterministic bytes."""

    def obj(v: np.ndarray, faces: np.ndarray | None) -> bytes:
        lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
        if faces is not None:
            lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
        return ("\n".join(lines) + "\n").encode()

    entries = {"base/source.obj": obj(pairs.source_base, source_faces),
               "base/target.obj": obj(pairs.target_base, target_faces)}
    keys = []
    for i, name in enumerate(pairs.names):
        s, t = f"source/{i:03d}.obj", f"target/{i:03d}.obj"
        entries[s], entries[t] = obj(pairs.source[i], source_faces), obj(pairs.target[i], target_faces)
        keys.append({"name": name, "source": s, "target": t, "kind": pairs.kinds[i]})
    manifest = {"keys": keys, "base": {"source": "base/source.obj", "target": "base/target.obj"}}
    if pairs.feature_ids is not None:
        manifest["feature_points"] = [int(i) for i in pairs.feature_ids]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in [("manifest.json", json.dumps(manifest, indent=1).encode())] + list(entries.items()):
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, data)
