"""The registry of output kinds: what facesvg can write, which writer writes it and which 2D stage feeds it.

The CLI (--to), convert, the web form, the API, OpenAPI and the job storage all read this one registry. A new output
is one writer module in converter/writers/ plus one OutputKind entry in OUTPUTS.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from converter.errors import InputError
from converter.options import ConversionOptions, OptionField, Progress, Report
from converter.writers import fap2d, lottie, player, puppet, svg_anim, svg_gouraud

Writer = Callable[[Any, ConversionOptions, Report, Progress], bytes]  # (2D data, options, report, progress)
"""(what the stage built: a Sheet or a Fat2dSheet, options, report) -> the output's bytes."""

SHEET = "sheet"  # converter.extract: projected, culled, shaded frames (converter.sheet.Sheet)
FAT2D = "fat2d"  # converter.mpeg4.fat2d: portrait, 2D mesh, 2D FAT and FAP stream (Fat2dSheet)
PUPPET = "puppet"  # converter.puppet: a face's 2D mesh and per-parameter 2D FAT tables (Puppet)


@dataclass(frozen=True)
class OutputFile:
    """One file an output kind produces: its key in the web API, extension and media type."""

    key: str  # the API's result kind: /jobs/{id}/result/{key}
    label: str  # the download button's text
    extension: str  # what `facesvg convert` names the file
    media_type: str
    gzip: bool = False  # the gzip of the kind's main file
    attachment: bool = False  # always downloaded, never shown inline by a browser
    download_suffix: str = ""  # the web download's and stored file's suffix, when it differs from extension

    @property
    def suffix(self) -> str:
        """Suffix of the stored result file and of the web download."""
        return self.download_suffix or self.extension


@dataclass(frozen=True)
class OutputKind:
    """One output kind: its name (the --to value), label, files, writer and the 2D stage it reads."""

    name: str
    label: str
    writer: Writer
    files: tuple[OutputFile, ...]  # the main file first; then variants (e.g. the gzip of it)
    stage: str = SHEET
    shading_writers: Mapping[str, Writer] = field(default_factory=dict)  # by options.shading, instead of writer
    gzip_option: str = ""  # the switch that asks for the gzip variant instead of the main file (svgz)
    requires: tuple[str, ...] = ()  # path options the kind cannot do without
    requires_text: str = ""  # those as the web form's error names them
    stills: bool = True  # options.frame makes a still of that frame
    verify: bool = False  # converter.verify can measure the output against the exact projection

    @property
    def takes_fap_stream(self) -> bool:
        """The stage reads options.fap itself (the 3D stages must not drive the face with it)."""
        return self.stage == FAT2D

    def writer_for(self, options: ConversionOptions) -> Writer:
        """The writer for the options' shading."""
        return self.shading_writers.get(options.shading, self.writer)

    def file_for(self, options: ConversionOptions) -> OutputFile:
        """The file `convert` returns with these options: the gzip variant when its switch is on."""
        if self.gzip_option and getattr(options, self.gzip_option):
            return next(f for f in self.files if f.gzip)
        return self.files[0]


SVG_FILE = OutputFile("svg", "SVG", ".svg", "image/svg+xml")
SVGZ_FILE = OutputFile("svgz", "SVGZ (gzip)", ".svgz", "image/svg+xml", gzip=True, attachment=True)
PLAYER_FILE = OutputFile("html", "Player (.html)", ".html", "text/html")

OUTPUTS: dict[str, OutputKind] = {k.name: k for k in (
    OutputKind("svg", "Animated SVG", svg_anim.write, (SVG_FILE, SVGZ_FILE),
               shading_writers={"flat": svg_anim.write, "gouraud": svg_gouraud.write,
                                "gouraud-chapter": svg_gouraud.write},
               gzip_option="svgz", verify=True),
    OutputKind("player", "WebGL player (HTML)", player.write, (PLAYER_FILE,), stills=False, verify=True),
    OutputKind("lottie", "Lottie animation (JSON)", lottie.write,
               (OutputFile("lottie", "Lottie (.json)", ".json", "application/json", attachment=True),), verify=True),
    OutputKind("dotlottie", "dotLottie animation (.lottie)", lottie.write_dotlottie,
               (OutputFile("dotlottie", "dotLottie (.lottie)", ".lottie", "application/zip", attachment=True),),
               verify=True),
    OutputKind("fap2d", "MPEG-4 2D face package", fap2d.write,
               (OutputFile("fap2d", "2D face package (.zip)", ".zip", "application/zip", attachment=True,
                           download_suffix=".fap2d.zip"),),
               stage=FAT2D, requires=("fap", "fdp"), requires_text="a FAP stream and an FDP file", stills=False),
    OutputKind("puppet", "Puppet (HTML, drive with any capture)", puppet.write,
               (OutputFile("puppet", "Puppet (.html)", ".html", "text/html", download_suffix=".puppet.html"),),
               stage=PUPPET, stills=False),
)}
"""Every output kind by name, in the order the CLI, the form and OpenAPI offer them."""


def output_kind(name: str) -> OutputKind:
    """The registered kind of that name; InputError naming the choices otherwise."""
    if name not in OUTPUTS:
        raise InputError(f"unknown output kind {name!r}; choose one of {', '.join(OUTPUTS)}.")
    return OUTPUTS[name]


def writer_for(options: ConversionOptions) -> Writer:
    """The writer for the options' output kind and shading."""
    return output_kind(options.to).writer_for(options)


def output_files() -> dict[str, OutputFile]:
    """Every file any kind produces, by key, in registry order."""
    return {f.key: f for kind in OUTPUTS.values() for f in kind.files}


def choices(spec: OptionField) -> Mapping[str, str] | None:
    """Value -> label of an option's choices (the registered kinds for `to`), or None when it is free."""
    if spec.meta.output_kinds:
        return {k.name: k.label for k in OUTPUTS.values()}
    return spec.meta.choices


def required_by(option_name: str) -> tuple[str, ...]:
    """Names of the output kinds that cannot do without this path option."""
    return tuple(k.name for k in OUTPUTS.values() if option_name in k.requires)

