"""Number text for SVG attributes: the shortest form that parses back to the rounded value."""

from __future__ import annotations


def number(x: float, decimals: int) -> str:
    """x rounded to decimals, without trailing zeros or a leading zero ('.25', '-.5', '3', '0')."""
    s = f"{x:.{decimals}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s.startswith("0."):
        s = s[1:]
    elif s.startswith("-0."):
        s = "-" + s[2:]
    return "0" if s in ("-0", "", "-") else s
