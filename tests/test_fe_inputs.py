"""Bad input to the FE chain gets a ValueError naming the problem."""
import copy

import numpy as np
import pytest
from mpi4py import MPI

from fe_joint.fe.box_joint import build_box_joint
from fe_joint.case import Material
from fe_joint.fe.assembly import check_mesh_data
from fe_joint.fe.mesh import mesh_from_data
from fe_joint.fe.preload import solve_preload
from fe_joint.fe.reduction import build_reduced_model_from_fe


@pytest.fixture(scope="module")
def data():
    return build_box_joint(half=6.0, thickness=4.0, cell=2.0, shank_half=2.0, hole_half=4.0)


def test_mesh_without_matched_lap_faces(data):
    bad = copy.copy(data)
    bad.pair_nodes = np.empty((0, 2), dtype=np.int64)
    with pytest.raises(ValueError, match="no matched lap faces"):
        check_mesh_data(bad)
    shifted = copy.copy(data)
    shifted.points = data.points.copy()
    shifted.points[data.pair_nodes[3, 1], 0] += 0.1
    with pytest.raises(ValueError, match="not matched"):
        check_mesh_data(shifted)
    fe = mesh_from_data(bad, MPI.COMM_WORLD)
    with pytest.raises(ValueError, match="no matched lap faces"):
        solve_preload(fe, Material(), 30000.0)


@pytest.mark.parametrize("force", [0.0, -5.0, float("nan"), float("inf")])
def test_preload_must_be_positive(data, force):
    fe = mesh_from_data(data, MPI.COMM_WORLD)
    with pytest.raises(ValueError, match="preload"):
        solve_preload(fe, Material(), force)


@pytest.mark.parametrize("zeta", [-1e-3, 1.0, 2.0])
def test_damping_ratio_range_checked_before_work(data, zeta):
    fe = mesh_from_data(data, MPI.COMM_WORLD)
    with pytest.raises(ValueError, match=r"damping_ratio must be in \[0, 1\)"):
        build_reduced_model_from_fe(fe, Material(), 30000.0, zeta, 1e4)


def test_cutoff_must_be_positive(data):
    fe = mesh_from_data(data, MPI.COMM_WORLD)
    with pytest.raises(ValueError, match="cutoff_hz"):
        build_reduced_model_from_fe(fe, Material(), 30000.0, 1e-3, 0.0)
