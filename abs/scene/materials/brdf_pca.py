"""``brdf_pca``: a measured-BRDF-like material given by coefficients over a PCA basis of measured
BRDFs (Nielsen et al. 2015). The table ``unmap(mean + components^T c)`` is rebuilt, differentiably,
whenever ``coefficients`` change (by :mod:`abs.render.brdf_tables`, in the renderer bridge above
this package), and rendered by the ``abs_tabulated`` BSDF."""

from __future__ import annotations

import numpy as np

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, ParameterSpec, register


@register
class BrdfPca(Material):
    type_name = "brdf_pca"

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "BrdfPca":
        fields.check_known({"type", "basis", "coefficients"})
        self = cls(name)
        self.basis_file = fields.file("basis", suffixes=(".npz",))
        raw = fields.raw("coefficients")
        if not isinstance(raw, list) or not raw:
            raise fields.error("coefficients", f"expected a non-empty list of numbers, got {raw!r}")
        self.coefficients = fields.array("coefficients", (len(raw),))
        self._fields = fields
        self._basis = None
        self._toml = {"type": cls.type_name, "basis": str(fields.raw("basis")),
                      "coefficients": self.coefficients.tolist()}
        return self

    @property
    def basis(self):
        """The basis, loaded on first use (it can be large)."""
        if self._basis is None:
            from abs.brdf.basis import BRDFBasis

            basis = BRDFBasis.load(self.basis_file)
            if basis.n_components != self.coefficients.size:
                raise self._fields.error(
                    "coefficients", f"{self.coefficients.size} coefficients given but the basis "
                                    f"{self.basis_file.name} has {basis.n_components} components")
            self._basis = basis
        return self._basis

    def to_mitsuba(self) -> dict:
        return {"type": "abs_tabulated"}

    def parameters(self) -> dict[str, ParameterSpec]:
        return {"coefficients": ParameterSpec("coefficients", self.coefficients.size, "1",
                                              -np.inf, np.inf, None)}
