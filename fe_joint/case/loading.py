"""Reading a case: defaults ← preset ← case file → typed sections (:mod:`.schema`) → rules.

Every key is optional: missing keys take the defaults of the embedded default case
(``fe_joint/cases/resonator.toml``); a preset sets the keys the case file does not write (a key
written in the file wins). Unknown keys and wrong types raise :class:`CaseError` here; ranges
are checked by the section dataclasses themselves, the geometry's and the rules between keys by
:mod:`.checks`. One line names the key (``section.key``) and the allowed range.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import re
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from ..errors import CaseError
from . import checks
from .checks import Sources
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


def _build_section(name: str, cls: type, table: Any, sources: Sources) -> Any:
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
        else:  # geometry fields: type from the default value, ranges from checks.GEOMETRY_RANGES
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
    if name == "geometry":
        checks.check_geometry_ranges(kwargs)
    obj = cls(**kwargs)
    if name == "geometry":
        checks.check_geometry(obj, sources)
    if hasattr(obj, "validate"):   # the geometry's own rules: a backstop behind check_geometry
        try:
            obj.validate()
        except ValueError as e:
            msg = str(e)
            raise CaseError(msg if msg.startswith(f"{name}.") else f"{name}.{msg}") from None
    if name == "geometry":
        checks.check_mesh_size(obj)
    return obj


def _merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _keys(data: dict) -> list[str]:
    """The keys a layer writes: "name" and "section.key"."""
    out = []
    for k, v in data.items():
        if isinstance(v, dict):
            out += [f"{k}.{kk}" for kk in v]
        else:
            out.append(k)
    return out


#: a case name is a plain file name: it names the default output folder results/<name>
_NAME = re.compile(r"[A-Za-z0-9._-]{1,100}")


def _check_name(name: Any) -> str:
    if not isinstance(name, str) or not _NAME.fullmatch(name) or name in (".", ".."):
        shown = repr(name) if not isinstance(name, str) or len(name) <= 40 else repr(name[:40]) + "…"
        raise CaseError(f"name = {shown}: must be a plain file name of 1 to 100 letters, digits, "
                        "'.', '_' or '-' (not '.' or '..')")
    return name


def _default_data() -> dict:
    return tomllib.loads(default_case_text())


def resolve_case(data: dict, preset: str | None = None) -> tuple[Case, Sources]:
    """Validate a parsed case file over the defaults and a preset; say where each value came from.

    Precedence, lowest first: the embedded default case, the preset, the case file (a key the
    file writes wins over the preset).

    Args:
        data: the parsed case file (``{}``: nothing written).
        preset: a name in :data:`PRESETS`, or None.
    Returns:
        (the case, {"name" or "section.key": "default" | "preset <name>" | "file"}).
    Raises:
        CaseError: unknown section or key, wrong type, out-of-range value, broken rule.
    """
    if not isinstance(data, dict):
        raise CaseError("case must be a TOML table")
    for k in data:
        if k != "name" and k not in SECTIONS:
            raise CaseError(f"{k}: unknown section (allowed: name, {', '.join(SECTIONS)})")
    layers = [("default", _default_data())]
    if preset is not None:
        if preset not in PRESETS:
            raise CaseError(f"--preset {preset!r}: must be one of {', '.join(PRESETS)}")
        layers.append((f"preset {preset}", PRESETS[preset]))
    layers.append(("file", data))
    merged: dict = {}
    sources: Sources = {}
    for label, layer in layers:
        merged = _merge(merged, layer)
        sources.update({k: label for k in _keys(layer)})
    name = _check_name(merged.get("name", "resonator"))
    sections = {s: _build_section(s, cls, merged.get(s, {}), sources) for s, cls in SECTIONS.items()}
    case = Case(name=name, **sections)
    checks.check_cross(case, sources)
    for s, cls in SECTIONS.items():   # keys no layer wrote: the dataclass defaults
        for f in dataclasses.fields(cls):
            sources.setdefault(f"{s}.{f.name}", "default")
    sources.setdefault("name", "default")
    return case, sources


def case_from_dict(data: dict, preset: str | None = None) -> Case:
    """Validate a parsed TOML dict (+ optional preset) into a :class:`Case` (see :func:`resolve_case`)."""
    return resolve_case(data, preset)[0]


def default_case_text() -> str:
    """The embedded default case file (the paper's resonator study)."""
    return resources.files("fe_joint").joinpath("cases/resonator.toml").read_text()


#: a case file is a few kB; anything much larger is not one (and /dev/zero would never end)
_MAX_CASE_BYTES = 1 << 20


def _read_case_file(p: Path) -> str:
    """The text of a case file; every failure a :class:`CaseError` naming the file."""
    where = f"case file {str(p)!r}"
    try:
        if p.is_dir():
            raise CaseError(f"{where}: is a folder, not a TOML file")
        if p.exists() and not p.is_file():
            raise CaseError(f"{where}: is not a regular file")
        with open(p, "rb") as f:
            raw = f.read(_MAX_CASE_BYTES + 1)
    except OSError as e:
        raise CaseError(f"{where}: {e.strerror or e}") from None
    if len(raw) > _MAX_CASE_BYTES:
        raise CaseError(f"{where}: larger than {_MAX_CASE_BYTES // 1024} kB, not a case file")
    try:
        return raw.decode("utf-8-sig")    # a BOM, as some editors write, is fine
    except UnicodeDecodeError as e:
        raise CaseError(f"{where}: not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); "
                        "TOML files must be UTF-8") from None


def load_case_with_sources(path: str | Path | None = None,
                           preset: str | None = None) -> tuple[Case, Sources]:
    """Read and validate a case file (``None``: the defaults alone); see :func:`resolve_case`.

    Raises:
        CaseError: unreadable or undecodable file, TOML syntax error, or any invalid value.
    """
    if path is None:
        return resolve_case({}, preset)
    p = Path(path)
    text = _read_case_file(p)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise CaseError(f"case file {str(p)!r}: TOML syntax error: {e}") from None
    return resolve_case(data, preset)


def load_case(path: str | Path | None = None, preset: str | None = None) -> Case:
    """Read and validate a case file (``None``: the embedded default case); see :func:`resolve_case`.

    Raises:
        CaseError: unreadable file, TOML syntax error, unknown key, wrong type or range.
    """
    return load_case_with_sources(path, preset)[0]


def case_to_toml(case: Case, sources: Sources | None = None) -> str:
    """Write a case back as TOML (round-trips through :func:`load_case`).

    Args:
        case: the case.
        sources: if given (:func:`load_case_with_sources`), each line ends with a comment
            saying where the value came from: ``# default``, ``# preset quick``, ``# file``.
    """
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

    def line(key: str, text: str) -> str:
        if sources is None:
            return text
        return f"{text:<40} # {sources.get(key, 'default')}"

    d = case.to_dict()
    lines = [line("name", f"name = {fmt(d['name'])}"), ""]
    for s in SECTIONS:
        lines.append(f"[{s}]")
        lines += [line(f"{s}.{k}", f"{k} = {fmt(v)}") for k, v in d[s].items()]
        lines.append("")
    return "\n".join(lines)
