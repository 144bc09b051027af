"""glTF scene to FaceAnimation: node hierarchy, meshes and primitives, morph targets, animation channels.

Supported: TRS/matrix nodes, several meshes and primitives (triangles, strips, fans; one Part each, labelled
node/material), morph targets (POSITION), translation/rotation/scale/weights animation (sampling.py), COLOR_0,
baseColorFactor and base-colour textures (linear or sRGB, converted to display values: _Document.part).
Bytes, accessors and meshopt decoding live in container.py, accessors.py and meshopt.py; clip choice in clips.py;
skinning in skin.py.
Material extensions and KHR_texture_transform are ignored.
"""

from __future__ import annotations

import base64
import binascii
import math
import struct
from pathlib import Path

import numpy as np

from converter.animation import DEFAULT_PART_COLORS, FaceAnimation, Part
from converter.errors import InputError
from converter.formats.gltf.accessors import Accessors
from converter.formats.gltf.clips import Tracks, choose, clip_label, summaries
from converter.formats.gltf.container import parse_container
from converter.formats.gltf.names import target_names
from converter.formats.gltf.sampling import keyframe_rate, sample, trs_matrices
from converter.formats.gltf.skin import check_joint_indices, influences, joint_matrices, skin_positions
from converter.formats.gltf.textures import decode_image, sample_texture
from converter.formats.gltf.vrm import read_expressions
from converter.formats.parts import part_name
from converter.srgb import linear_to_srgb

DEFAULT_FPS = 30.0
MAX_FRAMES = 100_000
MAX_FRAME_FLOATS = 1 << 28  # 1 GiB of float32 vertex positions over all frames


def load_gltf(data: bytes, base_dir: Path, fps: float | None = None, name: str = "face",
              animation: str | None = None) -> FaceAnimation:
    """Read a .glb or .gltf (bytes) into a FaceAnimation resampled at fps (default: the source's rate, else 30).

    animation picks the clip: a name, an index, "all", or None for the first take (see clips.py).
    """
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps}.")
    try:
        with np.errstate(all="ignore"):
            doc, bin_chunk = parse_container(data, name)
            return _Document(doc, bin_chunk, Path(base_dir), name).animation(fps, animation)
    except InputError:
        raise
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError, RecursionError,
            struct.error, RuntimeError, ZeroDivisionError, MemoryError) as exc:
        detail = f"{type(exc).__name__}: {exc}"[:120]
        raise InputError(f"{name}: the glTF file is malformed or truncated ({detail}); re-export it.") from None


class _Document(Accessors):
    """One parsed glTF: its default scene posed over the frames of an animation."""

    def __init__(self, doc: dict, bin_chunk: memoryview | None, base_dir: Path, name: str) -> None:
        super().__init__(doc, bin_chunk, base_dir, name)
        self._prims: dict[int, list[dict]] = {}
        self._parents: dict[int, int] | None = None
        self._images: dict[int, np.ndarray | None] = {}
        self.notes: list[str] = []  # for Report.warnings: what the loader could not honour

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

    def animation(self, fps: float | None, choice: str | None = None) -> FaceAnimation:
        """The default scene's meshes posed at every frame of the chosen animations (None: the first take)."""
        order = self.scene_nodes()
        instances = self.mesh_instances(order)
        anims = self.doc.get("animations") or []
        clips = [self.clip(j) for j in range(len(anims))]
        clip_names = [None if a.get("name") is None else str(a["name"]) for a in anims]
        chosen, notes = choose(clips, clip_names, choice, self.name)
        played = [{key: track for j in take for key, track in clips[j].items()} for take in chosen]
        all_times = [t for tracks in played for t, _, _ in tracks.values()]
        source_fps = keyframe_rate(all_times)
        out_fps = float(fps) if fps else (source_fps or DEFAULT_FPS)
        ends = [max((float(t[-1]) for t, _, _ in tracks.values()), default=0.0) for tracks in played]
        # Key times are float32: a time within 1/1000 of a frame still makes that frame.
        counts = [int(math.floor(max(end, 0.0) * out_fps + 1e-3)) + 1 for end in ends]
        if sum(counts) > MAX_FRAMES:
            raise InputError(f"{self.name}: the animation lasts {sum(ends):.0f} s, too long to convert; trim it.")
        n_vertices = sum(len(p["positions"]) for *_, prims in instances for p in prims)
        if sum(counts) * n_vertices * 3 > MAX_FRAME_FLOATS:
            raise InputError(f"{self.name}: {n_vertices} vertices x {sum(counts)} frames is too much to convert; "
                             "lower --fps or trim the animation.")
        frames = np.concatenate([self.pose(order, instances, n_vertices, tracks, np.arange(n) / out_fps)
                                 for tracks, n in zip(played, counts)])
        faces, parts, part_of_face, colors = [], [], [], []
        morph_names: list[str] = []
        morph_count = offset = 0
        for node_index, node, mesh, prims in instances:
            k = prims[0]["deltas"].shape[0]
            morph_count += k
            names = target_names(mesh, k) if k else []
            morph_names += [n for n in names if n and n not in morph_names]
            for j, p in enumerate(prims):
                faces.append(p["faces"] + offset)
                part, own = self.part(node_index, node, mesh, j, p)
                parts.append(part)
                part_of_face.append(np.full(len(p["faces"]), len(parts) - 1, np.int32))
                colors.append(np.ones((len(p["positions"]), 3), np.float32) if own is None else own)
                offset += len(p["positions"])
        has_colors = any(p["colors"] is not None or p["texture_colors"] is not None
                         for *_, prims in instances for p in prims)
        flat = [j for take in chosen for j in take]
        extras = {
            **self.node_index(order, instances),
            "morph_targets": morph_names if morph_names else morph_count,
            "animated_nodes": sorted({self.node_label(n) for tracks in played for (n, path) in tracks
                                      if path != "weights"}),
            "morph_animated_nodes": sorted({self.node_label(n) for tracks in played for (n, path) in tracks
                                            if path == "weights"}),
            "source_fps": source_fps,
            "skinned_meshes": sum(1 for _, node, _, _ in instances if node.get("skin") is not None),
            "animation": (clip_names[flat[0]] if len(flat) == 1 else
                          " + ".join(clip_label(j, clip_names[j]) for j in flat) or None),
            "animations": summaries(clips, clip_names, self.node_label),
        }
        if notes or self.notes:
            extras["warnings"] = notes + self.notes
        return FaceAnimation(
            frames=frames,
            faces=np.concatenate(faces).astype(np.int32),
            part_ids=np.concatenate(part_of_face),
            parts=tuple(parts),
            fps=out_fps,
            name=self.name,
            vertex_colors=np.concatenate(colors) if has_colors else None,
            extras=extras,
        )

    def node_index(self, order: list[tuple[int, int]], instances: list) -> dict:
        """What framing reads: the scene's node tree and the node each vertex comes from, plus the VRM version."""
        position = {node: i for i, (node, _) in enumerate(order)}
        tree = []
        for node, parent in order:
            mesh_index = self.item("nodes", node).get("mesh")
            mesh = self.item("meshes", mesh_index) if mesh_index is not None else {}
            targets = tuple(n for n in target_names(mesh) if n)
            tree.append((self.node_label(node), position.get(parent, -1), str(mesh.get("name") or ""), targets))
        counts = [sum(len(p["positions"]) for p in prims) for *_, prims in instances]
        of_vertex = np.repeat(np.array([position[i] for i, *_ in instances], np.int32), counts)
        joint_of_vertex = []  # the scene node of each vertex's strongest joint, -1 when unskinned or outside
        for _, node, _, prims in instances:
            joint_nodes = self.skin(node["skin"])[0] if node.get("skin") is not None else []
            where = np.array([position.get(j, -1) for j in joint_nodes] + [-1], np.int32)
            for p in prims:
                if not joint_nodes:
                    joint_of_vertex.append(np.full(len(p["positions"]), -1, np.int32))
                    continue
                strongest = p["joints"][np.arange(len(p["joints"])), np.argmax(p["weights"], axis=1)]
                joint_of_vertex.append(where[np.clip(strongest, 0, len(joint_nodes))])
        extensions = self.doc.get("extensions") or {}
        vrm = "0.x" if "VRM" in extensions else "1.0" if "VRMC_vrm" in extensions else None
        # what a weight capture can drive (`facesvg info` prints lists): expressions, and those with material binds
        expressions = read_expressions(self.doc)[0] if vrm else []
        shown = {"vrm_expressions": [e.name for e in expressions]} if expressions else {}
        if any(e.material_binds for e in expressions):
            shown["vrm_material_binds_not_drawn"] = [e.name for e in expressions if e.material_binds]
        # tuples and arrays: `info` prints only plain lists and dicts
        return {"node_tree": tuple(tree), "node_of_vertex": of_vertex, "joint_of_vertex": np.concatenate(
            joint_of_vertex), **({"vrm": vrm} if vrm else {}), **shown}

    def pose(self, order: list[tuple[int, int]], instances: list, n_vertices: int, tracks: Tracks,
             t: np.ndarray) -> np.ndarray:
        """(len(t), V, 3) world positions of every mesh instance's vertices at times t under one take's tracks."""
        world: dict[int, np.ndarray] = {}
        for node, parent in order:
            local = self.local_matrix(node, tracks, t)
            world[node] = local if parent < 0 else world[parent] @ local
        frames = np.empty((len(t), n_vertices, 3), np.float32)
        offset = 0
        for node_index, node, mesh, prims in instances:
            k = prims[0]["deltas"].shape[0]
            weights = self.weights(node_index, node, mesh, k, tracks, t)
            m = world[node_index]
            if node.get("skin") is not None:
                joint_nodes, inverse_bind = self.skin(node["skin"])
                matrices = joint_matrices([self.world_of(j, world, tracks, t) for j in joint_nodes], inverse_bind,
                                          len(t))
            for p in prims:
                v = p["positions"]
                local = v[None]
                if k:
                    # einsum, not @: a small product through multithreaded BLAS is far slower on a busy machine.
                    local = local + np.einsum("tk,kvc->tvc", weights, p["deltas"])
                if node.get("skin") is not None:  # the node's own transform is ignored (glTF 2.0, skins)
                    check_joint_indices(p["joints"], p["weights"], len(joint_nodes), self.name,
                                        self.node_label(node_index))
                    frames[:, offset:offset + len(v)] = skin_positions(local, p["joints"], p["weights"], matrices)
                else:
                    frames[:, offset:offset + len(v)] = local @ np.swapaxes(m[:, :3, :3], 1, 2) + m[:, None, :3, 3]
                offset += len(v)
        return frames

    def world_of(self, index: int, world: dict[int, np.ndarray], tracks: Tracks, t: np.ndarray) -> np.ndarray:
        """A node's global transform (T or 1, 4, 4), also for a joint outside the default scene's tree."""
        chain: list[int] = []  # index and its ancestors not yet in world, child first
        node: int | None = index
        while node is not None and node not in world:
            if node in chain:
                raise InputError(f"{self.name}: node {node} is its own ancestor (a cycle); the file is corrupt.")
            chain.append(node)
            node = self.parents().get(node)
        m = None if node is None else world[node]
        for n in reversed(chain):
            local = self.local_matrix(n, tracks, t)
            m = local if m is None else m @ local
            world[n] = m
        return world[index]

    def parents(self) -> dict[int, int]:
        """Parent of every child node in the document (cached)."""
        if self._parents is None:
            self._parents = {c: i for i, n in enumerate(self.doc.get("nodes") or []) if isinstance(n, dict)
                             for c in n.get("children") or [] if isinstance(c, int)}
        return self._parents

    def skin(self, index: int) -> tuple[list[int], np.ndarray]:
        """(joint node indices, inverse bind matrices (J, 4, 4)) of skin index; identity matrices when absent."""
        skin = self.item("skins", index)
        joints = skin.get("joints") or []
        if not joints:
            raise InputError(f"{self.name}: skin {index} has no joints; re-export the rig.")
        for j in joints:
            self.item("nodes", j)
        if skin.get("inverseBindMatrices") is None:
            return list(joints), np.broadcast_to(np.eye(4), (len(joints), 4, 4))
        ibm = self.accessor(skin["inverseBindMatrices"])
        if ibm.shape[1] != 16 or len(ibm) < len(joints):
            raise InputError(f"{self.name}: skin {index} has {len(ibm)} inverse bind matrices for {len(joints)} "
                             "joints; re-export the rig.")
        return list(joints), ibm[:len(joints)].reshape(-1, 4, 4).transpose(0, 2, 1)  # glTF stores column-major

    def mesh_instances(self, order: list[tuple[int, int]]) -> list[tuple[int, dict, dict, list[dict]]]:
        """(node index, node, mesh, triangle primitives) for every node that draws a mesh."""
        out = []
        for index, _ in order:
            node = self.item("nodes", index)
            if node.get("mesh") is None:
                continue
            prims = self.primitives(node["mesh"])
            if node.get("skin") is not None:
                self.skin(node["skin"])
                if any(p["joints"] is None for p in prims):
                    raise InputError(f"{self.name}: node {self.node_label(index)} has a skin but its mesh has no "
                                     "JOINTS_0/WEIGHTS_0; re-export the skinned mesh.")
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

    def part(self, node_index: int, node: dict, mesh: dict, j: int, p: dict) -> tuple[Part, np.ndarray | None]:
        """One primitive's Part (semantic name, display colour, label node/material) and its display vertex colours.

        glTF colours are linear (baseColorFactor, COLOR_0) or sRGB (base-colour textures); the pipeline's are display
        values multiplied as such (converter/animation.py), so the vertex colours are srgb(factor * own) / part colour:
        drawn, part times vertex colour is the spec's linear product, encoded once."""
        material = self.item("materials", p["material"]) if p["material"] is not None else {}
        own = p["colors"] if p["colors"] is not None else p["texture_colors"]  # both linear; COLOR_0 wins
        factor = self.base_color(material, textured=own is not None)  # the spec's white under own colours
        name = part_name(material.get("name"), mesh.get("name"), node.get("name"))
        display = None
        if factor is None:
            rgb = np.asarray(DEFAULT_PART_COLORS[name], np.float32)  # already a display value
        else:
            rgb = linear_to_srgb(np.asarray(factor, np.float32))
            if own is not None:
                display = linear_to_srgb(own * np.asarray(factor, np.float32))
                display = np.divide(display, rgb, out=np.zeros_like(display), where=rgb > 0).clip(0.0, 1.0)
        what = material.get("name") or mesh.get("name") or (f"material{p['material']}" if p["material"] is not None
                                                            else f"primitive{j}")
        label = f"{self.node_label(node_index)}/{what}"
        return Part(name, tuple(float(c) for c in rgb), label), display  # type: ignore[arg-type]

    def base_color(self, material: dict, textured: bool = False) -> tuple[float, float, float] | None:
        """The material's linear baseColorFactor rgb (white under vertex or texture colours), or None: the default."""
        pbr = material.get("pbrMetallicRoughness") or {}
        factor = pbr.get("baseColorFactor")
        if factor is None:
            # untextured default white would be meaningless for a face: use the part's colour
            return (1.0, 1.0, 1.0) if textured else None
        rgb = tuple(float(np.clip(c, 0.0, 1.0)) for c in list(factor)[:3])
        if len(rgb) != 3:
            raise InputError(f"{self.name}: a material's baseColorFactor needs 4 numbers.")
        if pbr.get("baseColorTexture") is not None and rgb == (1.0, 1.0, 1.0) and not textured:
            return None  # the colour lives in a texture we could not sample
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
            joints = weights = None
            n_sets = sum(1 for n in range(len(attrs)) if f"JOINTS_{n}" in attrs)
            if n_sets:
                if any(f"WEIGHTS_{n}" not in attrs or f"JOINTS_{n}" not in attrs for n in range(n_sets)):
                    raise InputError(f"{self.name}: mesh {mesh_index} has JOINTS_n without matching WEIGHTS_n; "
                                     "re-export the skin.")
                for n in range(n_sets):
                    if self.item("accessors", attrs[f"JOINTS_{n}"]).get("componentType") not in (5121, 5123):
                        raise InputError(f"{self.name}: JOINTS_{n} of mesh {mesh_index} is not unsigned bytes or "
                                         "shorts; re-export the skin.")
                joints, weights = influences([self.accessor(attrs[f"JOINTS_{n}"], normalize=False)
                                              for n in range(n_sets)],
                                             [self.accessor(attrs[f"WEIGHTS_{n}"]) for n in range(n_sets)],
                                             len(pos), self.name, mesh_index)
            material = self.item("materials", p["material"]) if p.get("material") is not None else {}
            texture_colors = self.texture_colors(material, attrs, len(pos), mesh_index)
            used = np.unique(tris)
            if len(used) < len(pos):
                # Primitives often share one vertex buffer per mesh: keep only this one's vertices.
                remap = np.zeros(len(pos), np.int64)
                remap[used] = np.arange(len(used))
                pos, deltas, tris = pos[used], deltas[:, used], remap[tris]
                colors = None if colors is None else colors[used]
                texture_colors = None if texture_colors is None else texture_colors[used]
                if joints is not None:
                    joints, weights = joints[used], weights[used]
            out.append({"positions": pos, "faces": tris, "deltas": deltas, "colors": colors,
                        "texture_colors": texture_colors, "material": p.get("material"), "joints": joints,
                        "weights": weights})
        cache[mesh_index] = out
        return out

    def texture_colors(self, material: dict, attrs: dict, n_vertices: int, mesh_index: int) -> np.ndarray | None:
        """(V, 3) linear base-colour texture at the vertices' UVs, or None (no texture, or one we cannot read)."""
        info = (material.get("pbrMetallicRoughness") or {}).get("baseColorTexture")
        if not isinstance(info, dict) or info.get("index") is None:
            return None
        texture = self.item("textures", info["index"])
        uv_key = f"TEXCOORD_{int(info.get('texCoord', 0))}"
        if attrs.get(uv_key) is None:
            self._note(f"{self.name}: mesh {mesh_index} has a base-colour texture but no {uv_key}; "
                       "drawing its material's base colour instead.")
            return None
        # Extensions (KHR_texture_basisu, EXT_texture_webp, ...) name alternative sources: take any Pillow decodes.
        sources = [texture.get("source")] + [e.get("source") for e in (texture.get("extensions") or {}).values()
                                              if isinstance(e, dict)]
        pixels = next((px for px in (self.image(i) for i in sources if i is not None) if px is not None), None)
        if pixels is None:
            kinds = sorted({str(self.item("images", i).get("mimeType") or "unknown type")
                            for i in sources if i is not None})
            self._note(f"{self.name}: texture {info['index']} ({', '.join(kinds) or 'no image'}) cannot be decoded "
                       "(Pillow reads PNG, JPEG, WebP); drawing its material's base colour instead.")
            return None
        uv = self.accessor(attrs[uv_key])
        if uv.shape != (n_vertices, 2):
            raise InputError(f"{self.name}: {uv_key} of mesh {mesh_index} does not match its vertices.")
        sampler = self.item("samplers", texture["sampler"]) if texture.get("sampler") is not None else {}
        wrap = sampler.get("wrapS", 10497), sampler.get("wrapT", 10497)
        return sample_texture(pixels, uv, *wrap, decode_srgb=True)

    def image(self, index: int) -> np.ndarray | None:
        """Decoded pixels of image index (cached), or None when missing or in a format Pillow cannot read."""
        if index not in self._images:
            image = self.item("images", index)
            uri = image.get("uri")
            try:
                if image.get("bufferView") is not None:
                    data = bytes(self.view(image["bufferView"]))
                elif isinstance(uri, str) and uri.startswith("data:"):
                    data = base64.b64decode(uri.partition(",")[2], validate=True)
                elif isinstance(uri, str):
                    data = self._external(uri, index, "image")
                else:
                    data = b""
            except (InputError, binascii.Error, ValueError) as exc:
                self._note(str(exc).rstrip(".") + "; drawing the base colour instead.")
                data = b""
            self._images[index] = decode_image(data) if data else None
        return self._images[index]

    def _note(self, message: str) -> None:
        if message not in self.notes:
            self.notes.append(message)

    def clip(self, index: int) -> Tracks:
        """Animation index's channels: (node, path) -> (times, values (keys, C), interpolation)."""
        anim = self.item("animations", index)
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
        return out

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
