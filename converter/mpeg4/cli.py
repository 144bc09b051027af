"""`facesvg fdp INPUT --auto` and `facesvg fap-loa IN.fap --level L -o OUT.fap`."""

from __future__ import annotations

import argparse
from pathlib import Path

from converter import formats
from converter.errors import InputError
from converter.mpeg4 import loa
from converter.mpeg4.auto import auto_fdp
from converter.mpeg4.fap import read_fap, write_fap
from converter.mpeg4.fdp import fdp_to_json
from converter.userfiles import check_output, write_atomic


def cmd_fdp(args: argparse.Namespace) -> int:
    """Propose an FDP for a face and write it as JSON."""
    if not args.auto:
        raise InputError("only automatic proposals are supported; add --auto (then check and edit the JSON).")
    face = formats.load(args.input)  # a single OBJ is a one-frame face
    fdp, report = auto_fdp(face)
    stem = Path(args.input).name.split(".")[0]
    out = Path(args.output) if args.output else Path(args.input).with_name(f"{stem}.fdp.json")
    check_output(out)
    write_atomic(out, fdp_to_json(fdp).encode())
    print(f"{out}: {len(fdp.points)} feature points, parts: {', '.join(sorted(fdp.parts)) or 'none'}")
    print("FAPU: " + ", ".join(f"{k}={v:.4g}" for k, v in fdp.fapu.items()))
    for line in report.lines():
        print(line)
    return 0


def cmd_fap_loa(args: argparse.Namespace) -> int:
    """Reduce a FAP stream to a level of articulation."""
    stream = read_fap(Path(args.input))
    original = len(write_fap(stream))
    reduced = loa.reduce(stream, args.level)
    text = write_fap(reduced).encode()
    out = Path(args.output)
    check_output(out)
    write_atomic(out, text)
    print(f"{out}: LoA {args.level}, {loa.fap_count(args.level)} FAPs, {int(reduced.mask.any(0).sum())} used, "
          f"{len(text)} bytes ({100 * len(text) / original:.1f}% of {original})")
    return 0


def register_cli(sub: argparse._SubParsersAction) -> None:
    """Add the fdp and fap-loa subcommands."""
    p = sub.add_parser("fdp", help="propose MPEG-4 feature points (FDP) for a face mesh")
    p.add_argument("input", help="glTF/GLB, zip of OBJ frames, or a single OBJ mesh (frame 0 is the neutral face)")
    p.add_argument("--auto", action="store_true", help="find the feature points by geometric heuristics")
    p.add_argument("-o", "--output", help="output JSON (default: INPUT name with .fdp.json beside it)")
    p.set_defaults(func=cmd_fdp)

    p = sub.add_parser("fap-loa", help="reduce a FAP stream to a level of articulation (Table 12.1)")
    p.add_argument("input", help="MPEG-4 .fap stream")
    p.add_argument("--level", required=True, choices=loa.LEVELS, help="high, medium, low or very-low")
    p.add_argument("-o", "--output", required=True, help="output .fap")
    p.set_defaults(func=cmd_fap_loa)

