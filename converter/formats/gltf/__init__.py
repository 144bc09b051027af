"""glTF 2.0 (.glb / .gltf) input: container and accessors, scene and sampling, clips, skins, textures.

The names the single-module loader had stay importable from here.
"""

from converter.formats.gltf.accessors import COMPONENT_DTYPES, INDEX_TYPES, NORMALIZE_DIVISOR, TYPE_COMPONENTS
from converter.formats.gltf.container import IGNORABLE_EXTENSIONS, SUPPORTED_EXTENSIONS, parse_container
from converter.formats.gltf.sampling import keyframe_rate, sample, slerp, trs_matrices
from converter.formats.gltf.scene import DEFAULT_FPS, MAX_FRAMES, _Document, load_gltf, triangles

__all__ = [
    "COMPONENT_DTYPES", "DEFAULT_FPS", "IGNORABLE_EXTENSIONS", "INDEX_TYPES", "MAX_FRAMES", "NORMALIZE_DIVISOR",
    "SUPPORTED_EXTENSIONS", "TYPE_COMPONENTS", "_Document", "keyframe_rate", "load_gltf", "parse_container",
    "sample", "slerp", "triangles", "trs_matrices",
]
