"""A worker warms the converter's kernels before its first claim, and a failure there does not stop it."""

from __future__ import annotations

import logging

from converter import warm
from webapp import warmup


def test_warm_up_loads_every_kernel_and_logs_it(caplog):
    with caplog.at_level(logging.INFO, logger="facesvg.webapp"):
        warmup.warm_converter()
    assert any("worker warm-up:" in r.message and "kernels" in r.message for r in caplog.records)
    assert len(warm._counts(warm.kernels(), "cache_hits")) + len(warm._counts(warm.kernels(), "cache_misses")) >= 20


def test_a_failed_warm_up_is_logged_and_the_worker_goes_on(caplog, monkeypatch):
    def broken(*a, **k):
        raise RuntimeError("no sample")

    monkeypatch.setattr(warm, "warm", broken)
    with caplog.at_level(logging.WARNING, logger="facesvg.webapp"):
        assert warmup.warm_converter() is None
    assert any("worker warm-up skipped: RuntimeError: no sample" in r.message for r in caplog.records)
