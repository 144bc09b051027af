"""Facts from the MPEG-4 face animation standard: the 68-FAP table, FAPU names, feature-point ids."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import numpy as np

N_FAPS = 68
FAPU_NAMES = ("IRISD0", "ES0", "ENS0", "MNS0", "MW0")
AU = 1e-5  # angle unit in radians
FAPU_DIVISOR = 1024.0  # FAPU = neutral distance / 1024

# Feature points per group (ISO/IEC 14496-2 figure C.1); 2.x jaw/lips, 3.x eyes, 4.x brows, 5.x cheeks,
# 6.x tongue, 7.1 top of spine, 8.x outer lips, 9.x nose/teeth, 10.x ears, 11.x hairline/skull.
FEATURE_POINTS: tuple[str, ...] = tuple(
    [f"2.{i}" for i in range(1, 15)] + [f"3.{i}" for i in range(1, 15)] + [f"4.{i}" for i in range(1, 7)]
    + [f"5.{i}" for i in range(1, 5)] + [f"6.{i}" for i in range(1, 5)] + ["7.1"]
    + [f"8.{i}" for i in range(1, 11)] + [f"9.{i}" for i in range(1, 16)] + [f"10.{i}" for i in range(1, 11)]
    + [f"11.{i}" for i in range(1, 7)]
)


@dataclass(frozen=True)
class FapDef:
    """One row of the FAP table."""

    number: int  # 1..68
    name: str
    unit: str  # IRISD, ES, ENS, MNS, MW, AU or na
    bidirectional: bool
    axis: str  # "+x", "-y", "rot+y", "scale+", "roll(...)", "na"
    group: int
    fdp: str  # feature point id like "2.1", "6.3|6.4", or "na"

    @property
    def is_translation(self) -> bool:
        """True when the FAP moves its feature point along one axis."""
        return self.axis[:1] in "+-" and self.axis[1:] in ("x", "y", "z")

    @property
    def axis_index(self) -> int:
        """0, 1, 2 for x, y, z translation or rotation axes; -1 otherwise."""
        return "xyz".find(self.axis[-1]) if self.axis[-1:] in "xyz" else -1

    @property
    def sign(self) -> float:
        """+1 or -1: the direction of a positive value along axis_index."""
        return -1.0 if self.axis.startswith("-") or self.axis.startswith("rot-") else 1.0


@lru_cache(maxsize=1)
def fap_table() -> tuple[FapDef, ...]:
    """The 68 FAPs in order (index k is FAP k+1), read from the bundled faps.csv."""
    text = resources.files("converter.mpeg4").joinpath("faps.csv").read_text(encoding="utf-8")
    rows = csv.DictReader(io.StringIO("".join(line for line in text.splitlines(True) if not line.startswith("#"))))
    table = tuple(
        FapDef(int(r["fap"]), r["name"], r["units"], r["dir"] == "B", r["axis"], int(r["group"]), r["fdp"])
        for r in rows
    )
    assert [f.number for f in table] == list(range(1, N_FAPS + 1)), "faps.csv must list FAPs 1..68 in order"
    return table


def fapu_scale(fapu: dict[str, float]) -> np.ndarray:
    """Per-FAP multiplier (68,) from FAPU units to model units (lengths) or radians (AU); 0 for FAP 1-2."""
    out = np.zeros(N_FAPS)
    for k, f in enumerate(fap_table()):
        if f.unit == "AU":
            out[k] = AU
        elif f.unit != "na":
            out[k] = float(fapu.get(f.unit + "0", 0.0)) / FAPU_DIVISOR
    return out
