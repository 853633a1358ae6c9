"""Write a :class:`~abs.scene.scene.Scene` back to a TOML scene file, optionally with some
parameters replaced (e.g. by fitted values), so that a fit result is itself a loadable scene.

The written file holds the same information as the loaded one, not the same text: comments and
field order of the source are not kept, defaults may be spelt out, and asset paths are rewritten
relative to the new file's folder.
"""

from __future__ import annotations

import copy
import os
import re
import textwrap
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import tomli_w

from abs.params.names import Parameter, parameter_specs
from abs.scene.materials.base import Material
from abs.scene.scene import Scene

__all__ = ["write_scene", "scene_table"]


def write_scene(scene: Scene, path: str | Path, values: Mapping[str, object] | None = None) -> Path:
    """Write ``scene`` as a TOML scene file that :func:`~abs.scene.load_scene` reads back.

    Parameters
    ----------
    scene : Scene
        The scene to write.
    path : str or Path
        The new scene file; its folder is created if missing. Asset paths in it are relative to
        this folder (absolute where no relative path exists, e.g. another drive).
    values : mapping of str to array-like, optional
        Parameter values to write instead of the scene's, by name (``glass.absorption``,
        ``environment.scale``, ``sphere.pose``, ...; see :func:`abs.params.parameter_specs`), in the
        parameter's unit.

    Returns
    -------
    Path
        The written file, absolute.

    Raises
    ------
    KeyError
        For a name that is not a parameter of ``scene``.
    ValueError
        For a value of the wrong size, non-finite or outside the parameter's bounds, or for a
        parameter without a fixed size (a texture), which has no place in the TOML file.
    """
    out = Path(path).resolve()
    checked = _checked_values(scene, values or {})
    data = scene_table(scene, out.parent, checked)
    note = f"Written by abs from {scene.source}. Paths are relative to this file."
    if checked:
        note += f" Values replaced: {', '.join(sorted(checked))}."
    header = "".join(f"# {line}\n" for line in textwrap.wrap(note, 98, break_long_words=False)) + "\n"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(header + _inline_flat_arrays(tomli_w.dumps(data)), encoding="utf-8")
    return out


# tomli-w puts every array item on its own line; a colour or a pose reads better on one. Strings
# are written single-line (escaped), so "[" followed by a newline only ever opens an array.
_ITEM = r'(?:[-+0-9.eE]+|"[^"\\\n]*")'
_FLAT_ARRAY = re.compile(r"\[\n((?:[ \t]*" + _ITEM + r",\n)+)[ \t]*\]")


def _inline_flat_arrays(text: str) -> str:
    """Put arrays of numbers or plain strings on one line; a matrix becomes one line per row."""
    return _FLAT_ARRAY.sub(
        lambda m: "[" + ", ".join(item.strip().rstrip(",") for item in m.group(1).splitlines()) + "]",
        text)


def _checked_values(scene: Scene, values: Mapping[str, object]) -> dict[str, object]:
    """The values as TOML-ready numbers: a float for size-1 parameters, a list otherwise."""
    specs = parameter_specs(scene)
    checked = {}
    for name, value in values.items():
        if name not in specs:
            raise KeyError(f"unknown parameter {name!r}; known: {', '.join(sorted(specs))}")
        checked[name] = _toml_value(specs[name], value)
    return checked


def _toml_value(spec: Parameter, value) -> float | list[float]:
    if spec.size == -1:
        raise ValueError(f"{spec.name}: has no fixed size (a texture) and cannot be written into "
                         "a scene file; write the image and point the scene at it instead")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{spec.name}: expected {spec.size} number(s), got {value!r}") from None
    if arr.ndim > 1 or arr.size != spec.size:
        raise ValueError(f"{spec.name}: expected {spec.size} number(s), got shape {list(arr.shape)}")
    arr = arr.reshape(-1)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{spec.name}: contains NaN or infinity: {arr.tolist()}")
    if np.any(arr < spec.lower) or np.any(arr > spec.upper):
        raise ValueError(f"{spec.name}: {arr.tolist()} outside [{spec.lower}, {spec.upper}] "
                         f"({spec.unit})")
    return float(arr[0]) if spec.size == 1 else arr.tolist()


def _relative(path: Path, folder: Path) -> str:
    """``path`` as seen from ``folder``, with '/' separators so the file is portable."""
    try:
        return Path(os.path.relpath(path, folder)).as_posix()
    except ValueError:  # Windows: no relative path between drives
        return Path(path).as_posix()


def _transform(table: dict, matrix: np.ndarray) -> None:
    """Add ``to_world`` unless it is the identity, the default (16 numbers of clutter otherwise)."""
    if not np.array_equal(matrix, np.eye(4)):
        table["to_world"] = np.asarray(matrix, dtype=np.float64).tolist()


def scene_table(scene: Scene, folder: Path, values: dict[str, object]) -> dict:
    env = scene.environment
    environment = {"file": _relative(env.file, folder),
                   "scale": values.get("environment.scale", float(env.scale))}
    _transform(environment, env.to_world)
    environment["rotation"] = values.get("environment.rotation", float(env.rotation))
    environment["inverse_distance"] = values.get("environment.inverse_distance",
                                                 float(env.inverse_distance))
    environment["center"] = np.asarray(env.center, np.float64).tolist()
    environment["orientation"] = values.get("environment.orientation",
                                            np.asarray(env.orientation, np.float64).tolist())
    environment["probe_fresnel"] = values.get("environment.probe_fresnel",
                                              np.asarray(env.probe_fresnel, np.float64).tolist())
    environment["probe_view"] = np.asarray(env.probe_view, np.float64).tolist()
    environment["probe_ior"] = np.asarray(env.probe_ior, np.float64).tolist()
    environment["probe_k"] = np.asarray(env.probe_k, np.float64).tolist()
    sensor = {key: values.get(f"sensor.{key}", np.asarray(getattr(scene.sensor, key), np.float64).tolist())
              for key in type(scene.sensor).FIELDS}
    # Three rows of three read as the matrix they are (the loader takes either form).
    sensor["colour_matrix"] = np.asarray(sensor["colour_matrix"], np.float64).reshape(3, 3).tolist()

    objects = []
    for obj in scene.objects:
        table = {"name": obj.name, "mesh": _relative(obj.mesh, folder), "material": obj.material}
        _transform(table, obj.to_world)
        table["pose"] = values.get(f"{obj.name}.pose", np.asarray(obj.pose, np.float64).tolist())
        # Written only where it is used, so scene files of objects that have none stay as they were.
        placement = values.get(f"{obj.name}.placement", np.asarray(obj.placement, np.float64).tolist())
        if np.any(np.asarray(placement) != 0) or f"{obj.name}.placement" in values:
            table["placement"] = placement
        objects.append(table)

    data = {
        "render": {"spp": int(scene.render.spp), "max_depth": int(scene.render.max_depth)},
        "environment": environment,
        "sensor": sensor,
        "materials": {name: _material_table(material, folder, values)
                      for name, material in scene.materials.items()},
        "objects": objects,
    }
    fit = _fit_table(scene)
    if fit:
        data["fit"] = fit
    return data


def _material_table(material: Material, folder: Path, values: dict[str, object]) -> dict:
    """The material's own TOML table, with asset paths re-rooted and fitted fields replaced."""
    table = copy.deepcopy(material.to_toml())
    for key, path in material.file_fields().items():
        *parents, last = key.split(".")
        sub = table
        for part in parents:
            sub = sub.get(part) if isinstance(sub, dict) else None
        # A file the material resolved but does not write back is not ours to add.
        if isinstance(sub, dict) and isinstance(sub.get(last), str):
            sub[last] = _relative(path, folder)
    fields = material.parameters()  # not <name>.pose or .placement, an object's when one shares the name
    for name, value in values.items():
        owner, field = name.split(".", 1)
        if owner == material.name and field in fields:
            table[field] = value
    return table


def _fit_table(scene: Scene) -> dict:
    fit = {}
    if scene.fit_parameters:
        fit["parameters"] = list(scene.fit_parameters)
    if scene.fit_priors:
        fit["priors"] = {name: {"mean": _numbers(prior.mean), "sd": _numbers(prior.sd)}
                         for name, prior in scene.fit_priors.items()}
    return fit


def _numbers(arr: np.ndarray) -> float | list[float]:
    return float(arr[0]) if arr.size == 1 else np.asarray(arr, np.float64).tolist()
