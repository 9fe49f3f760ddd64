"""Per-element results at resonance for ParaView: one XDMF + HDF5 point cloud per FRF curve.

For every study curve (configuration and level; v3 also per Rq) the friction elements are written
as points at their pair node (the matched nodes of the two faces coincide) with the joint's
parameters and its state at the curve's peak as point data. The files are written with h5py and
plain XML (Xdmf 3, topology ``Polyvertex``), so the report stays free of dolfinx; ParaView's
Xdmf3 reader and meshio read them.

Point data (one value per element, units N, mm, N/mm³):

- ``status``: 0 stuck, 1 stick–slip, 2 gross slip, 3 partly open, 4 open (at the peak);
- ``energy`` (N·mm per cycle) and ``energy_per_area`` (N·mm/mm² per cycle);
- ``N0``: the joint's preload normal force; ``mean_normal``: its cycle mean at the peak;
- ``kn``, ``kt``: the joint's contact stiffness per unit area; ``area``: tributary area, mm²;
- ``u_amplitude``: half the peak-to-peak relative displacement u_x over the cycle, mm;
- ``slip_amplitude``: half the peak-to-peak of the slip w_x = u_x − T_x / (k_t A), mm (the
  Jenkins element's slider; 0 for elements outside the dynamics and for elements open over the
  whole cycle, whose relative motion is not slip);
- ``T_amplitude``: the tangential force amplitude ‖(q_x, q_y)‖, N.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np

from ..model.joint import JointModel
from ..study.artifacts import CurveKey
from ..study.frf import CurveResult
from .data import ReportData
from .stiffness import configuration_joints, rq_joints

#: the folder of the files, relative to the run folder
FOLDER = "paraview"
OPEN = 4


def joint_of_curve(data: ReportData, key: CurveKey) -> JointModel:
    """The joint a study curve was computed with (v3 on another surface: that surface's v3)."""
    if key.config == "v3" and key.rq_um is not None and key.rq_um != data.v_rq:
        return rq_joints(data)[key.rq_um]
    return configuration_joints(data)[key.config]


def _half_range(x: np.ndarray) -> np.ndarray:
    """Half the peak-to-peak over the last axis."""
    return 0.5 * (x.max(axis=-1) - x.min(axis=-1))


def element_fields(data: ReportData, cr: CurveResult, joint: JointModel) -> dict[str, np.ndarray]:
    """The point data of one curve at its peak (module docstring), each (ne,).

    Args:
        data: the run's artifacts (tributary areas).
        cr: the curve (state at its peak).
        joint: the joint it was computed with.
    Returns:
        field name → values; ``status`` as int64, the others float64.
    """
    A = data.area
    ktA = joint.kt * A
    active = (joint.kn > 0) & (joint.kt > 0) & (cr.status < OPEN)
    w = cr.elem_u - cr.elem_T / np.where(ktA > 0, ktA, 1.0)[:, None]
    return {
        "status": np.asarray(cr.status, np.int64),
        "energy": np.asarray(cr.energy, float), "energy_per_area": cr.energy / A,
        "N0": joint.n0, "mean_normal": np.asarray(cr.mean_normal, float),
        "kn": joint.kn, "kt": joint.kt, "area": np.asarray(A, float),
        "u_amplitude": _half_range(cr.elem_u),
        "slip_amplitude": np.where(active, _half_range(w), 0.0),
        "T_amplitude": np.hypot(cr.q_amp[:, 0], cr.q_amp[:, 1]),
    }


def _data_item(parent: ET.Element, h5name: str, path: str, arr: np.ndarray) -> None:
    """An HDF DataItem for ``arr`` stored at ``h5name:/path``."""
    is_int = np.issubdtype(arr.dtype, np.integer)
    item = ET.SubElement(parent, "DataItem", Dimensions=" ".join(map(str, arr.shape)),
                         NumberType="Int" if is_int else "Float", Precision="8", Format="HDF")
    item.text = f"{h5name}:/{path}"


def write_point_cloud(xdmf: Path, name: str, xyz: np.ndarray, fields: dict[str, np.ndarray]) -> Path:
    """Write ``xdmf`` and its HDF5 beside it (same stem): points ``xyz`` with point data ``fields``.

    Args:
        xdmf: the .xdmf path (the .h5 gets the same stem).
        name: the grid's name (shown in ParaView).
        xyz: (n, 3) coordinates, mm.
        fields: name → (n,) values.
    Returns:
        ``xdmf``.
    """
    xdmf, n = Path(xdmf), len(xyz)
    h5 = xdmf.with_suffix(".h5")
    with h5py.File(h5, "w") as f:
        f["geometry"] = np.asarray(xyz, float)
        f["topology"] = np.arange(n, dtype=np.int64)
        for k, v in fields.items():
            f[f"point_data/{k}"] = v
    root = ET.Element("Xdmf", Version="3.0")
    grid = ET.SubElement(ET.SubElement(root, "Domain"), "Grid", Name=name, GridType="Uniform")
    topo = ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(n),
                         NodesPerElement="1")
    _data_item(topo, h5.name, "topology", np.arange(n, dtype=np.int64))
    _data_item(ET.SubElement(grid, "Geometry", GeometryType="XYZ"), h5.name, "geometry",
               np.asarray(xyz, float))
    for k, v in fields.items():
        att = ET.SubElement(grid, "Attribute", Name=k, AttributeType="Scalar", Center="Node")
        _data_item(att, h5.name, f"point_data/{k}", np.asarray(v))
    ET.indent(root)
    xdmf.write_text('<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
    return xdmf


def study_curves(data: ReportData) -> list[tuple[CurveKey, CurveResult]]:
    """The study's curves (not the small-excitation check), sorted by name."""
    return sorted(((k, cr) for k, cr in data.curves.items() if k.level_index is not None),
                  key=lambda kv: kv[0].name)


def write_interface_results(data: ReportData, folder: Path) -> list[Path]:
    """One point cloud per study curve: ``<folder>/<curve name>.xdmf`` (+ ``.h5``).

    Args:
        data: the run's artifacts.
        folder: where the files go (created).
    Returns:
        the .xdmf files written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    xyz = np.asarray(data.rm.pair_xyz, float)
    return [write_point_cloud(folder / f"{k.name}.xdmf", k.name, xyz,
                              element_fields(data, cr, joint_of_curve(data, k)))
            for k, cr in study_curves(data)]


def paraview_markdown(data: ReportData) -> list[str]:
    """The links to the per-element files, with what they hold."""
    curves = study_curves(data)
    if not curves:
        return []
    links = ", ".join(f"[`{k.name}`]({FOLDER}/{k.name}.xdmf)" for k, _ in curves)
    return ["Per-element results at each curve's peak, for ParaView (XDMF point cloud on the "
            "interface pair nodes; open the `.xdmf`, Xdmf3 reader; the `.h5` beside it holds the "
            "arrays): status, dissipated energy (per cycle and per area), N0 and the cycle-mean "
            "normal force, k_n, k_t, tributary area, relative displacement, slip and tangential "
            "force amplitudes (slip w = u_x − T_x/(k_t A), half peak-to-peak): " + links + ".", ""]
