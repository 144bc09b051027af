"""Golden files guard the exact SVG we generate for small, fixed inputs (compared as canonical XML)."""

from conftest import cube_animation
from converter.convert import convert_animation
from converter.options import ConversionOptions


def test_cube_flat_animation_golden(golden):
    result = convert_animation(cube_animation(6), ConversionOptions(size=64))
    golden("cube_flat.svg", result.data)


def test_cube_flat_raw_golden(golden):
    result = convert_animation(cube_animation(4), ConversionOptions(size=64, raw=True))
    golden("cube_flat_raw.svg", result.data)


def test_cube_still_golden(golden):
    result = convert_animation(cube_animation(4), ConversionOptions(size=64, frame=2))
    golden("cube_still.svg", result.data)


def test_output_is_deterministic():
    a = convert_animation(cube_animation(5), ConversionOptions(size=64)).data
    b = convert_animation(cube_animation(5), ConversionOptions(size=64)).data
    assert a == b
