"""The case: what a run computes, as typed sections validated once where the case is read."""
from ..errors import CaseError
from .loading import (PRESETS, case_from_dict, case_to_toml, default_case_text, load_case,
                      load_case_with_sources, resolve_case)
from .schema import (SECTIONS, Case, Contact, Dynamics, Material, Preload, Reduction,
                     Roughness)

__all__ = ["Case", "CaseError", "Contact", "Dynamics", "Material", "PRESETS", "Preload",
           "Reduction", "Roughness", "SECTIONS", "case_from_dict", "case_to_toml",
           "default_case_text", "load_case", "load_case_with_sources", "resolve_case"]
