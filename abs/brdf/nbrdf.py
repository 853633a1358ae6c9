"""MERL-format BRDF tables from the neural fits (NBRDF) of the MERL measured materials.

``shared/data/merl_nbrdf/merl_nbrdf.zip`` holds, per material, the Keras weights of a small MLP
(6 → 21 → 21 → 3, 675 numbers) fitted to the MERL measurement (Sztrajman et al. 2021); its
``FORMAT.md`` states how to evaluate them, and the item numbers below refer to it:

- weights: ``dense_k/dense_k/kernel:0`` (inputs, outputs) and ``bias:0`` of the ``.h5`` (items 3-4);
- network: y = max(exp(relu(relu(x·W1 + b1)·W2 + b2)·W3 + b3) − 1, 0), outputs R, G, B, the BRDF
  in 1/sr with the MERL scales already applied (items 6-8);
- input: x = (sinθh, 0, cosθh, sinθd cosφd, sinθd sinφd, cosθd) for Rusinkiewicz angles (item 9).

A table (:func:`nbrdf_table`) holds the network at the MERL sample positions (items 21, 25), with two
choices FORMAT.md leaves open (section 7):

- reciprocity: the network is only approximately reciprocal (item 17), so each entry is the
  mean of the network at φd and φd + π (the same direction pair with the roles of the two
  directions swapped); the table is then exactly reciprocal, as a BRDF must be;
- horizon: where one of the two directions is at or below the horizon the network was never
  constrained (item 16), so those entries are 0, the value :func:`abs.io.merl.read_merl` gives a
  real MERL file's invalid (negative) entries. Tables from both sources are then interchangeable.

Tables take about a second each to evaluate and are cached as ``.npy`` files under
:func:`abs.io.shared_data.cache_dir` (``merl``), keyed by a hash of the weights.
"""

from __future__ import annotations

import hashlib
import io
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abs.errors import InputError
from abs.io.merl import MERL_SHAPE, merl_sample_angles
from abs.io.shared_data import cache_dir, shared_data_dir

__all__ = [
    "NBRDFWeights",
    "nbrdf_archive_path",
    "nbrdf_material_names",
    "nbrdf_weights",
    "evaluate_nbrdf",
    "nbrdf_table",
]

_MEMBER_DIR = "merl_nbrdf/"
_SHAPES = {"kernel": ((6, 21), (21, 21), (21, 3)), "bias": ((21,), (21,), (3,))}
# Bump when the table construction changes, so stale caches are not reused.
_TABLE_VERSION = "v1"


@dataclass(frozen=True)
class NBRDFWeights:
    """The weights of one material's network, float32, kernels in (inputs, outputs) orientation.

    Attributes
    ----------
    kernels : tuple of np.ndarray
        Shapes (6, 21), (21, 21), (21, 3).
    biases : tuple of np.ndarray
        Shapes (21,), (21,), (3,).
    digest : str
        SHA-256 of the ``.h5`` file (identifies the weights in the table cache).
    """

    kernels: tuple[np.ndarray, np.ndarray, np.ndarray]
    biases: tuple[np.ndarray, np.ndarray, np.ndarray]
    digest: str


def nbrdf_archive_path() -> Path:
    """``merl_nbrdf/merl_nbrdf.zip`` in the shared data folder (:func:`shared_data_dir`)."""
    return shared_data_dir() / "merl_nbrdf" / "merl_nbrdf.zip"


def _archive(path: Path | None) -> tuple[Path, zipfile.ZipFile]:
    path = nbrdf_archive_path() if path is None else Path(path)
    if not path.is_file():
        raise InputError(path, "", "neural MERL archive not found (set ABS_SHARED_DATA to the folder "
                                   "holding merl_nbrdf/merl_nbrdf.zip, see ../shared/README.md)")
    try:
        return path, zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as err:
        raise InputError(path, "", f"cannot read as a zip archive: {err}") from err


def nbrdf_material_names(archive: str | Path | None = None) -> list[str]:
    """Names of the materials in the archive (e.g. ``"blue-rubber"``), sorted.

    Parameters
    ----------
    archive : str or Path, optional
        The zip file; :func:`nbrdf_archive_path` when omitted.
    """
    path, zf = _archive(archive)
    with zf:
        names = [n[len(_MEMBER_DIR):-3] for n in zf.namelist() if n.startswith(_MEMBER_DIR) and n.endswith(".h5")]
    if not names:
        raise InputError(path, "", f"no {_MEMBER_DIR}<name>.h5 weight files in the archive")
    return sorted(names)


def nbrdf_weights(name: str, archive: str | Path | None = None) -> NBRDFWeights:
    """Read one material's weights from its Keras ``.h5`` file inside the archive (h5py; no pickle).

    Raises
    ------
    InputError
        Naming the archive member and dataset when the material is missing or a weight array
        is absent or has the wrong shape.
    """
    import h5py

    path, zf = _archive(archive)
    member = f"{_MEMBER_DIR}{name}.h5"
    with zf:
        try:
            raw = zf.read(member)
        except KeyError:
            raise InputError(path, name, "no such material in the archive (see nbrdf_material_names)") from None
    source = f"{path}:{member}"
    arrays: dict[str, list[np.ndarray]] = {"kernel": [], "bias": []}
    try:
        with h5py.File(io.BytesIO(raw), "r") as h5:
            for layer in range(1, 4):
                for kind in ("kernel", "bias"):
                    key = f"dense_{layer}/dense_{layer}/{kind}:0"
                    if key not in h5:
                        raise InputError(source, key, "missing dataset")
                    value = np.asarray(h5[key], dtype=np.float32)
                    expected = _SHAPES[kind][layer - 1]
                    if value.shape != expected:
                        raise InputError(source, key, f"expected shape {expected}, got {value.shape}")
                    if not np.isfinite(value).all():
                        raise InputError(source, key, "holds NaN or infinite values")
                    arrays[kind].append(value)
    except OSError as err:
        raise InputError(source, "", f"cannot read as HDF5: {err}") from err
    return NBRDFWeights(tuple(arrays["kernel"]), tuple(arrays["bias"]), hashlib.sha256(raw).hexdigest())


def evaluate_nbrdf(weights: NBRDFWeights, theta_h: np.ndarray, theta_d: np.ndarray,
                   phi_d: np.ndarray) -> np.ndarray:
    """The network's BRDF at Rusinkiewicz angles (FORMAT.md items 6-9), no symmetrisation or mask.

    Parameters
    ----------
    weights : NBRDFWeights
        One material's network.
    theta_h, theta_d, phi_d : np.ndarray
        Angles in radians, broadcast together.

    Returns
    -------
    np.ndarray
        float32 array of shape ``broadcast shape + (3,)``: R, G, B BRDF values in 1/sr, >= 0.
    """
    theta_h, theta_d, phi_d = np.broadcast_arrays(theta_h, theta_d, phi_d)
    shape = theta_h.shape
    th, td, pd = (np.ravel(a) for a in (theta_h, theta_d, phi_d))
    x = np.stack([np.sin(th), np.zeros_like(th), np.cos(th),
                  np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=1).astype(np.float32)
    (w1, w2, w3), (b1, b2, b3) = weights.kernels, weights.biases
    hidden = np.maximum(x @ w1 + b1, 0.0)
    hidden = np.maximum(hidden @ w2 + b2, 0.0)
    # The clamp at 0 is the renderer's (item 7): the bare Keras output can dip to -1.
    y = np.maximum(np.expm1(hidden @ w3 + b3), 0.0)
    return y.reshape(shape + (3,))


def _build_table(weights: NBRDFWeights) -> np.ndarray:
    theta_h, theta_d, phi_d = merl_sample_angles()
    # cosθi·cosθo from the half-vector frame (as abs.brdf.basis.merl_cosine_weight).
    along = np.cos(theta_d) * np.cos(theta_h)
    across = np.sin(theta_d) * np.cos(phi_d) * np.sin(theta_h)
    valid = (along + across > 0) & (along - across > 0)
    table = np.zeros(MERL_SHAPE, np.float32)
    for i in range(MERL_SHAPE[1]):  # one θh slice at a time keeps the hidden layers small
        keep = valid[i]
        th, td, pd = theta_h[i][keep], theta_d[i][keep], phi_d[i][keep]
        f = evaluate_nbrdf(weights, th, td, pd) + evaluate_nbrdf(weights, th, td, pd + np.pi)
        table[:, i][:, keep] = 0.5 * f.T
    return table


def nbrdf_table(name: str, archive: str | Path | None = None, use_cache: bool = True) -> np.ndarray:
    """A material's MERL-layout table from its neural fit (see the module docstring).

    Parameters
    ----------
    name : str
        Material name, e.g. ``"blue-rubber"`` (:func:`nbrdf_material_names`).
    archive : str or Path, optional
        The zip file; :func:`nbrdf_archive_path` when omitted.
    use_cache : bool
        Read and write the on-disk cache (``<cache>/merl/<name>-<hash>.npy``).

    Returns
    -------
    np.ndarray
        float32 array of shape ``(3, 90, 90, 180)`` (R/G/B, θh, θd, φd), BRDF in 1/sr, 0 where a
        direction is below the horizon.
    """
    weights = nbrdf_weights(name, archive)
    path = cache_dir("merl") / f"{name}-{weights.digest[:16]}-{_TABLE_VERSION}.npy"
    if use_cache and path.is_file():
        try:
            table = np.load(path, allow_pickle=False)
            if table.shape == MERL_SHAPE and table.dtype == np.float32:
                return table
        except (OSError, ValueError):
            pass  # a damaged cache entry is rebuilt below
    table = _build_table(weights)
    if use_cache:
        # Write then rename, so a concurrent reader never sees a half-written file.
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        with open(tmp, "wb") as file:
            np.save(file, table)
        os.replace(tmp, path)
    return table
