"""Progress through the whole conversion, the writer included: the CLI's bar and ETA and the web job page read it,
and the web runner's callback stops a cancelled job by raising from it."""

import pytest

from converter import formats
from converter.convert import WRITE_FROM, convert_animation
from converter.options import ConversionOptions, span


@pytest.fixture(scope="module")
def anim(sample_path):
    return formats.load(sample_path).sliced(0, 40)


def recorded(anim, options: ConversionOptions) -> tuple[bytes, list[tuple[str, float]]]:
    calls: list[tuple[str, float]] = []
    data = convert_animation(anim, options, progress=lambda s, f: calls.append((s, f))).data
    return data, calls


@pytest.mark.parametrize("options", [
    ConversionOptions(size=256),
    ConversionOptions(size=256, rigid=False),
    ConversionOptions(size=256, raw=True),
    ConversionOptions(size=256, shading="gouraud"),
    ConversionOptions(size=256, to="player"),
], ids=["flat", "no-rigid", "raw", "gouraud", "player"])
def test_progress_only_grows_and_the_writer_reports_its_own(anim, options):
    data, calls = recorded(anim, options)
    fractions = [f for _, f in calls]
    assert fractions == sorted(fractions) and fractions[0] >= 0.0 and fractions[-1] == 1.0
    writing = [(s, f) for s, f in calls if WRITE_FROM < f < 1.0]
    assert len({f for _, f in writing}) >= 2, calls  # the writer's steps, not one jump to done
    assert data == convert_animation(anim, options).data  # reporting changes nothing


def test_the_flat_writer_reports_each_phase_of_the_plan(anim):
    _, calls = recorded(anim, ConversionOptions(size=256))
    writing = [s for s, f in calls if WRITE_FROM < f < 1.0]
    assert {"motion", "overlap", "groups", "keys", "text"} <= set(writing), writing
    # the phases come in that order
    firsts = [writing.index(s) for s in ("motion", "overlap", "groups", "keys", "text")]
    assert firsts == sorted(firsts)


@pytest.mark.parametrize("stage", ["overlap", "groups", "keys", "text"])
def test_a_callback_that_raises_stops_the_writer_there(anim, stage):
    """As the web runner's does for a cancelled job or a lost claim; the next conversion is unaffected."""

    class Stop(Exception):
        pass

    def stop(name: str, fraction: float) -> None:
        if name == stage:
            raise Stop(fraction)

    options = ConversionOptions(size=256)
    with pytest.raises(Stop) as info:
        convert_animation(anim, options, progress=stop)
    assert WRITE_FROM <= info.value.args[0] < 1.0
    assert convert_animation(anim, options).data == recorded(anim, options)[0]


def test_span_maps_a_part_onto_its_share():
    seen = []
    part = span(lambda s, f: seen.append((s, f)), 0.3, 0.8, "keys")
    part("x", 0.0)
    part("y", 0.5)
    part("z", 2.0)  # clamped to the part's end
    assert seen == [("keys", 0.3), ("keys", 0.55), ("keys", 0.8)]
    assert span(lambda s, f: None, 0.0, 1.0)("a", 0.5) is None
