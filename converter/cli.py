"""The `facesvg` command: parse arguments into ConversionOptions, call the library, print the Report."""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

from converter import formats, framing, warm
from converter.bundled import sample_path
from converter.convert import convert
from converter.encode import parallel
from converter.errors import FacesvgError, InputError
from converter.formats import captures
from converter.formats.weights import read_weights
from converter.live import ports as live_ports
from converter.options import ConversionOptions, Eta, OptionField, option_fields
from converter.outputs import choices, output_kind
from converter.puppet.take import from_track as take_from_track
from converter.userfiles import check_output, read_bytes, write_atomic
from converter.writers import puppet as puppet_writer


class ProgressBar:
    """A one-line progress bar on stderr (silent when stderr is not a terminal unless forced)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.last = -1.0
        self.stage = ""
        self.start: float | None = None
        self.eta = Eta()

    def __call__(self, stage: str, fraction: float) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        self.start = now if self.start is None else self.start
        left = self.eta(stage, fraction, now)  # every call: it must see where loading ended
        if fraction < 1.0 and now - self.last < 0.1 and stage == self.stage:  # a new stage shows at once
            return
        self.last, self.stage = now, stage
        filled = int(round(fraction * 30))
        eta = f"ETA {int(left) // 60}:{int(left) % 60:02d}" if left is not None and now - self.start > 1.0 else ""
        sys.stderr.write(f"\r[{'#' * filled}{' ' * (30 - filled)}] {fraction * 100:5.1f}% {stage:<12} {eta:<10}")
        if fraction >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _threads(text: str) -> int:
    """argparse type of --threads: parallel.thread_count, its error as argparse's message."""
    try:
        return parallel.thread_count(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _help(spec: OptionField) -> str:
    """The flag's help: the option's help plus its default (or what unset means)."""
    text = spec.meta.help
    if spec.type is bool:
        return f"turn off (on by default): {text}" if spec.default else text
    if spec.default is not None:
        return f"{text} (default {spec.default})"
    return f"{text} (default: {spec.meta.unset})" if spec.meta.unset else text


def add_conversion_options(p: argparse.ArgumentParser) -> None:
    """The ConversionOptions flags shared by every command that converts, from the options' metadata."""
    for spec in option_fields():
        if spec.type is bool:
            action = "store_false" if spec.default else "store_true"
            p.add_argument(spec.flag, dest=spec.name, action=action, default=argparse.SUPPRESS, help=_help(spec))
            continue
        kinds = choices(spec)
        # SUPPRESS: a flag not given stays out of the Namespace, so a preset fills it even where it was given at
        # its default value (which then stays).
        p.add_argument(spec.flag, dest=spec.name, type=spec.type, default=argparse.SUPPRESS,
                       choices=list(kinds) if kinds else None, help=_help(spec),
                       metavar="FILE" if spec.meta.path else None)


def options_from_args(args: argparse.Namespace) -> ConversionOptions:
    """ConversionOptions from parsed arguments (only the flags given; a --preset fills the others)."""
    names = {spec.name for spec in option_fields()}
    return ConversionOptions.given(**{k: v for k, v in vars(args).items() if k in names and v is not None})


def cmd_convert(args: argparse.Namespace) -> int:
    """facesvg convert INPUT -o OUT."""
    options = options_from_args(args)
    suffix = output_kind(options.to).file_for(options).extension
    if args.sample:  # the bundled face; the default output goes to the working folder, not beside the sample
        if args.input:
            raise InputError("give either an input file or --sample, not both.")
        args.input, default_out = str(sample_path()), Path("face").with_suffix(suffix)
    elif not args.input:
        raise InputError("give the input file to convert (or --sample for the bundled face).")
    else:
        default_out = Path(args.input).with_suffix(suffix)
    out = check_output(args.output if args.output else default_out)
    if args.threads is not None:
        parallel.use_threads(args.threads)
    result = convert(args.input, options, progress=ProgressBar(not args.quiet and sys.stderr.isatty() or args.progress),
                     cache=args.cache)
    write_atomic(out, result.data)
    print(f"{out}: {result.report.summary()}")
    for warning in result.report.warnings:  # what the web page lists under the result
        print(f"facesvg: warning: {warning}", file=sys.stderr)
    if args.report:
        write_atomic(Path(args.report), result.report.dumps().encode())
    return 0


def cmd_warm(args: argparse.Namespace) -> int:
    """facesvg warm: compile (or load) every kernel now."""
    print(warm.warm(ProgressBar(not args.quiet and sys.stderr.isatty() or args.progress), args.fresh).summary())
    return 0


def hex_color(rgb: tuple[float, float, float]) -> str:
    """#rrggbb of a display colour 0..1."""
    return "#" + "".join(f"{int(round(min(max(float(c), 0.0), 1.0) * 255)):02x}" for c in rgb)


def capture_info(path: str) -> dict | None:
    """What `facesvg info` says about a weight capture (layout, frames, rate, names, angles), or None for a face."""
    if captures.detect_file(path) is None:
        return None  # a face, or a path formats.load explains (missing, a folder)
    track = captures.read_capture(path)
    return {"name": Path(path).stem, "kind": "capture", **captures.describe(track)}


def cmd_info(args: argparse.Namespace) -> int:
    """facesvg info INPUT (a face or animation; a weight capture is described as one)."""
    capture = capture_info(args.input)
    if capture is not None:
        if args.json:
            print(json.dumps(capture, indent=2, sort_keys=True))
        else:
            for k, v in capture.items():
                print(f"{k:>16}: {', '.join(v) if isinstance(v, list) else v}")
        return 0
    anim = formats.load(args.input, cache=args.cache, animation=args.animation)
    counts: dict[str, int] = {}  # triangles per semantic part, over every part of that name
    for i, p in enumerate(anim.parts):
        counts[p.name] = counts.get(p.name, 0) + int((anim.part_ids == i).sum())
    info = {
        "name": anim.name,
        "frames": anim.n_frames,
        "fps": anim.fps,
        "duration": round(anim.duration, 4),
        "vertices": anim.n_vertices,
        "triangles": anim.n_faces,
        "parts": counts,
        "part_labels": [{"label": p.label, "part": p.name, "color": hex_color(p.color),
                         "triangles": int((anim.part_ids == i).sum())} for i, p in enumerate(anim.parts)],
        **{k: v for k, v in anim.extras.items() if isinstance(v, (int, float, str, list, dict))},
        "frame_on": framing.candidates(anim),  # what --frame-on accepts
    }
    if args.json:
        print(json.dumps(info, indent=2, sort_keys=True))
    else:
        for k, v in info.items():
            if k == "animations":  # one line per clip
                for clip in v:
                    print(f"{'animation':>16}: {clip['index']} {clip['name'] or '(unnamed)'}: {clip['duration']} s, "
                          f"{clip['channels']} channels, targets {', '.join(clip['targets']) or 'none'}")
                continue
            if k == "part_labels":  # one line per part: label, semantic part, display colour, triangles
                for part in v:
                    print(f"{'part':>16}: {part['label']} ({part['part']}) {part['color']}, {part['triangles']} "
                          "triangles")
                continue
            print(f"{k:>16}: {v}")
    return 0


def cmd_puppet_take(args: argparse.Namespace) -> int:
    """facesvg puppet-take PUPPET.html CAPTURE -o NEW.html: the puppet with another take embedded, no conversion."""
    out = check_output(Path(args.output) if args.output else Path(args.puppet))
    page = puppet_writer.replace_take(read_bytes(args.puppet, "puppet"), take_from_track(read_weights(args.capture)))
    write_atomic(out, page)
    print(f"{out}: {len(page)} bytes")
    return 0


def cmd_live(args: argparse.Namespace) -> int:
    """facesvg live: bridge Live Link Face, iFacialMocap and VMC streams to puppet players until Ctrl-C."""
    ports = live_ports.Ports(**{key: live_ports.port_number(getattr(args, f"{key}_port"), f"--{key}-port")
                                for key in ("llf", "ifm", "vmc", "ws")})
    # imported when it runs: websockets' import would slow every facesvg command (as webapp.cli defers Flask)
    importlib.import_module("converter.live.server").run(args.host, ports, say=lambda line: print(line, flush=True))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = argparse.ArgumentParser(prog="facesvg", description="Turn 3D facial animation into lightweight 2D.")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("convert", help="convert an animation to SVG (or another 2D output)")
    p.add_argument("input", nargs="?", help="glTF/GLB, zip of OBJ frames, or OBJ with --cache")
    p.add_argument("--sample", action="store_true", help="convert the bundled sample face instead of an input file")
    p.add_argument("-o", "--output", help="output file (default: the input name with the output kind's extension)")
    p.add_argument("--cache", help="PC2 or MDD point cache for an OBJ input")
    p.add_argument("--report", help="also write the Report as JSON to this file")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--progress", action="store_true", help="progress bar even when stderr is not a terminal")
    p.add_argument("--threads", type=_threads, metavar="N",
                   help=f"threads for the compiled loops (default: ${parallel.ENV}, else the CPUs this process may "
                        f"use, at most {parallel.MAX_THREADS}); 1 takes the least CPU time when conversions run side "
                        "by side. The output is the same for any N")
    add_conversion_options(p)
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("info", help="describe an input animation, or a weight capture (its layout, frames, rate)")
    p.add_argument("input")
    p.add_argument("--cache", help="PC2 or MDD point cache for an OBJ input")
    p.add_argument("--animation", help="glTF animation to describe: NAME, INDEX or all (default: the first take)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("warm", help="compile the converter's kernels now (a fresh install's first conversion would "
                                    "spend ~20 s on it); make setup runs it")
    p.add_argument("--fresh", action="store_true", help="forget the compiled code first and compile it all anew "
                   "(numba does not notice a change to a kernel's callee in another file)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--progress", action="store_true", help="progress bar even when stderr is not a terminal")
    p.set_defaults(func=cmd_warm)

    p = sub.add_parser("puppet-take", help="embed another capture in a puppet (--to puppet) without converting")
    p.add_argument("puppet", help="the puppet .html")
    p.add_argument("capture", help="the weight capture (any layout --weights reads)")
    p.add_argument("-o", "--output", help="output file (default: replace the puppet file)")
    p.set_defaults(func=cmd_puppet_take)

    p = sub.add_parser("live", help="bridge a face tracker's live stream (Live Link Face, iFacialMocap, VMC) to "
                                    "puppet players (--to puppet) over a WebSocket")
    defaults = live_ports.Ports()
    for key, label in (("llf", "Live Link Face's UDP stream"), ("ifm", "iFacialMocap's UDP frames"),
                       ("vmc", "VMC protocol (OSC over UDP)"), ("ws", "the players' WebSocket (TCP)")):
        p.add_argument(f"--{key}-port", default=str(getattr(defaults, key)), metavar="PORT",
                       help=f"port of {label} (default {getattr(defaults, key)}; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1, this machine only; 0.0.0.0 takes a phone's stream "
                        "from the network)")
    p.set_defaults(func=cmd_live)

    # Other subcommands register here (verify, clone, fdp, fap-loa, serve).
    for register in _extra_commands():
        register(sub)
    return parser


def _extra_commands():
    """Subcommand registrars of optional modules, in a fixed order."""
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
