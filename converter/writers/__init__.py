"""Writers: Sheet -> bytes. One module per output; the registry maps (output kind, shading) to a writer."""

from __future__ import annotations

from typing import Callable

from converter.errors import InputError
from converter.options import ConversionOptions, Report
from converter.sheet import Sheet

Writer = Callable[[Sheet, ConversionOptions, Report], bytes]


def writer_for(options: ConversionOptions) -> Writer:
    """The writer for the options' output kind and shading."""
    if options.to == "svg" and options.shading == "flat":
        from converter.writers import svg_anim

        return svg_anim.write
    if options.to == "svg" and options.shading in ("gouraud", "gouraud-chapter"):
        try:
            from converter.writers import svg_gouraud
        except ImportError:
            raise InputError(f"shading {options.shading!r} is not available in this build.") from None
        return svg_gouraud.write
    raise InputError(f"no writer for output {options.to!r} with shading {options.shading!r}.")
