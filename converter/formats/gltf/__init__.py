"""glTF 2.0 (.glb / .gltf) input: container and accessors, scene and sampling, skins."""

from converter.formats.gltf.scene import _Document, load_gltf, parse_container

__all__ = ["_Document", "load_gltf", "parse_container"]
