"""Parametric gmsh model of the bolted lap-joint resonator (pure gmsh + numpy)."""
from geometry.resonator import (EXCITATION_POINT, HEAD, LAP_A, LAP_B, MARKER_NAMES, NUT, PART_A,
                                PART_B, SHANK, WASHER_HEAD, WASHER_NUT, GeometryError,
                                ResonatorMesh, ResonatorParams, build_resonator, cell_volumes,
                                nominal_interface_area, nominal_volumes, scaled_jacobian)

__all__ = ["ResonatorParams", "ResonatorMesh", "GeometryError", "build_resonator",
           "nominal_volumes", "nominal_interface_area", "cell_volumes", "scaled_jacobian",
           "MARKER_NAMES", "PART_A", "PART_B", "SHANK", "HEAD", "NUT", "LAP_A", "LAP_B",
           "WASHER_HEAD", "WASHER_NUT", "EXCITATION_POINT"]
