"""EXT_meshopt_compression: decode one compressed buffer view with meshoptimizer's decoders."""

from __future__ import annotations

import meshoptimizer as mo
import numpy as np

from converter.errors import InputError

MAX_DECODED_VIEW = 1 << 28  # bytes of one meshopt-decoded buffer view


def decode_view(ext: dict, src_buf: memoryview, name: str, index: int) -> memoryview:
    """Buffer view index decoded from its EXT_meshopt_compression object ext over the source buffer's bytes."""
    off, length = int(ext.get("byteOffset", 0)), int(ext["byteLength"])
    count, stride = int(ext["count"]), int(ext["byteStride"])
    mode, filt = ext["mode"], ext.get("filter", "NONE")
    if off < 0 or length < 0 or off + length > len(src_buf):
        raise InputError(f"{name}: compressed buffer view {index} runs past its buffer; the file is truncated.")
    if count < 1 or stride < 1 or count * stride > MAX_DECODED_VIEW:
        raise InputError(f"{name}: compressed buffer view {index} has an invalid size.")
    src = np.frombuffer(src_buf[off:off + length], np.uint8)
    # The C decoders assert on these preconditions, so check them first rather than crash the process.
    try:
        if mode == "ATTRIBUTES":
            if stride % 4 or stride > 256:
                raise InputError(f"{name}: compressed buffer view {index} has byteStride {stride} "
                                 "(needs a multiple of 4 up to 256).")
            decoded = np.ascontiguousarray(mo.decode_vertex_buffer(count, stride, src))
            out = decoded.view(np.uint8).reshape(count, stride)
        elif mode in ("TRIANGLES", "INDICES"):
            if stride not in (2, 4) or (mode == "TRIANGLES" and count % 3):
                raise InputError(f"{name}: compressed index view {index} has an invalid count or stride.")
            decode = mo.decode_index_buffer if mode == "TRIANGLES" else mo.decode_index_sequence
            idx = decode(count, 4, src)
            if stride == 2 and idx.size and idx.max() > 0xFFFF:
                raise InputError(f"{name}: compressed index view {index} does not fit 16 bits.")
            out = idx.astype("<u2" if stride == 2 else "<u4").view(np.uint8).reshape(count, stride)
        else:
            raise InputError(f"{name}: buffer view {index} uses unknown meshopt mode {mode!r}.")
    except RuntimeError:
        raise InputError(f"{name}: compressed buffer view {index} does not decode; "
                         "the file is corrupt.") from None
    if filt != "NONE":
        if mode != "ATTRIBUTES":
            raise InputError(f"{name}: buffer view {index} applies filter {filt} to indices.")
        checks = {"OCTAHEDRAL": stride in (4, 8), "QUATERNION": stride == 8, "EXPONENTIAL": stride % 4 == 0}
        if filt not in checks:
            raise InputError(f"{name}: buffer view {index} uses unknown meshopt filter {filt!r}.")
        if not checks[filt]:
            raise InputError(f"{name}: buffer view {index} has byteStride {stride}, invalid for filter {filt}.")
        fn = {"OCTAHEDRAL": mo.decode_filter_oct, "QUATERNION": mo.decode_filter_quat,
              "EXPONENTIAL": mo.decode_filter_exp}[filt]
        out = fn(np.ascontiguousarray(out), count, stride)
    return memoryview(np.ascontiguousarray(out).reshape(-1).tobytes())
