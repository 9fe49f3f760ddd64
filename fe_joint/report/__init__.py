"""The report of a run: ``report.md``, ``figures/*.png``, ``summary.json`` and ``timings.json``.

Reads the artifacts of the earlier stages (rank 0 only) and draws the figures of the paper for our
resonator: FRFs per configuration and level (paper Figs. 11, 16) and versus Rq (Fig. 21); maps of
pressure, contact morphology, k_n, k_t, contact status and dissipated energy (Figs. 8, 10, 12–14,
17, 20); hysteresis loops of elements and of the whole joint (Figs. 18, 22); the equivalent
stiffness k_eq = Σ k_i A_i / Σ A_i per configuration and versus Rq (Figs. 15, 19); the contact-area
fraction versus Rq; the cost per stage (Tables 2–3) and a speed-against-error section.

Modules: :mod:`.data` (loading), :mod:`.stiffness` (k_eq through ``JointModel.k_eq``),
:mod:`.figures` (one function per figure), :mod:`.summary` (summary.json), :mod:`.markdown`
(report.md). :mod:`.fe_figures` holds the figures the FE stages draw.
"""
from __future__ import annotations

from pathlib import Path

from ..case import Case
from .data import ReportData, load_report_data
from .figures import draw_figures
from .findings import cost_findings, findings_summary
from .markdown import report_markdown
from .paraview import FOLDER as PARAVIEW_FOLDER, write_interface_results
from .summary import build_summary, build_timings, write_summary

__all__ = ["ReportData", "build_summary", "build_timings", "load_report_data", "write_report"]


def write_report(out: Path, case: Case, comm=None) -> dict | None:
    """Draw the figures, write report.md, summary.json, timings.json and the per-element ParaView
    files (``paraview/<curve>.xdmf``) from a run's artifacts (summary.json holds no wall time and
    no date: the same inputs give the same bytes).

    Args:
        out: the run's folder (stage manifests, fe/, contact/, dynamics/, speed/).
        case: the validated case of the run.
        comm: MPI communicator or None. On several ranks (collective) every rank loads the
            artifacts, takes a share of the eigenproblems (``linear_frf.share_eigenproblems``)
            and draws a share of the figures; rank 0 writes the rest.
    Returns:
        the summary dict written to summary.json (None on ranks other than 0).
    """
    data = load_report_data(Path(out), case)
    several = comm is not None and comm.size > 1
    if several:
        from .linear_frf import share_eigenproblems
        share_eigenproblems(data, comm)
    # the figures are dealt to the ranks (rank 0 also writes everything else)
    draw_figures(data, data.out / "figures", *((comm.rank, comm.size) if several else (0, 1)))
    if several and comm.rank != 0:
        comm.barrier()
        return None
    write_interface_results(data, data.out / PARAVIEW_FOLDER)
    summary, timings = build_summary(data), build_timings(data)
    timings["findings"] = findings_summary(cost_findings(data, summary, timings))
    write_summary(summary, data.out / "summary.json")
    write_summary(timings, data.out / "timings.json")
    if several:
        comm.barrier()          # every rank's figures are written: report.md links those it finds
    (data.out / "report.md").write_text(report_markdown(data, summary, timings))
    return summary
