"""Typed keys of the study's results and the files that hold them.

A curve is identified by a :class:`CurveKey` (configuration, level index, the Rq of its surface);
the key's fields are stored inside each curve file, and results are found again by reading them,
never by parsing a file name. File names and the labels of ``summary.json`` come from
:func:`rq_label`, which prints an Rq so that it reads back as the same float (``1`` for 1.0,
``1.2345678`` for 1.2345678), so distinct values never share a name.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path


def rq_label(rq_um: float) -> str:
    """Shortest text of an Rq in µm that reads back as the same float (for names; never parsed)."""
    text = f"{rq_um:g}"
    return text if float(text) == float(rq_um) else repr(float(rq_um))


@dataclass(frozen=True)
class CurveKey:
    """Which FRF a curve is.

    Attributes:
        config: configuration ('baseline', 'smooth-ms', 'v1', 'v2', 'v3').
        level_index: index into the study's excitation levels; None for the small-excitation
            check (a level far below first slip).
        rq_um: Rq of the surface behind a v3 curve, µm (None for the fixed configurations).
    """
    config: str
    level_index: int | None
    rq_um: float | None = None

    @property
    def name(self) -> str:
        """File stem and summary label, e.g. ``baseline@L1``, ``v3-rq10@L1``, ``check-linear@tiny``."""
        if self.level_index is None:
            return f"check-linear@tiny"
        head = self.config if self.rq_um is None else f"{self.config}-rq{rq_label(self.rq_um)}"
        return f"{head}@L{self.level_index}"

    def to_fields(self) -> dict:
        """The key as numbers and text to store inside a curve file (-1 / NaN for None)."""
        return {"config": self.config,
                "level_index": -1 if self.level_index is None else int(self.level_index),
                "rq_um": math.nan if self.rq_um is None else float(self.rq_um)}

    @classmethod
    def from_fields(cls, config: str, level_index: int, rq_um: float) -> "CurveKey":
        """Inverse of :meth:`to_fields`."""
        return cls(str(config), None if int(level_index) < 0 else int(level_index),
                   None if math.isnan(float(rq_um)) else float(rq_um))


def v3_job_name(rq_um: float) -> str:
    """File stem of a v3 fixed point's record (``v3-rq10.json``, ``v3-rq10.arrays.npz``)."""
    return f"v3-rq{rq_label(rq_um)}"


def load_curves(folder: Path) -> dict:
    """Every finished curve in a dynamics folder: {CurveKey: CurveResult}, keys read from the files."""
    from .frf import CurveResult
    out = {}
    for f in sorted(Path(folder).glob("*.npz")):
        if f.name.endswith(".arrays.npz"):
            continue
        cr = CurveResult.load(f)
        out[cr.key] = cr
    return out


#: the dynamics subfolder of the backbones (kept apart from the curves, which ``load_curves``
#: reads from every ``dynamics/*.npz``)
BACKBONE_DIR = "backbones"


@dataclass(frozen=True)
class BackboneKey:
    """Which nonlinear mode (backbone) a file holds.

    Attributes:
        config: configuration ('baseline', 'smooth-ms', 'v1', 'v2', 'v3').
        rq_um: Rq of the surface behind a v3 joint, µm (None for the fixed configurations).
    """
    config: str
    rq_um: float | None = None

    @property
    def name(self) -> str:
        """File stem and summary label, e.g. ``baseline``, ``v3-rq10``."""
        return self.config if self.rq_um is None else f"{self.config}-rq{rq_label(self.rq_um)}"

    def to_fields(self) -> dict:
        """The key as text and a number to store inside a backbone file (NaN for None)."""
        return {"config": self.config, "rq_um": math.nan if self.rq_um is None else float(self.rq_um)}

    @classmethod
    def from_fields(cls, config: str, rq_um: float) -> "BackboneKey":
        """Inverse of :meth:`to_fields`."""
        return cls(str(config), None if math.isnan(float(rq_um)) else float(rq_um))


def load_backbones(folder: Path) -> dict:
    """Every finished backbone of a dynamics folder: {BackboneKey: BackboneResult}, keys read
    from the files (``folder/backbones/*.npz``)."""
    from .backbone import BackboneResult
    out = {}
    for f in sorted((Path(folder) / BACKBONE_DIR).glob("*.npz")):
        br = BackboneResult.load(f)
        out[br.key] = br
    return out
