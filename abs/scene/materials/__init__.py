"""Material types of the scene file, one module each, registered by their ``type`` name."""

from abs.scene.materials import (  # noqa: F401  (registration side effect)
    brdf_pca,
    conductor,
    dielectric,
    diffuse,
    merl,
    plastic,
    roughdielectric,
)
from abs.scene.materials.base import Material, ParameterSpec, material_class, material_types, register

__all__ = ["Material", "ParameterSpec", "register", "material_types", "material_class"]
