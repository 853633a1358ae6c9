"""Material types of the scene file, one module each, registered by their ``type`` name.

Every module of this package is imported here, so adding a material type is adding a file (with
a :func:`register`-ed :class:`Material` subclass); nothing else lists the types.
"""

import importlib
import pkgutil

from abs.scene.materials.base import Material, ParameterSpec, material_class, material_types, register

for _info in sorted(pkgutil.iter_modules(__path__), key=lambda info: info.name):
    if _info.name != "base":
        importlib.import_module(f"{__name__}.{_info.name}")

__all__ = ["Material", "ParameterSpec", "register", "material_types", "material_class"]
