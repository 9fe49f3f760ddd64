"""The case: one typed, validated dataclass per section (the settings that travel whole).

A case file has one table per stage (``[geometry]``, ``[material]``, ``[preload]``,
``[reduction]``, ``[roughness]``, ``[contact]``, ``[dynamics]``) plus a top-level ``name``. Every
key is optional: missing keys take the defaults of the embedded default case (the paper's
resonator study, docs/design.md, "Configurations"). Unknown keys, wrong types and out-of-range values raise
:class:`CaseError` with one line naming the key (``section.key``) and the allowed range.

Presets set a few keys the case file does not write: ``quick`` (coarse everything; what tests and
demos use), ``default`` (nothing changed: the embedded case, ≤ 15 min on 2 cores) and ``paper``
(the paper's resolution everywhere). A key written in the case file wins over the preset.

Units: N, mm, s, tonne (MPa, t/mm³). Roughness is given in µm (``rq_um``) because that is how
every drawing and the paper state it; it is converted to mm where it is used.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

from geometry.resonator import ResonatorParams

from ..errors import CaseError




def _rng(lo: float | None = None, hi: float | None = None, lo_open: bool = False,
         hi_open: bool = False, choices: tuple | None = None, item: bool = False,
         unit: str = "") -> dict:
    """Field metadata describing the allowed range (``item``: applies to each list element).

    The bounds are physical, not numerical: wide enough for any steel-like joint, narrow enough
    that 1e300 or 1e-300 never reaches a solver (issue 14)."""
    return {"lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open, "choices": choices,
            "item": item, "unit": unit}


def _f(default: Any, **kw) -> Any:
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata=_rng(**kw))
    return field(default=default, metadata=_rng(**kw))


#: the joint configurations of the study (paper Table 1; docs/design.md, "Configurations")
CONFIGURATIONS = ("baseline", "smooth-ms", "v1", "v2", "v3")


class _Section:
    """Mixin: check every field's range (field metadata) when the section object is made, so a
    section is valid wherever it comes from (a case file or Python)."""
    section: ClassVar[str] = ""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if not f.metadata:
                continue
            v = getattr(self, f.name)
            items = v if (f.metadata.get("item") and isinstance(v, list)) else [v]
            for x in items:
                check_range(f"{self.section}.{f.name}", x, f.metadata)


def _num(x: float) -> str:
    """A bound as written in a message: 16, 2147483647, 0.5, 1e+07."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def check_range(key: str, v: Any, md: Any) -> None:
    """Raise :class:`CaseError` naming ``key`` and the allowed range unless ``v`` is in it."""
    choices = md.get("choices")
    if choices is not None:
        if v not in choices:
            raise CaseError(f"{key}: {v!r} is not one of {', '.join(map(str, choices))}")
        return
    lo, hi = md.get("lo"), md.get("hi")
    if lo is None and hi is None:
        return
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise CaseError(f"{key} = {v!r}: must be a finite number")
    bad = ((lo is not None and (v < lo or (md.get("lo_open") and v == lo))) or
           (hi is not None and (v > hi or (md.get("hi_open") and v == hi))))
    if bad:
        left = "(" if md.get("lo_open") else "["
        right = ")" if md.get("hi_open") else "]"
        rng = f"{left}{_num(lo) if lo is not None else '-inf'}, {_num(hi) if hi is not None else 'inf'}{right}"
        unit = f" {md['unit']}" if md.get("unit") else ""
        raise CaseError(f"{key} = {v!r}: allowed range {rng}{unit}")



@dataclass(frozen=True)
class Material(_Section):
    """Linear elastic steel of both parts and the bolt."""
    section: ClassVar[str] = "material"
    young: float = _f(198400.0, lo=1.0, hi=1e7, unit="MPa")        # MPa
    poisson: float = _f(0.3, lo=0.0, hi=0.5, hi_open=True)
    density: float = _f(7.949e-9, lo=1e-12, hi=1e-7, unit="t/mm³")      # t/mm³

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé parameters (lambda, mu), MPa."""
        e, nu = self.young, self.poisson
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))


@dataclass(frozen=True)
class Preload(_Section):
    section: ClassVar[str] = "preload"
    bolt_force: float = _f(30000.0, lo=1.0, hi=1e7, unit="N")    # N, target shank force


@dataclass(frozen=True)
class Reduction(_Section):
    """Modal analysis and Craig–Bampton reduction."""
    section: ClassVar[str] = "reduction"
    cutoff_hz: float = _f(60000.0, lo=1.0, hi=1e7, unit="Hz")     # fixed-interface modes kept below this
    damping_ratio: float = _f(0.001, lo=0.0, hi=1.0, hi_open=True)  # modal damping of the reduced model
    n_check_modes: int = _f(10, lo=1, hi=100)                 # elastic modes compared reduced vs full


@dataclass(frozen=True)
class Roughness(_Section):
    """Composite rough surface (one rough face against a smooth flat, docs/design.md, "Units and conventions")."""
    section: ClassVar[str] = "roughness"
    rq_um: list = _f([1.0, 5.0, 10.0, 15.0], lo=1e-3, hi=1000.0, item=True, unit="µm")  # Rq sweep, µm
    v_rq_um: float = _f(10.0, lo=1e-3, hi=1000.0, unit="µm")   # Rq of the v1/v2/v3 comparison, µm
    smooth_rq_um: float = _f(0.03, lo=1e-3, hi=1000.0, unit="µm")  # "smooth-ms": finest ISO 1302 finish
    corr_length: float = _f(0.5, lo=1e-3, hi=100.0, unit="mm")          # mm, ACF falls to 10 %
    seed: int = _f(0, lo=0, hi=2**31 - 1)
    grid: int = _f(256, lo=16, hi=4096)                          # global BEM grid (grid × grid)
    patch: int = _f(16, lo=4, hi=256)                            # local patch per friction element
    hardness: float = _f(0.0, lo=0.0, hi=1e6, unit="MPa")                            # MPa; 0 = purely elastic (the paper)
    # surface realizations per Rq of the contact-stage seed statistics (seeds seed … seed+seeds−1;
    # contact area, k_eq, stuck frequency; no FRFs): docs/design.md, "Rough contact"
    seeds: int = _f(5, lo=1, hi=100)
    # MPa, indentation hardness of the faces (stainless steel ≈ 200 HV ≈ 2.0 GPa): the report sets
    # the peak asperity pressures beside it and the contact stage repeats the sweep with the
    # pressure capped at it (0: no capped variant); ``hardness`` > 0 caps the study itself
    material_hardness: float = _f(2000.0, lo=0.0, hi=1e6, unit="MPa")


@dataclass(frozen=True)
class Contact(_Section):
    """Friction elements."""
    section: ClassVar[str] = "contact"
    mu: float = _f(0.6, lo=1e-3, hi=10.0)
    k_ref: float = _f(6.0e4, lo=1.0, hi=1e10, unit="N/mm³")               # N/mm³, baseline k_n = k_t
    kt_tol: float = _f(1e-3, lo=1e-9, hi=0.5)       # k_t fixed point: rel. change of f_res, peak
    kt_max_passes: int = _f(5, lo=1, hi=50)


@dataclass(frozen=True)
class Dynamics(_Section):
    """Multiharmonic balance and the frequency sweeps."""
    section: ClassVar[str] = "dynamics"
    harmonics: int = _f(3, lo=1, hi=15)
    samples: int = _f(128, lo=8, hi=8192)
    # excitation amplitudes on mass A in x (N); "auto" picks three levels from mostly stuck to
    # extensive slip from the stuck-joint estimate (docs/design.md, "Excitation levels")
    levels: Any = _f("auto")
    band: list = _f([0.93, 1.01], lo=0.01, hi=10.0, item=True)  # sweep band / f_linear
    max_points: int = _f(400, lo=10, hi=100000)
    speed_study: bool = _f(True)                                   # speed-vs-error tables in the report
    configurations: list = _f(list(CONFIGURATIONS), choices=CONFIGURATIONS, item=True)


SECTIONS: dict[str, type] = {
    "geometry": ResonatorParams,
    "material": Material,
    "preload": Preload,
    "reduction": Reduction,
    "roughness": Roughness,
    "contact": Contact,
    "dynamics": Dynamics,
}


@dataclass(frozen=True)
class Case:
    """A validated case: one dataclass per section."""
    name: str
    geometry: ResonatorParams
    material: Material
    preload: Preload
    reduction: Reduction
    roughness: Roughness
    contact: Contact
    dynamics: Dynamics

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"name": self.name}
        for s in SECTIONS:
            d[s] = dataclasses.asdict(getattr(self, s))
        return d

    def section_hash(self, *inputs: str) -> str:
        """Stable hash of the named inputs: whole sections ("roughness") or single keys
        ("dynamics.harmonics") — exactly what a stage reads."""
        d = self.to_dict()
        picked = {}
        for name in inputs:
            section, _, key = name.partition(".")
            picked[name] = d[section][key] if key else d[section]
        blob = json.dumps(picked, sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


