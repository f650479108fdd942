"""Electromagnetics: ITU-R P.2040-3 material table, complex permittivity, Fresnel/slab reflection.

Public API::

    from sim2radar.em import complex_permittivity, reflection_coefficients, MATERIALS
    eta = complex_permittivity("concrete", 77e9)             # (5.24 - 0.32j)
    r_te, r_tm = reflection_coefficients("glass", 77e9, 0.3)  # half-space
    r_te, r_tm = reflection_coefficients("glass", 77e9, 0.3, thickness_m=0.006)  # slab
    t = unpolarized_transmission("plasterboard", 77e9, 0.3, thickness_m=0.0125)  # through it
"""

from sim2radar.em.fresnel import (
    fresnel_coefficients,
    reflection_coefficients,
    slab_coefficients,
    slab_transmission_coefficients,
    transmission_coefficients,
    unpolarized_reflection,
    unpolarized_transmission,
)
from sim2radar.em.materials import (
    MATERIALS,
    Material,
    MaterialFrequencyWarning,
    MaterialRow,
    UnknownMaterialError,
    complex_permittivity,
    get_material,
    material_names,
    material_parameters,
    normalize_material_name,
)

__all__ = [
    "MATERIALS",
    "Material",
    "MaterialRow",
    "MaterialFrequencyWarning",
    "UnknownMaterialError",
    "complex_permittivity",
    "fresnel_coefficients",
    "get_material",
    "material_names",
    "material_parameters",
    "normalize_material_name",
    "reflection_coefficients",
    "slab_coefficients",
    "slab_transmission_coefficients",
    "transmission_coefficients",
    "unpolarized_reflection",
    "unpolarized_transmission",
]
