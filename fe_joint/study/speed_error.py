"""Speed against error of the study's numerical knobs, for the report.

Each table varies one knob with the others at the case's values and compares against the finest
setting computed in the same run: the global BEM grid (real contact area), the number of
harmonics and the AFT samples (the baseline's FRF peak at the middle level: frequency and
first-harmonic amplitude, each found by a local peak search warm-started from the study's own
curve there, its peak and contact harmonics, :func:`curve_reference`; a cold-start solve at the
peak frequency landed on the lower branch of the fold, 158.5 vs 492 µm on the default case, and
measured the wrong solution's convergence), and the element count: the lap mesh size sets how
many friction elements the interface has (:func:`mesh_rows`, on reduced models the ``speed``
stage builds at coarser lap meshes, each swept as the study sweeps its curves; the case's own
mesh's row is the study's curve; the FE side of mesh convergence is in ``scripts/bench_fe.py``
and ``scripts/bench_geometry.py``).
"""
from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import contact as ms
from .frf import SweepSettings, frf, peak_near


def bem_row(rm, case, n: int) -> dict:
    """Real contact area and time of the global rough solve (Rq of the v-configurations) on an
    n × n grid (errors are added by :func:`bem_errors`)."""
    r = case.roughness
    setup = ms.interface_setup(rm, case.geometry, case.material, dataclasses.replace(r, grid=n))
    t0 = time.perf_counter()
    sc = ms.rough_contact(setup, r.v_rq_um, r.corr_length, r.seed, stiffness=False)
    return {"grid": f"{n}²", "contact [%]": 100 * sc.contact_fraction,
            "iterations": sc.iterations, "time [s]": time.perf_counter() - t0}


def bem_errors(rows: list[dict]) -> list[dict]:
    """Add each row's contact-area error against the last (finest) row, %."""
    ref = rows[-1]["contact [%]"]
    for row in rows:
        row["error vs finest [%]"] = 100 * abs(row["contact [%]"] - ref) / ref
    return rows


def bem_grid(rm, case, grids=(64, 128, 256, 512)) -> list[dict]:
    """Real contact area and time of the global rough solve (Rq of the v-configurations) vs grid."""
    return bem_errors([bem_row(rm, case, n) for n in grids])


#: where the harmonics and samples rows' local peak searches start, relative to the reference
#: peak: just above it, where the branch is single-valued even when it folds below the peak (on
#: the default case H = 1 moves the peak by +0.2 %, the samples by less than 0.02 %)
LOCAL_START = 2e-3


def curve_reference(cr) -> dict:
    """The reference of the harmonics and samples rows, and the case mesh's row of the
    element-count table: the study's own FRF at the case's H and n_t (a ``CurveResult``).

    Its sweep is the one the other rows' are compared with, so it is not run again: the speed
    stage's own sweep of that curve (through ±1 % of its peak) took 18 s of the default study's
    84 s stage, as long as the study's curve over its whole band.

    Returns:
        the row's fields (H, samples, peak [Hz], amplitude [µm], time [s], points) and "guess",
        the contact harmonics at the peak, (ne, 3, 2H + 1) over all pairs: the rows' warm start
        (:func:`hbm_row`); None (and a "note") for a curve saved without them.
    """
    out = {"samples": int(cr.elem_u.shape[1]), "peak [Hz]": cr.peak_hz,
           "amplitude [µm]": 1e3 * cr.peak_amplitude, "time [s]": cr.seconds,
           "points": cr.n_points, "guess": None}
    if cr.peak_contact.size == 0:
        return {**out, "note": "not found (the curve has no contact harmonics at its peak)"}
    return {**out, "harmonics": (cr.peak_contact.shape[2] - 1) // 2,
            "guess": np.asarray(cr.peak_contact, float)}


def with_harmonics(contact: np.ndarray, H: int) -> np.ndarray:
    """Contact harmonics (ne, 3, 2H' + 1) cut or padded with zeros to H harmonics."""
    out = np.zeros(contact.shape[:2] + (2 * H + 1,))
    n = min(out.shape[2], contact.shape[2])
    out[..., :n] = contact[..., :n]
    return out


def hbm_row(rm, joint, level: float, settings: SweepSettings, reference: dict, H: int,
            nt: int) -> dict:
    """The FRF peak (frequency, amplitude) with H harmonics and nt AFT samples, and the time of
    its search: a local peak search (:func:`~fe_joint.study.frf.peak_near`) warm-started from
    the reference peak (:func:`curve_reference`: the study's curve, the case's H and n_t).

    A sweep per row through the peak cost 20-490 s a row on the default model (the n_t = 32
    row's sweep failed with the fast tolerances after 3800 solves before the strict one found
    it); the local search, 5-23 s, finds the same peak (n_t = 64: equal to 1e-10 to a sweep's).
    A search that fails gives a row that says so; no sweep follows (the run's results are not
    affected).

    Args:
        rm, joint, level: the model, the configuration and the level (N).
        settings: the study's sweep settings (H and n_t replaced).
        reference: :func:`curve_reference`'s fields (its "peak [Hz]" and "guess").
        H, nt: the row's harmonics and samples.
    Returns:
        H, samples, peak [Hz], amplitude [µm], time [s], points (of the local branch), and a
        "note" when no peak is found.
    """
    from hbm import ConvergenceError
    out = {"harmonics": H, "samples": nt}
    t0 = time.perf_counter()
    if reference.get("guess") is None:
        return {**out, "peak [Hz]": float("nan"), "amplitude [µm]": float("nan"),
                "time [s]": 0.0, "points": 0, "note": "not found (no reference peak)"}
    st = dataclasses.replace(settings, harmonics=H, samples=nt)
    try:
        cr, _ = peak_near(rm, joint, level, reference["peak [Hz]"] * (1 + LOCAL_START),
                          with_harmonics(np.asarray(reference["guess"]), H), st)
    except ConvergenceError as e:
        why = " ".join(str(e).split())
        return {**out, "peak [Hz]": float("nan"), "amplitude [µm]": float("nan"),
                "time [s]": time.perf_counter() - t0, "points": 0,
                "note": f"not found by the local search from the reference peak ({why})"}
    return {**out, "peak [Hz]": cr.peak_hz, "amplitude [µm]": 1e3 * cr.peak_amplitude,
            "time [s]": time.perf_counter() - t0, "points": cr.n_points}


#: titles of the HBM tables (the report reads them)
HARMONICS_TABLE = ("harmonics (baseline, middle level, FRF peak by a local search from the "
                   "case settings' peak)")
SAMPLES_TABLE = ("AFT samples (baseline, middle level, FRF peak by a local search from the case "
                 "settings' peak)")
MESH_TABLE = ("interface elements (lap mesh size; baseline, middle level, FRF peak by the study's "
              "sweep)")


def knob_grid(harmonics=(1, 3, 5, 7), samples=(16, 32, 64, 128, 256),
              h_fixed: int = 3) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The (H, n_t) rows of the harmonics table (n_t fine enough for the largest H) and of the
    samples table (H = ``h_fixed``)."""
    nt_h = max(256, 4 * (2 * max(harmonics) + 1))
    return [(H, nt_h) for H in harmonics], [(h_fixed, nt) for nt in samples]


def hbm_knobs(rm, joint, settings: SweepSettings, cr, harmonics=(1, 3, 5, 7),
              samples=(16, 32, 64, 128, 256), h_fixed: int = 3) -> dict:
    """The FRF peak (frequency, amplitude) and its search's time vs H and vs AFT samples.

    Args:
        rm: ReducedModel; joint: the configuration.
        settings: the study's sweep settings (μ, max_points; its H and samples are the curve's).
        cr: the study's curve of ``joint`` at one level (``CurveResult``, the reference,
            :func:`curve_reference`).
        harmonics, samples: the values tried; h_fixed: H of the samples table.
    Returns:
        {table title: rows}, each row with H, samples, peak [Hz], amplitude [µm], time [s],
        points, and its errors against the finest row.
    """
    ref = curve_reference(cr)
    hk, sk = knob_grid(harmonics, samples, h_fixed)
    hr = _errors([hbm_row(rm, joint, cr.level, settings, ref, H, nt) for H, nt in hk],
                 f"H={harmonics[-1]}")
    sr = _errors([hbm_row(rm, joint, cr.level, settings, ref, H, nt) for H, nt in sk], "finest")
    return {HARMONICS_TABLE: hr, SAMPLES_TABLE: sr}


#: lap mesh sizes of the element-count table, as multiples of the case's (coarser only: a finer
#: mesh multiplies the FE and HBM cost; the default's 2.8 mm gives 4.0 mm, the quick preset's mesh)
LAP_MESH_FACTORS = (1.43, 1.21)


def lap_mesh_sizes(lap_mesh_size: float) -> list[float]:
    """The coarser lap mesh sizes of the element-count table, mm (rounded to 0.1 mm)."""
    return [round(f * lap_mesh_size, 1) for f in LAP_MESH_FACTORS]


def mesh_row(model: tuple, level: float, settings: SweepSettings) -> dict:
    """One row of the element-count table (errors are added by :func:`mesh_errors`): the
    model's FRF swept as the study sweeps its curves (the band relative to the model's own stuck
    frequency), so that the rows compare like with like and the case mesh's row is the study's
    curve (:func:`curve_fields`).

    Args:
        model: (lap mesh size mm, ReducedModel, FE seconds, baseline JointModel on it).
        level: N; settings: the study's sweep settings.
    Returns:
        lap mesh size, elements, closed pairs, reduced DOFs, stuck and peak frequencies, peak
        amplitude, FE and HBM times, points.
    """
    from hbm import ConvergenceError
    _, rm, _, joint = model
    out = mesh_fields(model)
    t0 = time.perf_counter()
    try:
        cr = frf(rm, joint, level, out["stuck [Hz]"], settings)
        out.update(curve_fields(cr))
    except ConvergenceError as e:
        out.update({"peak [Hz]": float("nan"), "amplitude [µm]": float("nan"),
                    "HBM time [s]": time.perf_counter() - t0, "points": 0, "note": f"not found ({e})"})
    return out


def curve_fields(cr) -> dict:
    """An element-count row's sweep fields from a curve: peak [Hz], amplitude [µm], HBM time [s],
    points."""
    return {"peak [Hz]": cr.peak_hz, "amplitude [µm]": 1e3 * cr.peak_amplitude,
            "HBM time [s]": cr.seconds, "points": cr.n_points}


def mesh_fields(model: tuple) -> dict:
    """The element-count row's fields of the model itself (no sweep): lap mesh size, elements,
    closed pairs, reduced DOFs, stuck frequency, FE time.

    Args:
        model: (lap mesh size mm, ReducedModel, FE seconds, baseline JointModel on it).
    """
    from ..model.joint import stuck_modes
    size, rm, fe_s, joint = model
    return {"lap mesh [mm]": size, "elements": int(rm.n_pairs),
            "closed": int(np.sum(np.asarray(rm.preload_status) != 0)), "reduced DOFs": int(rm.n_dofs),
            "stuck [Hz]": stuck_modes(rm.K, rm.M, rm.pair_dofs, joint).frequency, "FE time [s]": fe_s}


def mesh_errors(rows: list[dict]) -> list[dict]:
    """Add the stuck, peak-frequency and amplitude errors against the last row (the case's mesh)."""
    f0 = rows[-1]["stuck [Hz]"]
    for r in rows:
        r["stuck error vs case mesh [%]"] = 100 * abs(r["stuck [Hz]"] - f0) / f0
    return _errors(rows, "case mesh")


def mesh_rows(models: list, settings: SweepSettings, cr) -> list[dict]:
    """The baseline's stuck frequency and FRF peak at one level against the interface element
    count (:func:`mesh_row` for each coarser model).

    Args:
        models: [(lap mesh size mm, ReducedModel, FE seconds, baseline JointModel on it)], the
            case's own mesh last (the reference row).
        settings: the study's sweep settings (H, samples, μ, band).
        cr: the study's curve of the case's model at the level (``CurveResult``): the last row's
            sweep.
    Returns:
        rows of :func:`mesh_row`, with the errors against the last.
    """
    rows = [mesh_row(m, cr.level, settings) for m in models[:-1]]
    return mesh_errors(rows + [{**mesh_fields(models[-1]), **curve_fields(cr)}])


def _errors(rows: list[dict], ref_name: str) -> list[dict]:
    """Add each row's peak frequency and amplitude errors (%) against the last row."""
    f0, a0 = rows[-1]["peak [Hz]"], rows[-1]["amplitude [µm]"]
    for r in rows:
        r[f"f error vs {ref_name} [%]"] = 100 * abs(r["peak [Hz]"] - f0) / f0
        r[f"amplitude error vs {ref_name} [%]"] = 100 * abs(r["amplitude [µm]"] - a0) / a0
    return rows


# ----------------------------------------------------------------------------- the stage's jobs
@dataclass(frozen=True)
class SpeedJob:
    """One row of a speed-against-error table, a job of the MPI queue (``study.queue``).

    Attributes:
        table: "bem", "harmonics", "samples", "mesh", or "reference" (the study's curve at the
            case's H and n_t, :func:`curve_reference`, that the harmonics and samples rows start
            from; not a table of its own).
        index: the row's place in its table.
        grid: BEM grid n (table "bem").
        harmonics, samples: H and n_t (tables "harmonics", "samples" and "reference").
        model: index into the stage's reduced models, the case's own last (table "mesh").
        builds_model: the row builds its FE model first (a coarser mesh's row, table "mesh").
        peak_of: name of the job whose peak this row's is (the same computation: the harmonics
            row at the samples table's H, and the case mesh's row, whose sweep is the
            reference's: the study's curve); such a job computes only its own fields
            (:func:`own_fields`), "" for a row with its own search.
    """
    table: str
    index: int
    grid: int = 0
    harmonics: int = 0
    samples: int = 0
    model: int = -1
    peak_of: str = ""
    builds_model: bool = False

    @property
    def name(self) -> str:
        return f"{self.table}-{self.index}"

    @property
    def needs_reference(self) -> bool:
        """Whether the job starts from the reference peak (it runs after the reference job)."""
        return self.table in ("harmonics", "samples") and not self.peak_of


#: the name of the reference job (:func:`speed_jobs`)
REFERENCE = "reference-0"
#: bump when how a row is computed changes: rows on disk of another version are computed again
#: (2: the harmonics and samples rows are local searches from the reference peak, not sweeps;
#: 3: a coarser mesh's row builds its FE model on its own rank, its FE time is that serial build;
#: 4: the reference is the study's curve, and the coarser meshes' rows sweep the study's band)
ROWS_VERSION = 4


def speed_jobs(grids, knobs: tuple[list, list] | None, n_models: int,
               study_knobs: tuple[int, int] = (3, 128)) -> list[SpeedJob]:
    """Every row of the stage as a job, in the order the queue deals them: the reference (the
    harmonics and samples rows need its peak, :attr:`SpeedJob.needs_reference`; the stage's queue
    deals them once it is written, ``run_jobs(after=)``), then the coarser meshes' rows (each
    builds its FE model, the longest jobs), then the others, costly ones first.

    Args:
        grids: BEM grid sizes; knobs: :func:`knob_grid`'s (H, n_t) rows, None without the HBM
            tables; n_models: reduced models of the element-count table (0: no table), the
            case's own last; study_knobs: the study's (H, n_t), those of the element-count rows
            and of the reference.
    """
    jobs = [SpeedJob("bem", i, grid=n) for i, n in enumerate(grids)]
    H, nt = study_knobs
    if knobs is not None:
        jobs.append(SpeedJob("reference", 0, harmonics=H, samples=nt))
        # a row whose peak another row computes takes that row's: the default case's harmonics
        # row H = 3, n_t = 256 is the samples row n_t = 256
        jobs += [SpeedJob("samples", i, harmonics=h, samples=n) for i, (h, n) in enumerate(knobs[1])]
        same = {(j.harmonics, j.samples): j.name for j in jobs if j.table == "samples"}
        jobs += [SpeedJob("harmonics", i, harmonics=h, samples=n, peak_of=same.get((h, n), ""))
                 for i, (h, n) in enumerate(knobs[0])]
    # the case mesh's row is the reference's sweep (the study's curve: same model, H, n_t, band)
    jobs += [SpeedJob("mesh", i, model=i,
                      peak_of=REFERENCE if knobs is not None and i == n_models - 1 else "",
                      builds_model=i < n_models - 1)
             for i in range(n_models)]

    # the reference first (read from the study's curve; every harmonics and samples row waits
    # for it); then the coarser meshes' rows, the finer first (an FE build, 20-45 s, and a
    # sweep); a search's cost grows
    # like (2H + 1)·n_t (the march); the BEM rows (seconds) and the rows without a search last
    def cost(j: SpeedJob) -> float:
        if j.table == "reference":
            return float("inf")
        if j.builds_model:
            return 1e12 * (1 + j.model)       # model index grows with the mesh's fineness
        if j.peak_of:
            return 0.0
        if j.table == "bem":
            return j.grid ** 2 / 1e6
        return (2 * j.harmonics + 1) * j.samples
    return sorted(jobs, key=lambda j: -cost(j))


def assemble_tables(jobs: list[SpeedJob], rows: dict[str, dict], h_ref: int) -> dict:
    """The stage's tables from its rows (any order of completion gives the same tables).

    Args:
        jobs: :func:`speed_jobs`; rows: {job name: row}; h_ref: the largest H (the harmonics
            table's reference).
    Returns:
        {table title: rows with their errors}; the BEM title is added by the caller.
    """
    by = {}
    for j in sorted(jobs, key=lambda j: (j.table, j.index)):
        row = dict(rows[j.name])
        if j.peak_of:
            row.update(_peak_fields(rows[j.peak_of], j.table))
        by.setdefault(j.table, []).append(row)
    out = {}
    if "bem" in by:
        out["bem"] = bem_errors(by["bem"])
    if "harmonics" in by:
        out[HARMONICS_TABLE] = _errors(by["harmonics"], f"H={h_ref}")
        out[SAMPLES_TABLE] = _errors(by["samples"], "finest")
    if "mesh" in by:
        out[MESH_TABLE] = mesh_errors(by["mesh"])
    return out


def own_fields(job: SpeedJob, models: list) -> dict:
    """The fields of a row whose peak is another row's sweep (``job.peak_of``): H and n_t, or the
    model's own fields (:func:`mesh_fields`)."""
    if job.table == "mesh":
        return mesh_fields(models[job.model])
    return {"harmonics": job.harmonics, "samples": job.samples}


def _peak_fields(source: dict, table: str) -> dict:
    """The sweep's fields of a finished row, named as ``table``'s rows name them."""
    out = {k: source[k] for k in ("peak [Hz]", "amplitude [µm]", "points", "note") if k in source}
    t = source.get("time [s]", source.get("HBM time [s]"))
    out["HBM time [s]" if table == "mesh" else "time [s]"] = t
    return out


def write_row(folder: Path, job: SpeedJob, row: dict, key: str) -> None:
    """A finished row (rank 0), with the stage key it was computed under; the reference's
    contact harmonics ("guess") in ``reference.npy`` beside it, written first (a row on disk
    means its guess is too)."""
    folder.mkdir(parents=True, exist_ok=True)
    row = dict(row)
    guess = row.pop("guess", None)
    if guess is not None:
        with open(folder / "reference.npy.tmp", "wb") as f:
            np.save(f, np.asarray(guess, float))
        (folder / "reference.npy.tmp").replace(folder / "reference.npy")
    tmp = folder / f"{job.name}.json.tmp"
    tmp.write_text(json.dumps({"key": key, "version": ROWS_VERSION, "job": dataclasses.asdict(job),
                               "row": row}, default=float))
    tmp.replace(folder / f"{job.name}.json")


def read_reference(folder: Path, rows: dict[str, dict]) -> dict:
    """The reference row with its "guess" (None when its sweep failed or the file is missing)."""
    ref = dict(rows.get(REFERENCE, {}))
    try:
        ref["guess"] = np.load(folder / "reference.npy") if "note" not in ref else None
    except (OSError, ValueError):
        ref["guess"] = None
    return ref


def read_rows(folder: Path, jobs: list[SpeedJob], key: str) -> dict[str, dict]:
    """The rows on disk computed for these jobs under ``key`` by this :data:`ROWS_VERSION`
    (others are ignored)."""
    out = {}
    for j in jobs:
        try:
            m = json.loads((folder / f"{j.name}.json").read_text())
        except (OSError, ValueError):
            continue
        if (isinstance(m, dict) and m.get("key") == key and m.get("version") == ROWS_VERSION
                and m.get("job") == dataclasses.asdict(j)):
            out[j.name] = m["row"]
    return out
