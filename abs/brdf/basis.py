"""A PCA basis of isotropic BRDF tables: file format, the log-relative mapping, and evaluation.

numpy only: the differentiable Dr.Jit evaluation used for rendering is
:mod:`abs.render.brdf_tables`, above the renderer bridge (docs/architecture.md).

A BRDF table (MERL layout, N = 3·90·90·180 values in 1/sr, see :mod:`abs.io.merl`) is
represented as ``unmap(mean + componentsᵀ · c)`` for a small coefficient vector ``c``, the
model of Nielsen, Jensen and Ramamoorthi, "On optimal, minimal BRDF sampling for reflectance
acquisition" (SIGGRAPH Asia 2015). Their mapping compresses the dynamic range of specular peaks
and de-emphasises grazing angles:

    x = log((f·w + ε) / (median·w + ε)),        f = ((median·w + ε)·exp(x) − ε) / w,

with ``w`` the cosine weight cosθi·cosθo of each table entry (:func:`merl_cosine_weight`),
``median`` a per-entry reference BRDF and ``ε`` a small offset.

File format (``.npz``, read with ``allow_pickle=False``, so a file never runs code):

=================  ===========  =========================================================
array              shape        meaning
=================  ===========  =========================================================
``mean``           (N,)         mean of the mapped training tables
``components``     (K, N)       scaled eigenvectors Q = VΣ, one row per component
``median``         (N,)         per-entry reference BRDF of the mapping, 1/sr, >= 0
``cosine_weight``  (N,)         optional: ``w``; :func:`merl_cosine_weight` when absent
``epsilon``        ()           ε of the mapping, 1/sr, > 0
``format_version`` ()           1
=================  ===========  =========================================================

Optional arrays written by :func:`abs.brdf.pca.build_basis` (describe the training set; used to
choose the regularisation of :mod:`abs.brdf.reconstruct`):

=========================  =======  ==========================================================
array                      shape    meaning
=========================  =======  ==========================================================
``materials``              (m,)     names of the m training materials (unicode strings)
``training_coefficients``  (m, K)   coefficients of the training tables (rows of U)
``singular_values``        (r,)     all singular values Σ of the centred mapped data, descending
``residual_variance``      ()       per-entry variance of the mapped residual of a material
                                    outside the training set (leave-one-out estimate)
=========================  =======  ==========================================================

The format is documented with the rest of the BRDF tools in ``docs/brdf.md``.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from abs.errors import InputError
from abs.io.merl import MERL_SHAPE, MERL_SIZE, merl_sample_angles

__all__ = [
    "FORMAT_VERSION",
    "COSINE_WEIGHT_MIN",
    "BRDFBasis",
    "merl_cosine_weight",
    "map_brdf",
    "unmap_brdf",
]

FORMAT_VERSION = 1
COSINE_WEIGHT_MIN = 1e-3
"""Lower clip of the cosine weight. Entries with a direction at or below the horizon have
cosθi·cosθo <= 0; clipping keeps the mapping defined there, and at 1e-3 (the order of a typical
ε) the inverse mapping's ε/w term stays O(1), so reconstruction errors are not blown up."""

_REQUIRED = ("mean", "components", "median", "epsilon", "format_version")
_OPTIONAL = ("cosine_weight", "materials", "training_coefficients", "singular_values", "residual_variance")


def merl_cosine_weight(min_weight: float = COSINE_WEIGHT_MIN) -> np.ndarray:
    """Cosine weight cosθi·cosθo at every MERL sample position, clipped below.

    With h = (sinθh, 0, cosθh) and d = (sinθd cosφd, sinθd sinφd, cosθd) in the half-vector frame,
    rotating d and its mirror image about h back to the normal frame gives
    cosθo = cosθd cosθh − sinθd cosφd sinθh and cosθi = cosθd cosθh + sinθd cosφd sinθh.

    Parameters
    ----------
    min_weight : float
        Lower clip (dimensionless); also applied to below-horizon entries.

    Returns
    -------
    np.ndarray
        float32 array of shape (N,) in MERL order, the same weight repeated for R, G and B.
    """
    theta_h, theta_d, phi_d = merl_sample_angles()
    along = np.cos(theta_d) * np.cos(theta_h)
    across = np.sin(theta_d) * np.cos(phi_d) * np.sin(theta_h)
    weight = np.maximum((along + across) * (along - across), min_weight)
    return np.tile(weight.ravel(), 3).astype(np.float32)


def map_brdf(f: np.ndarray, median: np.ndarray, w: np.ndarray, eps: float) -> np.ndarray:
    """Log-relative mapping x = log((f·w + ε) / (median·w + ε)).

    Parameters
    ----------
    f : np.ndarray
        BRDF values, 1/sr, >= 0 (arrays broadcast together).
    median : np.ndarray
        Reference BRDF values, 1/sr, >= 0.
    w : np.ndarray
        Cosine weights, dimensionless, > 0.
    eps : float
        Offset ε, 1/sr, > 0.

    Returns
    -------
    np.ndarray
        Mapped values (dimensionless), in the floating-point precision of the inputs.
    """
    f, median, w = np.asarray(f), np.asarray(median), np.asarray(w)
    return np.log((f * w + eps) / (median * w + eps))


def unmap_brdf(x: np.ndarray, median: np.ndarray, w: np.ndarray, eps: float) -> np.ndarray:
    """Inverse of :func:`map_brdf`: f = ((median·w + ε)·exp(x) − ε) / w.

    No clamping: values of ``x`` below the image of f = 0 give negative f (the exact inverse).
    :func:`abs.render.brdf_tables.table_from_coefficients` clamps at 0 for rendering.
    """
    x, median, w = np.asarray(x), np.asarray(median), np.asarray(w)
    return ((median * w + eps) * np.exp(x) - eps) / w


def _check_vector(source: str | None, name: str, value: np.ndarray) -> None:
    if value.shape != (MERL_SIZE,):
        raise InputError(source, name, f"expected shape ({MERL_SIZE},) = 3*90*90*180, got {value.shape}")


def _check_finite(source: str | None, name: str, value: np.ndarray) -> None:
    if not np.isfinite(value).all():
        raise InputError(source, name, "holds NaN or infinite values")


def _as_float(source: str | None, name: str, value: Any) -> np.ndarray:
    array = np.asarray(value)
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise InputError(source, name, f"expected a numeric array, got dtype {array.dtype}")
    return array.astype(np.float32, copy=False)


@dataclass(frozen=True, eq=False)
class BRDFBasis:
    """A PCA basis of mapped MERL tables (see the module docstring for the model).

    Parameters
    ----------
    mean : np.ndarray
        (N,) mean of the mapped tables.
    components : np.ndarray
        (K, N) scaled eigenvectors, one row per component.
    median : np.ndarray
        (N,) reference BRDF of the mapping, 1/sr, >= 0.
    epsilon : float
        ε of the mapping, 1/sr, > 0.
    cosine_weight : np.ndarray, optional
        (N,) weights ``w`` > 0; :func:`merl_cosine_weight` when omitted.
    materials : np.ndarray, optional
        (m,) names of the training materials.
    training_coefficients : np.ndarray, optional
        (m, K) coefficients of the training tables.
    singular_values : np.ndarray, optional
        (r,) all singular values of the centred, mapped training data, descending.
    residual_variance : float, optional
        Per-entry variance of the mapped out-of-basis residual of a held-out material.
    source : str, optional
        The file the basis came from, used in error messages.

    Arrays are stored as float32 (K·N·4 bytes for the components). Their Dr.Jit copies are made
    once per variant on first use by :func:`abs.render.brdf_tables.table_from_coefficients`:
    treat the arrays as read-only.
    """

    mean: np.ndarray
    components: np.ndarray
    median: np.ndarray
    epsilon: float
    cosine_weight: np.ndarray | None = None
    materials: np.ndarray | None = None
    training_coefficients: np.ndarray | None = None
    singular_values: np.ndarray | None = None
    residual_variance: float | None = None
    source: str | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        src = self.source
        mean = _as_float(src, "mean", self.mean)
        median = _as_float(src, "median", self.median)
        components = _as_float(src, "components", self.components)
        _check_vector(src, "mean", mean)
        _check_vector(src, "median", median)
        if components.ndim != 2 or components.shape[1] != MERL_SIZE or components.shape[0] < 1:
            raise InputError(
                src, "components", f"expected shape (K, {MERL_SIZE}) with K >= 1, got {components.shape}"
            )
        for name, value in (("mean", mean), ("median", median), ("components", components)):
            _check_finite(src, name, value)
        if (median < 0).any():
            raise InputError(src, "median", "BRDF values must be >= 0")
        if self.cosine_weight is None:
            weight = merl_cosine_weight()
        else:
            weight = _as_float(src, "cosine_weight", self.cosine_weight)
            _check_vector(src, "cosine_weight", weight)
            if not (np.isfinite(weight).all() and (weight > 0).all()):
                raise InputError(src, "cosine_weight", "weights must be finite and > 0")
        epsilon = np.asarray(self.epsilon)
        if epsilon.shape != () or not np.issubdtype(epsilon.dtype, np.number):
            raise InputError(src, "epsilon", f"expected a number, got {epsilon!r}")
        if not (np.isfinite(epsilon) and epsilon > 0):
            raise InputError(src, "epsilon", f"must be finite and > 0, got {float(epsilon)}")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "median", median)
        object.__setattr__(self, "components", np.ascontiguousarray(components))
        object.__setattr__(self, "cosine_weight", weight)
        object.__setattr__(self, "epsilon", float(epsilon))
        self._check_training_set(src, components.shape[0])

    def _check_training_set(self, src: str | None, n_components: int) -> None:
        """Validate the optional description of the training set."""
        if self.materials is not None:
            names = np.asarray(self.materials)
            if names.ndim != 1 or names.dtype.kind != "U":
                raise InputError(src, "materials", f"expected a 1-D array of names, got {names.dtype} {names.shape}")
            object.__setattr__(self, "materials", names)
        if self.training_coefficients is not None:
            coeffs = _as_float(src, "training_coefficients", self.training_coefficients)
            if coeffs.ndim != 2 or coeffs.shape[1] != n_components:
                raise InputError(src, "training_coefficients",
                                 f"expected shape (m, {n_components}), got {coeffs.shape}")
            if self.materials is not None and len(self.materials) != coeffs.shape[0]:
                raise InputError(src, "training_coefficients",
                                 f"{coeffs.shape[0]} rows for {len(self.materials)} materials")
            _check_finite(src, "training_coefficients", coeffs)
            object.__setattr__(self, "training_coefficients", coeffs)
        if self.singular_values is not None:
            sv = np.asarray(self.singular_values, dtype=np.float64)
            if sv.ndim != 1 or not np.isfinite(sv).all() or (sv < 0).any() or (np.diff(sv) > 0).any():
                raise InputError(src, "singular_values", "expected finite, non-negative, descending values")
            object.__setattr__(self, "singular_values", sv)
        if self.residual_variance is not None:
            value = np.asarray(self.residual_variance)
            if value.shape != () or not (np.isfinite(value) and value >= 0):
                raise InputError(src, "residual_variance", f"expected a finite number >= 0, got {value!r}")
            object.__setattr__(self, "residual_variance", float(value))

    @property
    def n_components(self) -> int:
        """Number of components K."""
        return int(self.components.shape[0])

    # -- files ----------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> BRDFBasis:
        """Read a basis ``.npz`` (never unpickles; see the module docstring for the arrays).

        Raises
        ------
        InputError
            Naming the file and the array when the file is unreadable, lacks an array, holds
            pickled objects, or an array has the wrong shape, type or values.
        """
        path = Path(path)
        src = str(path)
        try:
            archive = np.load(path, allow_pickle=False)
        except (OSError, ValueError, zipfile.BadZipFile) as err:
            raise InputError(src, "", f"cannot read as a NumPy .npz archive: {err}") from err
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise InputError(src, "", "expected a .npz archive of named arrays, got a single .npy array")
        arrays: dict[str, np.ndarray] = {}
        with archive:
            for name in _REQUIRED + _OPTIONAL:
                if name not in archive.files:
                    if name in _REQUIRED:
                        raise InputError(src, name, "missing from the archive")
                    continue
                try:
                    arrays[name] = archive[name]
                except ValueError as err:  # object arrays need pickle, which is refused
                    raise InputError(src, name, f"cannot be loaded without unpickling ({err})") from err
        version = arrays["format_version"]
        is_int = version.shape == () and np.issubdtype(version.dtype, np.integer)
        if not is_int or int(version) != FORMAT_VERSION:
            raise InputError(src, "format_version", f"expected {FORMAT_VERSION}, got {version!r}")
        return cls(
            mean=arrays["mean"],
            components=arrays["components"],
            median=arrays["median"],
            epsilon=arrays["epsilon"],
            cosine_weight=arrays.get("cosine_weight"),
            materials=arrays.get("materials"),
            training_coefficients=arrays.get("training_coefficients"),
            singular_values=arrays.get("singular_values"),
            residual_variance=arrays.get("residual_variance"),
            source=src,
        )

    def save(self, path: str | Path) -> None:
        """Write the basis as an uncompressed ``.npz`` at exactly ``path`` (no suffix added)."""
        optional = {
            "materials": self.materials,
            "training_coefficients": self.training_coefficients,
            "singular_values": self.singular_values,
            "residual_variance": None if self.residual_variance is None else np.float64(self.residual_variance),
        }
        with open(path, "wb") as file:
            np.savez(
                file,
                mean=self.mean,
                components=self.components,
                median=self.median,
                cosine_weight=self.cosine_weight,
                epsilon=np.float64(self.epsilon),
                format_version=np.int64(FORMAT_VERSION),
                **{name: value for name, value in optional.items() if value is not None},
            )

    # -- numpy ----------------------------------------------------------------------------------
    def mapped(self, table: np.ndarray) -> np.ndarray:
        """A table (``(3, 90, 90, 180)`` or flat, 1/sr) in the basis' mapped space, float64 (N,)."""
        f = np.asarray(table, dtype=np.float64).reshape(-1)
        if f.size != MERL_SIZE:
            raise InputError(None, "table", f"expected {MERL_SIZE} values, got {f.size}")
        return map_brdf(f, self.median.astype(np.float64), self.cosine_weight.astype(np.float64), self.epsilon)

    def table(self, coefficients: np.ndarray) -> np.ndarray:
        """numpy counterpart of :func:`abs.render.brdf_tables.table_from_coefficients` (not
        differentiable).

        Parameters
        ----------
        coefficients : np.ndarray
            K coefficients (dimensionless).

        Returns
        -------
        np.ndarray
            float32 table of shape ``(3, 90, 90, 180)``, BRDF in 1/sr, clamped at 0.
        """
        c = np.asarray(coefficients, dtype=np.float64).reshape(-1)
        if c.size != self.n_components:
            raise ValueError(f"expected {self.n_components} coefficients (one per component), got {c.size}")
        x = self.mean.astype(np.float64)
        for c_k, row in zip(c, self.components):
            x += c_k * row
        f = unmap_brdf(x, self.median.astype(np.float64), self.cosine_weight.astype(np.float64), self.epsilon)
        return np.maximum(f, 0.0).astype(np.float32).reshape(MERL_SHAPE)
