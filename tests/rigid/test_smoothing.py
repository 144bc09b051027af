"""--smooth: jitter out, deviation reported, verifier measures against the smoothed input, bad values refused."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from converter import smoothing
from converter.convert import convert_animation
from converter.errors import InputError
from converter.extract import fit_camera
from converter.options import ConversionOptions, Report
from tests.rigid.synth import captured_head


def test_smoothing_removes_jitter_and_reports_its_deviation():
    noisy, clean = captured_head(200, jitter=1.0), captured_head(200, jitter=0.0)  # slow motion, fast jitter
    options = ConversionOptions(size=256, smooth=1.5)
    report = Report()
    out = smoothing.apply(noisy, options, report)
    cam = fit_camera(clean, 256)
    before = np.linalg.norm(cam.project(noisy.frames)[0] - cam.project(clean.frames)[0], axis=-1)
    after = np.linalg.norm(cam.project(out.frames)[0] - cam.project(clean.frames)[0], axis=-1)
    assert np.median(after) < 0.7 * np.median(before)  # closer to the jitter-free motion
    mx, mean = smoothing.deviation_px(noisy.frames, out.frames, fit_camera(out, 256))
    assert report.figures["smooth_max_px"] == pytest.approx(mx) and mx > mean > 0
    assert out.faces is noisy.faces or np.array_equal(out.faces, noisy.faces)


def test_zero_is_identity_and_bad_values_are_refused():
    anim = captured_head(10)
    assert smoothing.smooth(anim, 0.0) is anim
    for bad in (-1.0, float("nan"), 1000.0):
        with pytest.raises(InputError):
            smoothing.smooth(anim, bad)
    with pytest.raises(InputError):
        ConversionOptions(smooth=-0.5)


def test_smoothed_svg_verifies_against_smoothed_input():
    from converter import verify

    anim = captured_head(30)
    options = ConversionOptions(size=192, smooth=1.0, occlusion=False, tolerance=0.5)
    result = convert_animation(anim, options)
    assert result.report.figures["smooth_max_px"] > 0
    v = verify.verify_animation(result.data, smoothing.smooth(anim, 1.0))
    assert v.ok, v.summary()
    raw = verify.verify_animation(result.data, anim)  # against the unsmoothed input: within tol + deviation
    assert raw.max_px <= 0.5 + result.report.figures["smooth_max_px"] + 1e-6


def test_cli_has_smooth_and_no_rigid_flags():
    import argparse

    from converter.cli import add_conversion_options, options_from_args

    p = argparse.ArgumentParser()
    add_conversion_options(p)
    o = options_from_args(p.parse_args(["--smooth", "2", "--no-rigid"]))
    assert o.smooth == 2.0 and o.rigid is False
    assert options_from_args(p.parse_args([])).rigid is True
    r = subprocess.run([sys.executable, "-m", "converter.cli", "convert", "x.glb", "--smooth", "-3"],
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2 and "smooth" in r.stderr.lower() and "Traceback" not in r.stderr
