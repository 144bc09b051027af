"""`facesvg clone SOURCE_ANIM TARGET_FACE [--method ...] [--keys pairs.zip] [--correspondences file] -o out.glb`."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from converter import formats
from converter.cloning import clone
from converter.errors import InputError
from converter.export.glb import write_glb
from converter.userfiles import check_output, write_atomic


def cmd_clone(args: argparse.Namespace) -> int:
    """Clone the source animation onto the target face and write a GLB."""
    out = Path(args.output)
    if out.suffix.lower() != ".glb":
        raise InputError(f"the output must be a .glb file, got {out.name}.")
    check_output(out)
    t = time.perf_counter()
    source = formats.load(args.source, cache=args.cache)
    target = formats.load(args.target)
    result = clone(source, target, args.method, keys=args.keys, correspondences=args.correspondences)
    write_atomic(out, write_glb(result))
    print(f"{out}: {result.n_frames} frames, {result.n_vertices} vertices, {args.method} cloning, "
          f"{time.perf_counter() - t:.2f} s")
    return 0


def register_cli(sub) -> None:
    """Add the `clone` subcommand."""
    p = sub.add_parser("clone", help="put an animation onto another face (writes GLB)")
    p.add_argument("source", help="source animation (its first frame is the neutral face)")
    p.add_argument("target", help="target face (its first frame is used)")
    p.add_argument("--method", default="dense", choices=("example", "frames", "dense"),
                   help="example (key-model pairs), frames (same topology), dense (default)")
    p.add_argument("--keys", help="zip of key-model pairs for --method example")
    p.add_argument("--correspondences", help="JSON {\"pairs\": [[source, target], ...]} (ids or [x,y,z])")
    p.add_argument("--cache", help="PC2 or MDD point cache when the source is a single OBJ")
    p.add_argument("-o", "--output", required=True, help="output .glb")
    p.set_defaults(func=cmd_clone)
