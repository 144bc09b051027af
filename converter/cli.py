"""The `facesvg` command: parse arguments into ConversionOptions, call the library, print the Report."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from converter.bundled import sample_path
from converter.errors import FacesvgError
from converter.userfiles import check_output


class ProgressBar:
    """A one-line progress bar on stderr (silent when stderr is not a terminal unless forced)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.last = -1.0

    def __call__(self, stage: str, fraction: float) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if fraction < 1.0 and now - self.last < 0.1:
            return
        self.last = now
        filled = int(round(fraction * 30))
        sys.stderr.write(f"\r[{'#' * filled}{' ' * (30 - filled)}] {fraction * 100:5.1f}% {stage:<12}")
        if fraction >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()


def add_conversion_options(p: argparse.ArgumentParser) -> None:
    """The ConversionOptions flags shared by every command that converts."""
    p.add_argument("--to", default="svg", help="output kind: svg (default) or fap2d")
    p.add_argument("--shading", default="flat", help="flat (default), gouraud, gouraud-chapter")
    p.add_argument("--frame", type=int, help="write a still of this frame instead of the animation")
    p.add_argument("--fps", type=float, help="resample to this frame rate (default: the source's, else 30)")
    p.add_argument("--size", type=int, default=512, help="output size in pixels (default 512)")
    p.add_argument("--yaw", type=float, default=0.0, help="camera degrees around the vertical axis")
    p.add_argument("--pitch", type=float, default=0.0, help="camera degrees up or down")
    p.add_argument("--fov", type=float, default=30.0, help="vertical field of view in degrees")
    p.add_argument("--ortho", action="store_true", help="orthographic projection")
    p.add_argument("--neutral-frame", type=int, default=0, help="frame that serves as the neutral face")
    p.add_argument("--start", type=int, default=0, help="first frame")
    p.add_argument("--end", type=int, help="one past the last frame")
    p.add_argument("--tolerance", type=float, default=0.25, help="max deviation in px the encoder may add")
    p.add_argument("--raw", action="store_true", help="write every frame (no keyframe reduction)")
    p.add_argument("--max-triangles", type=int, help="triangle budget")
    p.add_argument("--no-occlusion", dest="occlusion", action="store_false", help="keep never-seen triangles")
    p.add_argument("--svgz", action="store_true", help="gzip the SVG")
    p.add_argument("--depth-layers", action="store_true",
                   help="experimental: layer copies for triangles whose depth order flips")
    p.add_argument("--no-rigid", dest="rigid", action="store_false",
                   help="do not factor rigid 2D motion into animated group transforms")
    p.add_argument("--smooth", type=float, help="temporal smoothing, Gaussian sigma in frames (default 0: off)")
    p.add_argument("--fap", help="MPEG-4 FAP stream that drives the input face")
    p.add_argument("--fdp", help="feature-point definition of the input face (JSON or Xface .fdp)")
    p.add_argument("--clone-target", help="put the animation onto this face before converting")
    p.add_argument("--clone-method", default="dense", help="example | frames | dense")
    p.add_argument("--clone-keys", help="key-model pairs (zip) for --clone-method example")
    p.add_argument("--correspondences", help="user correspondences for dense cloning")


def options_from_args(args: argparse.Namespace):
    """ConversionOptions from parsed arguments (only the fields the parser has)."""
    from dataclasses import fields

    from converter.options import ConversionOptions

    names = {f.name for f in fields(ConversionOptions)}
    return ConversionOptions(**{k: v for k, v in vars(args).items() if k in names and v is not None})


def cmd_convert(args: argparse.Namespace) -> int:
    """facesvg convert INPUT -o OUT."""
    from converter.convert import convert, write_atomic

    options = options_from_args(args)
    suffix = ".zip" if options.to == "fap2d" else (".svgz" if options.svgz else ".svg")
    if args.sample:  # the bundled face; the default output goes to the working folder, not beside the sample
        if args.input:
            raise_input("give either an input file or --sample, not both.")
        args.input, default_out = str(sample_path()), Path("face").with_suffix(suffix)
    elif not args.input:
        raise_input("give the input file to convert (or --sample for the bundled face).")
    else:
        default_out = Path(args.input).with_suffix(suffix)
    out = check_output(args.output if args.output else default_out)
    result = convert(args.input, options, progress=ProgressBar(not args.quiet and sys.stderr.isatty() or args.progress),
                     cache=args.cache)
    write_atomic(out, result.data)
    print(f"{out}: {result.report.summary()}")
    if args.report:
        write_atomic(Path(args.report), result.report.dumps().encode())
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    """facesvg info INPUT."""
    from converter import formats

    anim = formats.load(args.input, cache=args.cache)
    info = {
        "name": anim.name,
        "frames": anim.n_frames,
        "fps": anim.fps,
        "duration": round(anim.duration, 4),
        "vertices": anim.n_vertices,
        "triangles": anim.n_faces,
        "parts": {p.name: int((anim.part_ids == i).sum()) for i, p in enumerate(anim.parts)},
        **{k: v for k, v in anim.extras.items() if isinstance(v, (int, float, str, list, dict))},
    }
    if args.json:
        print(json.dumps(info, indent=2, sort_keys=True))
    else:
        for k, v in info.items():
            print(f"{k:>16}: {v}")
    return 0


def raise_input(message: str) -> None:
    """Raise the InputError the CLI prints as one line."""
    from converter.errors import InputError

    raise InputError(message)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = argparse.ArgumentParser(prog="facesvg", description="Turn 3D facial animation into lightweight 2D.")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("convert", help="convert an animation to SVG (or another 2D output)")
    p.add_argument("input", nargs="?", help="glTF/GLB, zip of OBJ frames, or OBJ with --cache")
    p.add_argument("--sample", action="store_true", help="convert the bundled sample face instead of an input file")
    p.add_argument("-o", "--output", help="output file (default: input name with .svg)")
    p.add_argument("--cache", help="PC2 or MDD point cache for an OBJ input")
    p.add_argument("--report", help="also write the Report as JSON to this file")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--progress", action="store_true", help="progress bar even when stderr is not a terminal")
    add_conversion_options(p)
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("info", help="describe an input animation")
    p.add_argument("input")
    p.add_argument("--cache", help="PC2 or MDD point cache for an OBJ input")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_info)

    # Other subcommands register here (verify, clone, fdp, fap-loa, serve).
    for register in _extra_commands():
        register(sub)
    return parser


def _extra_commands():
    """Subcommand registrars of optional modules, in a fixed order."""
    import importlib

    out = []
    for mod, attr in (
        ("converter.verify", "register_cli"),
        ("converter.mpeg4.cli", "register_cli"),
        ("converter.cloning.cli", "register_cli"),
        ("webapp.cli", "register_cli"),
    ):
        try:
            module = importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name and mod.startswith(exc.name):
                continue  # that part is not built yet
            raise
        out.append(getattr(module, attr))
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point: exit 0 on success, 2 on a user error (one line on stderr), 1 on an internal failure."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except FacesvgError as exc:
        print(f"facesvg: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("facesvg: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
