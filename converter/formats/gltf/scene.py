"""glTF 2.0 (.glb / .gltf) to FaceAnimation: node hierarchy, morph targets, animations, quantized and meshopt data.

Supported: TRS/matrix nodes, several meshes and primitives (triangles, strips, fans), morph targets (POSITION),
translation/rotation/scale/weights animation with LINEAR (slerp for rotations), STEP and CUBICSPLINE samplers,
COLOR_0 and baseColorFactor, sparse accessors, KHR_mesh_quantization and EXT_meshopt_compression. Texture and
material extensions are ignored (we draw flat base colours). Skinned meshes are refused for now.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from converter.animation import FaceAnimation
from converter.errors import InputError
from converter.formats.parts import collect_parts, part_name

DEFAULT_FPS = 30.0
MAX_FRAMES = 100_000
MAX_FRAME_FLOATS = 1 << 28  # 1 GiB of float32 vertex positions over all frames
MAX_DECODED_VIEW = 1 << 28  # bytes of one meshopt-decoded buffer view
MAX_ACCESSOR_COMPONENTS = 1 << 26  # numbers in one accessor (a 20M-vertex mesh); bounds what a tiny file can allocate

COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NORMALIZE_DIVISOR = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
INDEX_TYPES = (5121, 5123, 5125)
SUPPORTED_EXTENSIONS = {"KHR_mesh_quantization", "EXT_meshopt_compression"}
# Extensions that only change how textures or materials look: safe to ignore when we draw flat base colours.
IGNORABLE_EXTENSIONS = {
    "KHR_texture_transform", "KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif",
    "KHR_materials_variants", "KHR_lights_punctual", "EXT_lights_image_based",
}
IGNORABLE_PREFIXES = ("KHR_materials_",)
SKINNED = "skinned meshes are not supported yet; bake the skin to morph targets or a point cache"


def load_gltf(data: bytes, base_dir: Path, fps: float | None = None, name: str = "face") -> FaceAnimation:
    """Read a .glb or .gltf (bytes) into a FaceAnimation resampled at fps (default: the source's rate, else 30)."""
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps}.")
    try:
        with np.errstate(all="ignore"):
            doc, bin_chunk = parse_container(data, name)
            return _Document(doc, bin_chunk, Path(base_dir), name).animation(fps)
    except InputError:
        raise
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError, RecursionError,
            struct.error, RuntimeError, ZeroDivisionError, MemoryError) as exc:
        detail = f"{type(exc).__name__}: {exc}"[:120]
        raise InputError(f"{name}: the glTF file is malformed or truncated ({detail}); re-export it.") from None


def parse_container(data: bytes, name: str = "glTF") -> tuple[dict, memoryview | None]:
    """(JSON document, binary chunk or None) of a .glb or a .gltf JSON text."""
    if not data:
        raise InputError(f"{name} is empty; give a .glb or .gltf file.")
    bin_chunk = None
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise InputError(f"{name} is truncated: the .glb header is incomplete.")
        _, version, length = struct.unpack_from("<4sII", data)
        if version != 2:
            raise InputError(f"{name} is glTF version {version}; only glTF 2.0 is supported, re-export as glTF 2.0.")
        if length > len(data):
            raise InputError(f"{name} is truncated: the header says {length} bytes, the file has {len(data)}.")
        view = memoryview(data)
        pos, json_chunk = 12, None
        while pos + 8 <= length:
            clen, ctype = struct.unpack_from("<II", data, pos)
            pos += 8
            if pos + clen > length:
                raise InputError(f"{name} is truncated: a chunk runs past the end of the file.")
            if ctype == 0x4E4F534A and json_chunk is None:
                json_chunk = bytes(view[pos:pos + clen])
            elif ctype == 0x004E4942 and bin_chunk is None:
                bin_chunk = view[pos:pos + clen]
            pos += clen
        if json_chunk is None:
            raise InputError(f"{name} has no JSON chunk; the .glb is corrupt.")
        text = json_chunk
    else:
        text = data
    try:
        doc = json.loads(bytes(text).decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise InputError(f"{name}: the glTF JSON is garbled; re-export the file.") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        raise InputError(f"{name} is not a glTF document (no 'asset'); re-export it as glTF 2.0.")
    version = str(doc["asset"].get("version", ""))
    if not version.startswith("2"):
        raise InputError(f"{name} is glTF version {version or '?'}; only glTF 2.0 is supported.")
    return doc, bin_chunk


class _Document:
    """One parsed glTF with lazily loaded, cached buffers, views and accessors."""

    def __init__(self, doc: dict, bin_chunk: memoryview | None, base_dir: Path, name: str) -> None:
        self.doc, self.bin, self.base_dir, self.name = doc, bin_chunk, base_dir, name
        self._buffers: dict[int, memoryview] = {}
        self._views: dict[int, memoryview] = {}
        self._prims: dict[int, list[dict]] = {}
        required = doc.get("extensionsRequired") or []
        unsupported = [e for e in required if e not in SUPPORTED_EXTENSIONS and e not in IGNORABLE_EXTENSIONS
                       and not str(e).startswith(IGNORABLE_PREFIXES)]
        if unsupported:
            raise InputError(f"{name} requires the glTF extension {', '.join(map(str, unsupported))}, which facesvg "
                             "does not support; re-export without it (e.g. with gltfpack, or uncompressed).")

    def item(self, kind: str, index) -> dict:
        """The JSON object kind[index] (e.g. "nodes", 3), or InputError when it does not exist."""
        items = self.doc.get(kind) or []
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items):
            raise InputError(f"{self.name}: {kind[:-1]} {index!r} does not exist; the glTF is corrupt.")
        item = items[index]
        if not isinstance(item, dict):
            raise InputError(f"{self.name}: {kind[:-1]} {index} is not an object; the glTF is corrupt.")
        return item

    # -- bytes ---------------------------------------------------------------------------------------------
    def buffer(self, index: int) -> memoryview:
        """The bytes of buffer index: the .glb binary chunk, a data: URI, or a file next to the glTF."""
        if index in self._buffers:
            return self._buffers[index]
        buf = self.item("buffers", index)
        uri = buf.get("uri")
        if uri is None:
            if index != 0 or self.bin is None:
                raise InputError(f"{self.name}: buffer {index} has no data (no uri and no .glb binary chunk).")
            data = self.bin
        elif uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                raise InputError(f"{self.name}: buffer {index} has a data: URI that is not base64.")
            try:
                data = memoryview(base64.b64decode(payload, validate=True))
            except (binascii.Error, ValueError):
                raise InputError(f"{self.name}: buffer {index} has a garbled base64 data: URI.") from None
        else:
            data = memoryview(self._external(uri, index))
        if len(data) < int(buf.get("byteLength", 0)):
            raise InputError(f"{self.name}: buffer {index} is truncated ({len(data)} of {buf['byteLength']} bytes).")
        self._buffers[index] = data
        return data

    def _external(self, uri: str, index: int) -> bytes:
        """An external buffer file, refused when its path leaves base_dir."""
        rel = unquote(uri)
        if "://" in rel or rel.startswith(("/", "\\")) or (len(rel) > 1 and rel[1] == ":"):
            raise InputError(f"{self.name}: buffer {index} points to {uri!r}; only files next to the glTF are read.")
        root = self.base_dir.resolve()
        path = (root / rel).resolve()
        if not path.is_relative_to(root):
            raise InputError(f"{self.name}: buffer {index} points outside the glTF's folder ({uri!r}); refusing it.")
        try:
            return path.read_bytes()
        except OSError:
            raise InputError(f"{self.name}: external buffer {uri!r} is missing; put it next to the .gltf.") from None

    def view(self, index: int) -> memoryview:
        """The bytes of buffer view index, meshopt-decoded when compressed."""
        if index in self._views:
            return self._views[index]
        bv = self.item("bufferViews", index)
        ext = (bv.get("extensions") or {}).get("EXT_meshopt_compression")
        if ext is not None:
            data = self._meshopt(ext, index)
        else:
            buf = self.buffer(bv["buffer"])
            off, length = int(bv.get("byteOffset", 0)), int(bv["byteLength"])
            if off < 0 or length < 0 or off + length > len(buf):
                raise InputError(f"{self.name}: buffer view {index} runs past the end of its buffer; "
                                 "the file is truncated.")
            data = buf[off:off + length]
        self._views[index] = data
        return data

    def _meshopt(self, ext: dict, index: int) -> memoryview:
        """Decode one EXT_meshopt_compression buffer view with meshoptimizer's decoders."""
        import meshoptimizer as mo

        src_buf = self.buffer(ext["buffer"])
        off, length = int(ext.get("byteOffset", 0)), int(ext["byteLength"])
        count, stride = int(ext["count"]), int(ext["byteStride"])
        mode, filt = ext["mode"], ext.get("filter", "NONE")
        if off < 0 or length < 0 or off + length > len(src_buf):
            raise InputError(f"{self.name}: compressed buffer view {index} runs past its buffer; the file is truncated.")
        if count < 1 or stride < 1 or count * stride > MAX_DECODED_VIEW:
            raise InputError(f"{self.name}: compressed buffer view {index} has an invalid size.")
        src = np.frombuffer(src_buf[off:off + length], np.uint8)
        # The C decoders assert on these preconditions, so check them first rather than crash the process.
        try:
            if mode == "ATTRIBUTES":
                if stride % 4 or stride > 256:
                    raise InputError(f"{self.name}: compressed buffer view {index} has byteStride {stride} "
                                     "(needs a multiple of 4 up to 256).")
                decoded = np.ascontiguousarray(mo.decode_vertex_buffer(count, stride, src))
                out = decoded.view(np.uint8).reshape(count, stride)
            elif mode in ("TRIANGLES", "INDICES"):
                if stride not in (2, 4) or (mode == "TRIANGLES" and count % 3):
                    raise InputError(f"{self.name}: compressed index view {index} has an invalid count or stride.")
                decode = mo.decode_index_buffer if mode == "TRIANGLES" else mo.decode_index_sequence
                idx = decode(count, 4, src)
                if stride == 2 and idx.size and idx.max() > 0xFFFF:
                    raise InputError(f"{self.name}: compressed index view {index} does not fit 16 bits.")
                out = idx.astype("<u2" if stride == 2 else "<u4").view(np.uint8).reshape(count, stride)
            else:
                raise InputError(f"{self.name}: buffer view {index} uses unknown meshopt mode {mode!r}.")
        except RuntimeError:
            raise InputError(f"{self.name}: compressed buffer view {index} does not decode; "
                             "the file is corrupt.") from None
        if filt != "NONE":
            if mode != "ATTRIBUTES":
                raise InputError(f"{self.name}: buffer view {index} applies filter {filt} to indices.")
            checks = {"OCTAHEDRAL": stride in (4, 8), "QUATERNION": stride == 8, "EXPONENTIAL": stride % 4 == 0}
            if filt not in checks:
                raise InputError(f"{self.name}: buffer view {index} uses unknown meshopt filter {filt!r}.")
            if not checks[filt]:
                raise InputError(f"{self.name}: buffer view {index} has byteStride {stride}, invalid for filter {filt}.")
            fn = {"OCTAHEDRAL": mo.decode_filter_oct, "QUATERNION": mo.decode_filter_quat,
                  "EXPONENTIAL": mo.decode_filter_exp}[filt]
            out = fn(np.ascontiguousarray(out), count, stride)
        return memoryview(np.ascontiguousarray(out).reshape(-1).tobytes())

    # -- accessors ----------------------------------------------------------------------------------------
    def accessor(self, index: int, normalize: bool = True) -> np.ndarray:
        """Accessor data as (count, components) float64 (normalized integers mapped to [-1, 1] / [0, 1])."""
        acc = self.item("accessors", index)
        ctype = acc["componentType"]
        if ctype not in COMPONENT_DTYPES or acc.get("type") not in TYPE_COMPONENTS:
            raise InputError(f"{self.name}: accessor {index} has an unknown component type or type.")
        dtype = np.dtype(COMPONENT_DTYPES[ctype])
        nc = TYPE_COMPONENTS[acc["type"]]
        count = int(acc["count"])
        if count < 1 or count * nc > MAX_ACCESSOR_COMPONENTS:
            raise InputError(f"{self.name}: accessor {index} has an invalid count {count}.")
        if acc.get("bufferView") is not None:
            arr = self._strided(acc["bufferView"], int(acc.get("byteOffset", 0)), count, nc, dtype, index)
        else:
            arr = np.zeros((count, nc), dtype)
        sparse = acc.get("sparse")
        if sparse is not None:
            n = int(sparse["count"])
            if not 1 <= n <= count:
                raise InputError(f"{self.name}: sparse accessor {index} has an invalid count {n}.")
            ind, val = sparse["indices"], sparse["values"]
            if ind["componentType"] not in INDEX_TYPES:
                raise InputError(f"{self.name}: sparse accessor {index} has non-integer indices.")
            where = self._strided(ind["bufferView"], int(ind.get("byteOffset", 0)), n, 1,
                                  np.dtype(COMPONENT_DTYPES[ind["componentType"]]), index, packed=True)[:, 0]
            if where.max() >= count:
                raise InputError(f"{self.name}: sparse accessor {index} writes past its {count} elements.")
            arr = arr.copy()
            arr[where.astype(np.int64)] = self._strided(val["bufferView"], int(val.get("byteOffset", 0)), n, nc, dtype,
                                                        index, packed=True)
        if not normalize:
            return arr
        out = arr.astype(np.float64)
        if acc.get("normalized") and ctype in NORMALIZE_DIVISOR:
            out = np.maximum(out / NORMALIZE_DIVISOR[ctype], -1.0)
        return out

    def _strided(self, view_index: int, offset: int, count: int, nc: int, dtype: np.dtype, acc_index: int,
                 packed: bool = False) -> np.ndarray:
        """count rows of nc components from a buffer view, honouring its byteStride (unless packed)."""
        view = self.view(view_index)
        elem = dtype.itemsize * nc
        stride = elem if packed else int(self.item("bufferViews", view_index).get("byteStride") or elem)
        if offset < 0 or stride < elem or offset + stride * (count - 1) + elem > len(view):
            raise InputError(f"{self.name}: accessor {acc_index} reads past the end of its buffer view; the file is "
                             "truncated or corrupt.")
        return np.ndarray((count, nc), dtype, buffer=view, offset=offset, strides=(stride, dtype.itemsize)).copy()

    def indices(self, index: int) -> np.ndarray:
        """An index accessor as int64."""
        acc = self.item("accessors", index)
        if acc.get("componentType") not in INDEX_TYPES or acc.get("type") != "SCALAR":
            raise InputError(f"{self.name}: index accessor {index} is not unsigned integer scalars.")
        return self.accessor(index, normalize=False)[:, 0].astype(np.int64)

    # -- scene --------------------------------------------------------------------------------------------
    def scene_nodes(self) -> list[tuple[int, int]]:
        """(node, parent or -1) for every node of the default scene, parents first."""
        nodes = self.doc.get("nodes") or []
        scenes = self.doc.get("scenes") or []
        if scenes:
            scene = self.item("scenes", self.doc.get("scene", 0))
            roots = list(scene.get("nodes") or [])
        else:
            children = {c for n in nodes if isinstance(n, dict) for c in n.get("children") or []}
            roots = [i for i in range(len(nodes)) if i not in children]
        order, seen = [], set()
        stack = [(r, -1) for r in reversed(roots)]
        while stack:
            node, parent = stack.pop()
            if node in seen:
                raise InputError(f"{self.name}: node {node} appears twice in the node tree (a cycle); "
                                 "the file is corrupt.")
            self.item("nodes", node)
            seen.add(node)
            order.append((node, parent))
            stack.extend((c, node) for c in reversed(self.item("nodes", node).get("children") or []))
        return order

    def animation(self, fps: float | None) -> FaceAnimation:
        """The default scene's meshes posed at every frame of the first animation."""
        order = self.scene_nodes()
        instances = self.mesh_instances(order)
        tracks, anim_name = self.tracks()
        all_times = [t for t, _, _ in tracks.values()]
        source_fps = keyframe_rate(all_times)
        out_fps = float(fps) if fps else (source_fps or DEFAULT_FPS)
        t_end = max((float(t[-1]) for t in all_times), default=0.0)
        # Key times are float32: a time within 1/1000 of a frame still makes that frame.
        n_frames = int(math.floor(max(t_end, 0.0) * out_fps + 1e-3)) + 1
        if n_frames > MAX_FRAMES:
            raise InputError(f"{self.name}: the animation lasts {t_end:.0f} s, too long to convert; trim it.")
        n_vertices = sum(len(p["positions"]) for *_, prims in instances for p in prims)
        if n_frames * n_vertices * 3 > MAX_FRAME_FLOATS:
            raise InputError(f"{self.name}: {n_vertices} vertices x {n_frames} frames is too much to convert; "
                             "lower --fps or trim the animation.")
        t = np.arange(n_frames) / out_fps
        world: dict[int, np.ndarray] = {}
        for node, parent in order:
            local = self.local_matrix(node, tracks, t)
            world[node] = local if parent < 0 else world[parent] @ local

        frames = np.empty((n_frames, n_vertices, 3), np.float32)
        faces, keys, key_of_face, colors = [], [], [], []
        morph_names: list[str] = []
        morph_count = offset = 0
        for node_index, node, mesh, prims in instances:
            k = prims[0]["deltas"].shape[0]
            weights = self.weights(node_index, node, mesh, k, tracks, t)
            morph_count += k
            names = ((mesh.get("extras") or {}).get("targetNames") or []) if k else []
            morph_names += [str(n) for n in names if str(n) not in morph_names]
            m = world[node_index]
            for p in prims:
                v = p["positions"]
                local = v[None]
                if k:
                    # einsum, not @: a small product through multithreaded BLAS is 100x slower on a busy machine.
                    local = local + np.einsum("tk,kvc->tvc", weights, p["deltas"])
                frames[:, offset:offset + len(v)] = local @ np.swapaxes(m[:, :3, :3], 1, 2) + m[:, None, :3, 3]
                faces.append(p["faces"] + offset)
                material = self.item("materials", p["material"]) if p["material"] is not None else {}
                keys.append((part_name(material.get("name"), mesh.get("name"), node.get("name")),
                             self.base_color(material)))
                key_of_face.append(np.full(len(p["faces"]), len(keys) - 1, np.int32))
                colors.append(np.ones((len(v), 3), np.float32) if p["colors"] is None else p["colors"])
                offset += len(v)
        parts, part_of_key = collect_parts(keys)
        has_colors = any(p["colors"] is not None for *_, prims in instances for p in prims)
        extras = {
            "morph_targets": morph_names if morph_names else morph_count,
            "animated_nodes": sorted({self.node_label(n) for (n, path) in tracks if path != "weights"}),
            "morph_animated_nodes": sorted({self.node_label(n) for (n, path) in tracks if path == "weights"}),
            "source_fps": source_fps,
            "animation": anim_name,
        }
        return FaceAnimation(
            frames=frames,
            faces=np.concatenate(faces).astype(np.int32),
            part_ids=part_of_key[np.concatenate(key_of_face)],
            parts=parts,
            fps=out_fps,
            name=self.name,
            vertex_colors=np.concatenate(colors) if has_colors else None,
            extras=extras,
        )

    def mesh_instances(self, order: list[tuple[int, int]]) -> list[tuple[int, dict, dict, list[dict]]]:
        """(node index, node, mesh, triangle primitives) for every node that draws a mesh."""
        out = []
        for index, _ in order:
            node = self.item("nodes", index)
            if node.get("mesh") is None:
                continue
            if node.get("skin") is not None:
                raise InputError(f"{self.name}: {SKINNED}.")
            prims = self.primitives(node["mesh"])
            if prims:
                if len({p["deltas"].shape[0] for p in prims}) != 1:
                    raise InputError(f"{self.name}: primitives of mesh {node['mesh']} have different "
                                     "morph target counts.")
                out.append((index, node, self.item("meshes", node["mesh"]), prims))
        if not any(self.item("nodes", n).get("mesh") is not None for n, _ in order):
            raise InputError(f"{self.name} has no mesh in its scene; export the face geometry too.")
        if not out:
            raise InputError(f"{self.name} has no triangles; export the mesh as triangles.")
        return out

    def node_label(self, index: int) -> str:
        """A node's name, or node<index>."""
        return str(self.item("nodes", index).get("name") or f"node{index}")

    def base_color(self, material: dict) -> tuple[float, float, float] | None:
        """The material's baseColorFactor rgb, or None to use the part's default colour."""
        pbr = material.get("pbrMetallicRoughness") or {}
        factor = pbr.get("baseColorFactor")
        if factor is None:
            return None  # untextured default white would be meaningless for a face: use the part's colour
        rgb = tuple(float(np.clip(c, 0.0, 1.0)) for c in list(factor)[:3])
        if len(rgb) != 3:
            raise InputError(f"{self.name}: a material's baseColorFactor needs 4 numbers.")
        if pbr.get("baseColorTexture") is not None and rgb == (1.0, 1.0, 1.0):
            return None  # the colour lives in a texture we do not sample
        return rgb  # type: ignore[return-value]

    def primitives(self, mesh_index: int) -> list[dict]:
        """A mesh's triangle primitives: positions, faces, morph deltas, colours, material (cached per mesh)."""
        cache = self._prims
        if mesh_index in cache:
            return cache[mesh_index]
        mesh = self.item("meshes", mesh_index)
        out = []
        for p in mesh.get("primitives") or []:
            mode = p.get("mode", 4)
            if mode not in (4, 5, 6):
                continue  # points and lines draw nothing in a face
            attrs = p.get("attributes") or {}
            if "POSITION" not in attrs:
                raise InputError(f"{self.name}: a primitive of mesh {mesh_index} has no POSITION attribute.")
            pos = self.accessor(attrs["POSITION"])
            if pos.shape[1] != 3:
                raise InputError(f"{self.name}: POSITION of mesh {mesh_index} is not VEC3.")
            idx = self.indices(p["indices"]) if p.get("indices") is not None else np.arange(len(pos))
            if idx.size and idx.max() >= len(pos):
                raise InputError(f"{self.name}: mesh {mesh_index} has an index past its {len(pos)} vertices.")
            tris = triangles(idx, mode)
            if len(tris) == 0:
                continue
            targets = p.get("targets") or []
            deltas = np.zeros((len(targets), len(pos), 3))
            for i, target in enumerate(targets):
                if target.get("POSITION") is not None:
                    d = self.accessor(target["POSITION"])
                    if d.shape != (len(pos), 3):
                        raise InputError(f"{self.name}: morph target {i} of mesh {mesh_index} does not "
                                         "match its vertices.")
                    deltas[i] = d
            colors = None
            if attrs.get("COLOR_0") is not None:
                c = self.accessor(attrs["COLOR_0"])
                if c.shape[0] != len(pos) or c.shape[1] not in (3, 4):
                    raise InputError(f"{self.name}: COLOR_0 of mesh {mesh_index} does not match its vertices.")
                colors = np.clip(c[:, :3], 0, 1).astype(np.float32)
            used = np.unique(tris)
            if len(used) < len(pos):
                # Primitives often share one vertex buffer per mesh: keep only this one's vertices.
                remap = np.zeros(len(pos), np.int64)
                remap[used] = np.arange(len(used))
                pos, deltas, tris = pos[used], deltas[:, used], remap[tris]
                colors = None if colors is None else colors[used]
            out.append({"positions": pos, "faces": tris, "deltas": deltas, "colors": colors,
                        "material": p.get("material")})
        cache[mesh_index] = out
        return out

    def tracks(self) -> tuple[dict[tuple[int, str], tuple[np.ndarray, np.ndarray, str]], str | None]:
        """The first animation's channels: (node, path) -> (times, values (keys, C), interpolation)."""
        anims = self.doc.get("animations") or []
        if not anims:
            return {}, None
        anim = anims[0]
        samplers = anim.get("samplers") or []
        out = {}
        for ch in anim.get("channels") or []:
            target = ch.get("target") or {}
            path, node = target.get("path"), target.get("node")
            if path not in ("translation", "rotation", "scale", "weights") or node is None:
                continue  # e.g. KHR_animation_pointer targets: nothing we draw
            self.item("nodes", node)
            s = ch["sampler"]
            if not isinstance(s, int) or not 0 <= s < len(samplers):
                raise InputError(f"{self.name}: an animation channel refers to missing sampler {s!r}.")
            sampler = samplers[s]
            interp = sampler.get("interpolation", "LINEAR")
            if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
                raise InputError(f"{self.name}: unknown animation interpolation {interp!r}.")
            times = self.accessor(sampler["input"])[:, 0]
            if not np.isfinite(times).all() or np.any(np.diff(times) < 0):
                raise InputError(f"{self.name}: animation key times are not increasing finite numbers; re-export.")
            values = self.accessor(sampler["output"])
            width = {"translation": 3, "rotation": 4, "scale": 3}.get(path)
            if width is not None and values.shape[1] != width:
                raise InputError(f"{self.name}: a {path} track has {values.shape[1]} components instead of {width}.")
            keys = len(times) * (3 if interp == "CUBICSPLINE" else 1)
            if path == "weights":
                if values.shape[1] != 1 or len(values) % keys:
                    raise InputError(f"{self.name}: a weights track does not hold whole keyframes.")
                values = values.reshape(keys, -1)
            elif len(values) != keys:
                raise InputError(f"{self.name}: a {path} track has {len(values)} values for {len(times)} key times.")
            out[(node, path)] = (times, values, interp)
        return out, anim.get("name")

    def local_matrix(self, index: int, tracks: dict, t: np.ndarray) -> np.ndarray:
        """(T or 1, 4, 4) local transform of a node over the frame times."""
        node = self.item("nodes", index)
        if node.get("matrix") is not None:
            m = np.asarray(node["matrix"], np.float64)
            if m.shape != (16,):
                raise InputError(f"{self.name}: node {index} has a matrix that is not 16 numbers.")
            return m.reshape(1, 4, 4).transpose(0, 2, 1)  # glTF stores column-major
        trs = {}
        for path, default in (("translation", (0, 0, 0)), ("rotation", (0, 0, 0, 1)), ("scale", (1, 1, 1))):
            if (index, path) in tracks:
                times, values, interp = tracks[(index, path)]
                trs[path] = sample(times, values, interp, t, rotation=path == "rotation")
            else:
                value = np.asarray(node.get(path, default), np.float64)
                if value.shape != (len(default),):
                    raise InputError(f"{self.name}: node {index} has a malformed {path}.")
                trs[path] = value[None]
        return trs_matrices(trs["translation"], trs["rotation"], trs["scale"])

    def weights(self, index: int, node: dict, mesh: dict, k: int, tracks: dict, t: np.ndarray) -> np.ndarray:
        """(T or 1, K) morph weights of a mesh instance."""
        if (index, "weights") in tracks:
            times, values, interp = tracks[(index, "weights")]
            if values.shape[1] != k:
                raise InputError(f"{self.name}: a weights track has {values.shape[1]} weights, "
                                 f"the mesh has {k} targets.")
            return sample(times, values, interp, t)
        w = node.get("weights", mesh.get("weights"))
        w = np.zeros(k) if w is None else np.asarray(w, np.float64)
        if w.shape != (k,):
            raise InputError(f"{self.name}: default morph weights ({w.size}) do not match the {k} morph targets.")
        return w[None]


def triangles(idx: np.ndarray, mode: int) -> np.ndarray:
    """(F, 3) triangles from an index list in primitive mode 4 (list), 5 (strip) or 6 (fan)."""
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    n = len(idx) - 2
    if n <= 0:
        return np.zeros((0, 3), np.int64)
    k = np.arange(n)
    if mode == 5:
        odd = k % 2 == 1  # odd strip triangles swap two corners to keep the winding
        return np.stack([idx[k], np.where(odd, idx[k + 2], idx[k + 1]), np.where(odd, idx[k + 1], idx[k + 2])], 1)
    return np.stack([np.full(n, idx[0]), idx[k + 1], idx[k + 2]], 1)


def sample(times: np.ndarray, values: np.ndarray, interp: str, t: np.ndarray, rotation: bool = False) -> np.ndarray:
    """A glTF sampler evaluated at times t, clamped outside its keys: (len(t), C)."""
    n = len(times)
    if interp == "CUBICSPLINE":
        v = values.reshape(n, 3, -1)
        a, p, b = v[:, 0], v[:, 1], v[:, 2]
    else:
        p = values
    if rotation:
        p = p / np.linalg.norm(p, axis=1, keepdims=True)
    if n == 1:
        return np.repeat(p[:1], len(t), axis=0)
    # Keys are float32: a key at 0.3 s is stored as 0.30000001, so snap sample times within float32 error.
    after = np.searchsorted(times, t + np.maximum(1e-6, np.abs(t) * 1e-6), side="right") - 1
    if interp == "STEP":
        return p[np.clip(after, 0, n - 1)]
    k = np.clip(after, 0, n - 2)
    dt = times[k + 1] - times[k]
    u = np.clip(np.where(dt > 0, (t - times[k]) / np.where(dt > 0, dt, 1.0), 1.0), 0.0, 1.0)[:, None]
    if interp == "LINEAR":
        if rotation:
            return slerp(p[k], p[k + 1], u)
        return p[k] * (1 - u) + p[k + 1] * u
    u2, u3, d = u * u, u * u * u, dt[:, None]
    out = ((2 * u3 - 3 * u2 + 1) * p[k] + (u3 - 2 * u2 + u) * d * b[k]
           + (-2 * u3 + 3 * u2) * p[k + 1] + (u3 - u2) * d * a[k + 1])
    if rotation:
        out = out / np.linalg.norm(out, axis=1, keepdims=True)
    return out


def slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions along the shorter arc, rows (x, y, z, w)."""
    d = np.sum(q0 * q1, axis=1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    near = s < 1e-6
    safe = np.where(near, 1.0, s)
    w0 = np.where(near, 1 - u, np.sin((1 - u) * theta) / safe)
    w1 = np.where(near, u, np.sin(u * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def trs_matrices(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(N, 4, 4) matrices T * R * S from broadcastable (N|1, 3) translations, (x, y, z, w) quaternions, scales."""
    n = max(len(t), len(q), len(s))
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = (np.broadcast_to(q[:, i], (n,)) for i in range(4))
    r = np.empty((n, 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = r * np.broadcast_to(s, (n, 3))[:, None, :]
    m[:, :3, 3] = np.broadcast_to(t, (n, 3))
    m[:, 3, 3] = 1.0
    return m


def keyframe_rate(all_times: list[np.ndarray]) -> float | None:
    """The frame rate keys were baked at when evident (every gap a whole number of one step, 12..240 fps)."""
    if not all_times:
        return None
    times = np.unique(np.concatenate(all_times))
    if len(times) < 3:
        return None
    gaps = np.diff(times)
    step = gaps.min()
    if step <= 0:
        return None
    ratio = gaps / step
    if np.abs(ratio - np.round(ratio)).max() > 1e-3:
        return None
    rate = 1.0 / step
    if not 12.0 <= rate <= 240.0:
        return None
    whole = round(rate)
    return float(whole) if abs(rate - whole) < 1e-3 * rate else round(rate, 3)
