"""Progress through the whole conversion, the writer included: the CLI's bar and ETA and the web job page read it,
and the web runner's callback stops a cancelled job by raising from it."""

import pytest

from converter import formats
from converter.convert import PREPARED_AT, SIMPLIFY_FROM, WRITE_FROM, convert_animation, prepared_at
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


def test_a_triangle_budget_reports_its_passes_and_takes_its_share(anim):
    # The sample's 2,998 triangles to 400: the budget's passes over every frame get a share of the bar of their own
    # (before, one jump to 0.1 after them), and the 2D stage and the writer keep theirs of what is left.
    options = ConversionOptions(size=256, max_triangles=400)
    ready = prepared_at(anim, options)
    assert SIMPLIFY_FROM < PREPARED_AT < ready < 0.5
    data, calls = recorded(anim, options)
    fractions = [f for _, f in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    budget = [f for s, f in calls if s == "simplify"]
    assert budget[0] >= SIMPLIFY_FROM and budget[-1] == pytest.approx(ready)
    assert len({round(f, 6) for f in budget}) >= 8, budget  # facing, motion and deviation steps
    assert min(f for s, f in calls if s not in ("load", "simplify")) >= ready - 1e-12
    assert data == convert_animation(anim, options).data  # reporting changes nothing


def test_the_budget_share_follows_the_triangles_it_removes():
    class Face:  # prepared_at reads only the triangle count
        n_faces = 51_000

    shares = [prepared_at(Face, ConversionOptions(max_triangles=n)) for n in (51_000, 20_000, 1_500, 100)]
    assert shares[0] == PREPARED_AT and shares == sorted(shares) and shares[-1] < 1.0
    assert shares[2] > 0.5  # ICT head to 1,500: its passes are more than half of the whole conversion
    assert prepared_at(Face, ConversionOptions()) == PREPARED_AT


def test_a_callback_that_raises_stops_the_budget(anim):
    class Stop(Exception):
        pass

    def stop(name: str, fraction: float) -> None:
        if name == "simplify":
            raise Stop(fraction)

    with pytest.raises(Stop):
        convert_animation(anim, ConversionOptions(size=256, max_triangles=400), progress=stop)
