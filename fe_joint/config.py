"""Case files: TOML → typed, validated dataclasses.

A case file has one table per stage (``[geometry]``, ``[material]``, ``[preload]``,
``[reduction]``, ``[roughness]``, ``[contact]``, ``[dynamics]``) plus a top-level ``name``. Every
key is optional: missing keys take the defaults of the embedded default case (the paper's
resonator study, DESIGN §4.6). Unknown keys, wrong types and out-of-range values raise
:class:`CaseError` with one line naming the key (``section.key``) and the allowed range.

Presets overlay a few keys on the case: ``quick`` (coarse everything; what tests and demos use),
``default`` (nothing changed: the embedded case, ≤ 15 min on 2 cores) and ``paper`` (the paper's
resolution everywhere).

Units: N, mm, s, tonne (MPa, t/mm³). Roughness is given in µm (``rq_um``) because that is how
every drawing and the paper state it; it is converted to mm where it is used.
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from geometry.resonator import ResonatorParams


class CaseError(ValueError):
    """A case file (or preset/override) value is invalid; the message names the key."""


def _rng(lo: float | None = None, hi: float | None = None, lo_open: bool = False,
         hi_open: bool = False, choices: tuple | None = None, item: bool = False) -> dict:
    """Field metadata describing the allowed range (``item``: applies to each list element)."""
    return {"lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open, "choices": choices,
            "item": item}


def _f(default: Any, **kw) -> Any:
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata=_rng(**kw))
    return field(default=default, metadata=_rng(**kw))


@dataclass(frozen=True)
class Material:
    """Linear elastic steel of both parts and the bolt."""
    young: float = _f(198400.0, lo=0.0, lo_open=True)        # MPa
    poisson: float = _f(0.3, lo=0.0, hi=0.5, hi_open=True)
    density: float = _f(7.949e-9, lo=0.0, lo_open=True)      # t/mm³


@dataclass(frozen=True)
class Preload:
    bolt_force: float = _f(30000.0, lo=0.0, lo_open=True)    # N, target shank force


@dataclass(frozen=True)
class Reduction:
    """Modal analysis and Craig–Bampton reduction."""
    cutoff_hz: float = _f(60000.0, lo=0.0, lo_open=True)     # fixed-interface modes kept below this
    damping_ratio: float = _f(0.001, lo=0.0, hi=1.0, hi_open=True)  # modal damping of the reduced model
    n_check_modes: int = _f(10, lo=1, hi=100)                 # elastic modes compared reduced vs full


@dataclass(frozen=True)
class Roughness:
    """Composite rough surface (one rough face against a smooth flat, DESIGN §3)."""
    rq_um: list = _f([1.0, 5.0, 10.0, 15.0], lo=0.0, lo_open=True, hi=1000.0, item=True)  # Rq sweep, µm
    v_rq_um: float = _f(10.0, lo=0.0, lo_open=True, hi=1000.0)   # Rq of the v1/v2/v3 comparison, µm
    smooth_rq_um: float = _f(0.03, lo=0.0, lo_open=True, hi=1000.0)  # "smooth-ms": finest ISO 1302 finish
    corr_length: float = _f(0.5, lo=0.0, lo_open=True)          # mm, ACF falls to 10 %
    seed: int = _f(0, lo=0)
    grid: int = _f(256, lo=16, hi=4096)                          # global BEM grid (grid × grid)
    patch: int = _f(16, lo=4, hi=256)                            # local patch per friction element
    hardness: float = _f(0.0, lo=0.0)                            # MPa; 0 = purely elastic (the paper)


@dataclass(frozen=True)
class Contact:
    """Friction elements."""
    mu: float = _f(0.6, lo=0.0, lo_open=True, hi=10.0)
    k_ref: float = _f(6.0e4, lo=0.0, lo_open=True)               # N/mm³, baseline k_n = k_t
    kt_tol: float = _f(1e-3, lo=0.0, lo_open=True, hi=0.5)       # k_t fixed point: rel. change of f_res, peak
    kt_max_passes: int = _f(5, lo=1, hi=50)


@dataclass(frozen=True)
class Dynamics:
    """Multiharmonic balance and the frequency sweeps."""
    harmonics: int = _f(3, lo=1, hi=15)
    samples: int = _f(128, lo=8, hi=8192)
    # excitation amplitudes on mass A in x (N); "auto" picks three levels from mostly stuck to
    # extensive slip with the nonlinear model (DESIGN §4.6)
    levels: Any = _f("auto")
    band: list = _f([0.93, 1.01], lo=0.0, lo_open=True, hi=10.0, item=True)  # sweep band / f_linear
    max_points: int = _f(400, lo=10, hi=100000)
    speed_study: bool = _f(True)                                   # speed-vs-error tables in the report
    configurations: list = _f(["baseline", "smooth-ms", "v1", "v2", "v3"],
                              choices=("baseline", "smooth-ms", "v1", "v2", "v3"), item=True)


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

    def section_hash(self, *sections: str) -> str:
        """Stable hash of the named sections (the inputs a stage depends on)."""
        d = self.to_dict()
        blob = json.dumps({s: d[s] for s in sections}, sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


PRESETS: dict[str, dict] = {
    "default": {},
    # coarse and small everywhere: what tests and demos run (a few minutes end to end)
    "quick": {
        "geometry": {"lap_mesh_size": 4.0, "body_mesh_size": 14.0},   # 201 pairs, 23k DOFs
        "reduction": {"n_check_modes": 4},
        "roughness": {"grid": 64, "patch": 8, "rq_um": [1.0, 15.0]},
        "dynamics": {"harmonics": 1, "samples": 32, "max_points": 600, "speed_study": False},
        "contact": {"kt_max_passes": 2},
    },
    # the paper's resolution everywhere (256² global grid, 16² patches, 340-ish elements, H = 3)
    "paper": {
        "roughness": {"grid": 256, "patch": 16},
        "dynamics": {"harmonics": 3, "samples": 256, "max_points": 400},
        "contact": {"kt_max_passes": 10, "kt_tol": 1e-3},
    },
}


def _type_name(t: Any) -> str:
    return getattr(t, "__name__", str(t))


def _check_value(key: str, value: Any, f: dataclasses.Field) -> Any:
    """Type- and range-check one value; returns it converted (int → float where a float is due)."""
    md = f.metadata
    ftype = f.type if not isinstance(f.type, str) else {"float": float, "int": int, "str": str,
                                                        "bool": bool, "list": list, "Any": Any}.get(f.type, Any)
    if ftype is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CaseError(f"{key} = {value!r}: must be a number")
        value = float(value)
        if not math.isfinite(value):
            raise CaseError(f"{key} = {value!r}: must be finite")
    elif ftype is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise CaseError(f"{key} = {value!r}: must be an integer")
    elif ftype is bool:
        if not isinstance(value, bool):
            raise CaseError(f"{key} = {value!r}: must be true or false")
    elif ftype is str:
        if not isinstance(value, str):
            raise CaseError(f"{key} = {value!r}: must be a string")
    elif ftype is list:
        if not isinstance(value, list) or not value:
            raise CaseError(f"{key} = {value!r}: must be a non-empty list")
    items = value if (md.get("item") and isinstance(value, list)) else [value]
    for v in items:
        _check_range(key, v, md)
    return value


def _check_range(key: str, v: Any, md: Any) -> None:
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
        rng = f"{left}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}{right}"
        raise CaseError(f"{key} = {v!r}: allowed range {rng}")


def _build_section(name: str, cls: type, table: Any) -> Any:
    if not isinstance(table, dict):
        raise CaseError(f"[{name}] must be a table")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for k in table:
        if k not in fields:
            raise CaseError(f"{name}.{k}: unknown key (allowed: {', '.join(fields)})")
    kwargs = {}
    for k, v in table.items():
        f = fields[k]
        if f.metadata:
            kwargs[k] = _check_value(f"{name}.{k}", v, f)
        else:  # geometry fields: type from the default value, ranges from ResonatorParams.validate
            default = f.default
            if isinstance(default, bool) or not isinstance(default, (int, float)):
                kwargs[k] = v
            elif isinstance(default, int):
                if isinstance(v, bool) or not isinstance(v, int):
                    raise CaseError(f"{name}.{k} = {v!r}: must be an integer")
                kwargs[k] = v
            else:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise CaseError(f"{name}.{k} = {v!r}: must be a finite number")
                kwargs[k] = float(v)
    obj = cls(**kwargs)
    if hasattr(obj, "validate"):
        try:
            obj.validate()
        except ValueError as e:
            msg = str(e)
            raise CaseError(msg if msg.startswith(f"{name}.") else f"{name}.{msg}") from None
    return obj


def _validate_cross(case: Case) -> None:
    r, d = case.roughness, case.dynamics
    if r.patch > r.grid:
        raise CaseError(f"roughness.patch = {r.patch}: must be ≤ roughness.grid ({r.grid})")
    if len(d.band) != 2 or not d.band[0] < d.band[1]:
        raise CaseError(f"dynamics.band = {d.band!r}: must be [low, high] with low < high "
                        "(fractions of the stuck linear frequency)")
    if d.samples < 2 * (2 * d.harmonics + 1):
        raise CaseError(f"dynamics.samples = {d.samples}: must be ≥ 2(2H+1) = "
                        f"{2 * (2 * d.harmonics + 1)} for harmonics = {d.harmonics} (aliasing)")
    lv = d.levels
    if isinstance(lv, str):
        if lv != "auto":
            raise CaseError(f"dynamics.levels = {lv!r}: must be \"auto\" or a list of forces in N > 0")
    elif isinstance(lv, list) and lv:
        for v in lv:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise CaseError(f"dynamics.levels: {v!r} must be a force in N, > 0")
    else:
        raise CaseError(f"dynamics.levels = {lv!r}: must be \"auto\" or a non-empty list of forces in N > 0")


def _merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def case_from_dict(data: dict, preset: str | None = None) -> Case:
    """Validate a parsed TOML dict (+ optional preset overlay) into a :class:`Case`."""
    if not isinstance(data, dict):
        raise CaseError("case must be a TOML table")
    for k in data:
        if k != "name" and k not in SECTIONS:
            raise CaseError(f"{k}: unknown section (allowed: name, {', '.join(SECTIONS)})")
    if preset is not None:
        if preset not in PRESETS:
            raise CaseError(f"--preset {preset!r}: must be one of {', '.join(PRESETS)}")
        data = _merge(data, PRESETS[preset])
    name = data.get("name", "resonator")
    if not isinstance(name, str) or not name or any(c in name for c in "/\\ \t"):
        raise CaseError(f"name = {name!r}: must be a non-empty string without spaces or slashes")
    sections = {s: _build_section(s, cls, data.get(s, {})) for s, cls in SECTIONS.items()}
    case = Case(name=name, **sections)
    _validate_cross(case)
    return case


def default_case_text() -> str:
    """The embedded default case file (the paper's resonator study)."""
    return resources.files("fe_joint").joinpath("cases/resonator.toml").read_text()


def load_case(path: str | Path | None = None, preset: str | None = None) -> Case:
    """Read and validate a case file (``None``: the embedded default case).

    Raises:
        CaseError: unreadable file, TOML syntax error, unknown key, wrong type or range.
    """
    if path is None:
        text, where = default_case_text(), "default case"
    else:
        p = Path(path)
        try:
            text = p.read_text()
        except OSError as e:
            raise CaseError(f"case file {str(p)!r}: {e.strerror or e}") from None
        where = str(p)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise CaseError(f"{where}: TOML syntax error: {e}") from None
    return case_from_dict(data, preset=preset)


def case_to_toml(case: Case) -> str:
    """Write a case back as TOML (round-trips through :func:`load_case`)."""
    def fmt(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, float):
            return repr(v)
        if isinstance(v, list):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        return str(v)

    d = case.to_dict()
    lines = [f"name = {fmt(d['name'])}", ""]
    for s in SECTIONS:
        lines.append(f"[{s}]")
        lines += [f"{k} = {fmt(v)}" for k, v in d[s].items()]
        lines.append("")
    return "\n".join(lines)
