"""Reading a case: TOML → presets → typed sections (:mod:`.schema`) → cross-checks.

Every key is optional: missing keys take the defaults of the embedded default case
(``fe_joint/cases/resonator.toml``). Unknown keys and wrong types raise :class:`CaseError` here;
ranges are checked by the section dataclasses themselves; cross-section rules by
:func:`_validate_cross`. One line names the key (``section.key``) and the allowed range.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from ..errors import CaseError
from .schema import SECTIONS, Case


PRESETS: dict[str, dict] = {
    "default": {},
    # coarse and small everywhere: what tests and demos run (a few minutes end to end)
    "quick": {
        "geometry": {"lap_mesh_size": 4.0, "body_mesh_size": 14.0},   # 201 pairs, 29 769 P2 DOFs
        "reduction": {"n_check_modes": 4},
        "roughness": {"grid": 64, "patch": 8, "rq_um": [1.0, 15.0], "seeds": 3},
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
    """Type-check one value; returns it converted (int → float where a float is due). Ranges are
    checked by the section dataclass when it is made."""
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
    return value   # ranges: checked by the section dataclass (schema._Section)


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
