"""Figures of the FE stages (numpy + matplotlib only): the resonator's geometry and pairs, the
preload pressure map. Called by the mesh and fe stages with plain arrays."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geometry.resonator import LAP_A, MARKER_NAMES, ResonatorMesh

from ..model.interface_contact import lap_triangles


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _exterior_faces(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex triangles of the boundary of a tet mesh and the cell each belongs to."""
    t = cells[:, :4]
    loc = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = t[:, loc].reshape(-1, 3)
    owner = np.repeat(np.arange(len(t)), 4)
    key = np.sort(faces, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    ext = cnt[inv] == 1
    return faces[ext], owner[ext]


def plot_geometry(data: ResonatorMesh, path: Path) -> None:
    """geometry.png: side view (x–z) of the parts and a plan view of lap face A with the pairs."""
    plt = _plt()
    from matplotlib.collections import PolyCollection
    from matplotlib.tri import Triangulation

    faces, owner = _exterior_faces(data.cells)
    x = data.points
    colors = {1: "tab:blue", 2: "tab:orange", 3: "tab:gray", 4: "dimgray", 5: "black"}
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1.2, 1]})
    # side view from -y: draw faces back to front (painter's order by y)
    order = np.argsort(-x[faces].mean(axis=1)[:, 1])
    polys = x[faces[order]][:, :, [0, 2]]
    fc = [colors[int(m)] for m in data.cell_markers[owner[order]]]
    ax0.add_collection(PolyCollection(polys, facecolors=fc, edgecolors="k", linewidths=0.1))
    ax0.set_xlim(x[:, 0].min() - 2, x[:, 0].max() + 2)
    ax0.set_ylim(x[:, 2].min() - 2, x[:, 2].max() + 2)
    ax0.set_aspect("equal")
    ax0.set_xlabel("x [mm]")
    ax0.set_ylabel("z [mm]")
    for m, c in colors.items():
        ax0.plot([], [], "s", color=c, label=MARKER_NAMES[m])
    e = x[data.excitation_node]
    ax0.plot(e[0], e[2], "r*", ms=14, label="excitation / response")
    ax0.legend(loc="lower right", fontsize=8)
    ax0.set_title(f"resonator: {len(x)} nodes, {len(data.cells)} tets")

    lap = data.facets[data.facet_markers == LAP_A][:, :3]
    used, tri = np.unique(lap, return_inverse=True)
    triang = Triangulation(x[used, 0], x[used, 1], tri.reshape(-1, 3))
    ax1.triplot(triang, color="0.6", lw=0.5)
    sc = ax1.scatter(data.pair_xyz[:, 0], data.pair_xyz[:, 1], c=data.pair_area, s=14,
                     cmap="viridis")
    fig.colorbar(sc, ax=ax1, label="tributary area [mm²]", shrink=0.8)
    ax1.set_aspect("equal")
    ax1.set_xlabel("x [mm]")
    ax1.set_ylabel("y [mm]")
    ax1.set_title(f"lap interface: {data.n_pairs} pairs, Σ area = {data.pair_area.sum():.2f} mm²")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_pressure_map(data, pressure: np.ndarray, path: str) -> None:
    """PNG map of the interface pressure over the lap face (tri6 split into four tri3)."""
    plt = _plt()
    from matplotlib.tri import Triangulation

    tri6 = lap_triangles(data)
    sub = np.vstack([tri6[:, [0, 3, 5]], tri6[:, [3, 1, 4]], tri6[:, [5, 4, 2]], tri6[:, [3, 4, 5]]])
    xyz = np.asarray(data.pair_xyz)
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    tc = ax.tripcolor(Triangulation(xyz[:, 0], xyz[:, 1], sub), pressure, shading="gouraud", cmap="viridis")
    fig.colorbar(tc, ax=ax, label="contact pressure (MPa)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"preload interface pressure, total {np.sum(pressure * np.asarray(data.pair_area)):.0f} N")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
