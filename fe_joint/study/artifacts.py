"""Typed keys of the study's results and the files that hold them.

A curve is identified by a :class:`CurveKey` (configuration, level index, the Rq of its surface);
the key's fields are stored inside each curve file, and results are found again by reading them,
never by parsing a file name. File names and the labels of ``summary.json`` come from
:func:`rq_label`, which prints an Rq so that it reads back as the same float (``1`` for 1.0,
``1.2345678`` for 1.2345678), so distinct values never share a name.

It also holds what every stage uses to trust a file again (docs/design.md, "Caching and
resume"): :func:`file_record` (size and sha256 of what a stage or a job wrote),
:func:`check_files` (the first missing, truncated or changed one), :func:`load_artifact` (a
loader whose failure names the path) and :func:`digest` (the cache key of a curve from the data
it is computed from).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..errors import ArtifactError


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


#: files of a dynamics folder that hold a job's data but are not a study curve
NOT_CURVES = (".arrays.npz", ".pass0.npz")


def v3_pass0_file(rq_um: float) -> str:
    """File of a v3 fixed point's pass-0 FRF (the v2 joint at the middle level)."""
    return f"{v3_job_name(rq_um)}.pass0.npz"


def load_curves(folder: Path, names: Iterable[str] | None = None) -> dict:
    """Finished curves of a dynamics folder: {CurveKey: CurveResult}, keys read from the files.

    Args:
        folder: the dynamics folder.
        names: curve names (file stems) to load; None: every curve file in the folder.
    Raises:
        ArtifactError naming the file when one cannot be read.
    """
    from .frf import CurveResult
    folder = Path(folder)
    if names is None:
        files = [f for f in sorted(folder.glob("*.npz")) if not f.name.endswith(NOT_CURVES)
                 and not f.name.endswith(".tmp.npz")]
    else:
        files = [folder / f"{n}.npz" for n in names]
    out = {}
    for f in files:
        cr = load_artifact(f, CurveResult.load)
        out[cr.key] = cr
    return out


# --- trusting files again -------------------------------------------------------------------

#: what a loader raises for a broken file: numpy's zip reader, h5py (OSError, KeyError for a
#: missing dataset), json, a field of the wrong shape or type
LOAD_ERRORS = (OSError, ValueError, KeyError, EOFError, TypeError, IndexError, zipfile.BadZipFile)


@contextmanager
def artifact(path: Path) -> Iterator[None]:
    """Turn a failure while reading ``path`` into one :class:`ArtifactError` line naming it."""
    try:
        yield
    except ArtifactError:
        raise
    except LOAD_ERRORS as e:
        why = " ".join(str(e).split()) or type(e).__name__
        raise ArtifactError(f"{path}: cannot be read ({type(e).__name__}: {why[:160]}); run again "
                            "to rebuild it (or --force the stage that writes it)") from e


def load_artifact(path: Path, loader: Callable):
    """``loader(path)``; a missing or unreadable file raises ArtifactError naming ``path``."""
    path = Path(path)
    if not path.is_file():
        raise ArtifactError(f"{path}: missing; rerun the stage that writes it")
    with artifact(path):
        return loader(path)


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes (≈ 0.1 s for the quick preset's 40 MB reduced model)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def file_record(root: Path, paths: Iterable[Path]) -> dict[str, dict]:
    """{path relative to ``root`` (posix): {"size": bytes, "sha256": hex}} of existing files.

    Folders are walked (every file below them); paths that do not exist are left out.
    """
    root = Path(root)
    files: list[Path] = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            files += [f for f in p.rglob("*") if f.is_file()]
        elif p.is_file():
            files.append(p)
    return {f.relative_to(root).as_posix(): {"size": f.stat().st_size, "sha256": sha256_file(f)}
            for f in sorted(set(files))}


def file_problem(root: Path, rel: str, rec: dict) -> str | None:
    """Why the file ``root/rel`` no longer matches its record, None if it does.

    Returns:
        "missing", "truncated (a of b bytes)", "changed (a bytes, was b)" or "changed
        (sha256 differs)".
    """
    f = Path(root) / rel
    if not f.is_file():
        return "missing"
    size = f.stat().st_size
    if size < rec["size"]:
        return f"truncated ({size} of {rec['size']} bytes)"
    if size != rec["size"]:
        return f"changed ({size} bytes, was {rec['size']})"
    if sha256_file(f) != rec["sha256"]:
        return "changed (sha256 differs)"
    return None


def check_files(root: Path, record: dict[str, dict]) -> str | None:
    """The first file of ``record`` that does not match, as ``"<path> <problem>"``; None if all do.

    Args:
        root: the folder the record's paths are relative to.
        record: what :func:`file_record` returned when the files were written.
    """
    bad = [(rel, why) for rel in sorted(record) if (why := file_problem(root, rel, record[rel]))]
    if not bad:
        return None
    more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
    return f"{bad[0][0]} {bad[0][1]}{more}"


def digest(*parts) -> str:
    """A 16-hex cache key of numbers, text, arrays and dataclasses of them (order matters).

    Arrays enter by dtype, shape and bytes, floats by their exact repr, dataclasses by their
    fields: two inputs get the same key only if every number a computation reads is the same.
    """
    h = hashlib.sha256()

    def feed(x) -> None:
        if isinstance(x, np.ndarray):
            a = np.ascontiguousarray(x)
            h.update(f"nd|{a.dtype.str}|{a.shape}|".encode())
            h.update(a.tobytes())
        elif dataclasses.is_dataclass(x) and not isinstance(x, type):
            h.update(f"dc|{type(x).__name__}|".encode())
            for f in dataclasses.fields(x):
                h.update(f"{f.name}=".encode())
                feed(getattr(x, f.name))
        elif isinstance(x, dict):
            h.update(b"{")
            for k in sorted(x, key=str):
                h.update(f"{k}:".encode())
                feed(x[k])
            h.update(b"}")
        elif isinstance(x, (list, tuple)):
            h.update(f"[{len(x)}|".encode())
            for v in x:
                feed(v)
            h.update(b"]")
        elif isinstance(x, (bool, int, str, type(None))):
            h.update(f"{type(x).__name__}:{x!r}|".encode())
        elif isinstance(x, (float, np.floating, np.integer)):
            h.update(f"f:{float(x)!r}|".encode())
        else:
            raise TypeError(f"digest: no stable encoding for {type(x).__name__}")

    for p in parts:
        feed(p)
    return h.hexdigest()[:16]


def read_json_artifact(path: Path) -> dict:
    """A JSON artifact; a missing or broken one raises ArtifactError naming ``path``."""
    return load_artifact(path, lambda p: json.loads(Path(p).read_text()))

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


def save_dataclass_npz(obj, path: Path) -> None:
    """Write a dataclass of arrays and numbers as one ``.npz`` (field name → array), atomically:
    a killed run leaves the old file or none, never half of one."""
    tmp = Path(str(path) + ".tmp.npz")
    np.savez(tmp, **{k: np.asarray(v) for k, v in dataclasses.asdict(obj).items()})
    tmp.replace(path)
