"""Read a scene file (TOML) into a :class:`~abs.scene.scene.Scene`, validating every field.

Scene files are data: they are parsed with :mod:`tomllib`, never evaluated.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np

from abs.errors import SceneError
from abs.params.names import OBJECT_FIELDS
from abs.scene import materials as _materials  # noqa: F401  (registers the material types)
from abs.scene.fields import Fields
from abs.scene.materials.base import material_class, material_types
from abs.scene.scene import (CHROMIUM_IOR_RGB, CHROMIUM_K_RGB, EnvironmentSpec, ObjectSpec, Prior,
                             RenderSettings, Scene, SensorSpec)

__all__ = ["load_scene"]

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*$")
_MESH_SUFFIXES = (".ply", ".obj")
_IMAGE_SUFFIXES = (".exr", ".hdr", ".png", ".jpg", ".jpeg")


def _check_name(fields: Fields, key: str, name: str, what: str) -> None:
    if not _NAME.match(name):
        raise fields.error(key, f"{what} name {name!r} must start with a letter or '_' and contain "
                                "only letters, digits, '_' and '-'")
    if name in ("environment", "sensor"):
        raise fields.error(key, f"{what} name {name!r} is reserved")


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file.

    Parameters
    ----------
    path : str or Path
        A TOML scene file (format: ``docs/scene-format.md``).

    Raises
    ------
    SceneError
        Naming the file and the field, for any malformed or missing value or asset.
    """
    source = Path(path).resolve()
    if not source.is_file():
        raise SceneError(source, "", "scene file not found")
    try:
        data = tomllib.loads(source.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(source, "", f"not valid TOML: {exc}") from None
    root = Fields(data, source, "")
    root.check_known({"render", "environment", "sensor", "materials", "objects", "fit"})

    render_fields = root.sub("render", required=False) or Fields({}, source, "render")
    render_fields.check_known({"spp", "max_depth"})
    render = RenderSettings(
        spp=render_fields.number("spp", 64, lower=1, integer=True),
        max_depth=render_fields.number("max_depth", 12, lower=1, upper=1000, integer=True),
    )

    env_fields = root.sub("environment")
    env_fields.check_known({"file", "scale", "to_world", "rotation", "inverse_distance", "center",
                            "orientation", "probe_fresnel", "probe_view", "probe_ior", "probe_k"})
    environment = EnvironmentSpec(
        file=env_fields.file("file", suffixes=_IMAGE_SUFFIXES),
        scale=env_fields.number("scale", 1.0, lower=0.0),
        to_world=env_fields.transform("to_world"),
        rotation=env_fields.number("rotation", 0.0),
        inverse_distance=env_fields.number("inverse_distance", 0.0, lower=0.0),
        center=env_fields.array("center", (3,), default=[0.0, 0.0, 0.0]),
        # Three numbers, never one for all: a rotation vector [a, a, a] is no natural shorthand.
        orientation=env_fields.array("orientation", (3,), default=[0.0, 0.0, 0.0]),
        # Bounded so that 1 + c (F/F(1) - 1) stays positive for every direction for a ball of
        # normal-incidence reflectance above 0.47 whose reflectance dips by less than 20 %.
        probe_fresnel=env_fields.vector("probe_fresnel", 3, default=np.zeros(3), lower=-0.9, upper=5.0),
        probe_view=_unit(env_fields, "probe_view", [0.0, 0.0, 1.0]),
        probe_ior=env_fields.rgb("probe_ior", default=np.array(CHROMIUM_IOR_RGB), lower=1e-3),
        probe_k=env_fields.rgb("probe_k", default=np.array(CHROMIUM_K_RGB), lower=0.0),
    )
    sensor = _sensor(root.sub("sensor", required=False) or Fields({}, source, "sensor"))

    mat_fields = root.sub("materials")
    materials = {}
    for name in mat_fields.table:
        _check_name(mat_fields, name, name, "material")
        fields = mat_fields.sub(name)
        type_name = fields.string("type")
        cls = material_class(type_name)
        if cls is None:
            raise fields.error("type", f"unknown material type {type_name!r}; known types: "
                                       f"{', '.join(material_types())}")
        for reserved in OBJECT_FIELDS:
            if fields.has(reserved):
                raise _object_field(fields, name, reserved)
        materials[name] = cls.from_fields(name, fields)
        for reserved in OBJECT_FIELDS:
            if reserved in materials[name].parameters():  # a material type that declares one
                raise _object_field(fields, name, reserved)
        materials[name]._files = fields.files_below()
    if not materials:
        raise mat_fields.error("", "no materials defined")

    raw_objects = root.raw("objects")
    if not isinstance(raw_objects, list) or not raw_objects:
        raise root.error("objects", "expected at least one [[objects]] table")
    objects = []
    for i, raw in enumerate(raw_objects):
        if not isinstance(raw, dict):
            raise root.error(f"objects[{i}]", "expected a table")
        fields = Fields(raw, source, f"objects[{i}]")
        fields.check_known({"name", "mesh", "material", "to_world", "pose", "placement"})
        name = fields.string("name")
        # An object may share its material's name (a "cloth" object of material "cloth"): its
        # parameters are <name>.pose and <name>.placement, and no material has such fields.
        _check_name(fields, "name", name, "object")
        if any(o.name == name for o in objects):
            raise fields.error("name", f"duplicate object name {name!r}")
        material = fields.string("material")
        if material not in materials:
            raise fields.error("material", f"unknown material {material!r}; defined: "
                                           f"{', '.join(sorted(materials))}")
        objects.append(ObjectSpec(
            name=name,
            mesh=fields.file("mesh", suffixes=_MESH_SUFFIXES),
            material=material,
            to_world=fields.transform("to_world"),
            pose=fields.array("pose", (6,), default=[0.0] * 6),
            placement=fields.array("placement", (3,), default=[0.0] * 3),
        ))

    scene = Scene(source, render, environment, materials, tuple(objects), sensor)
    fit_fields = root.sub("fit", required=False)
    if fit_fields is None:
        return scene
    fit_fields.check_known({"parameters", "priors"})
    # Validate parameter names now, so a typo fails at load time rather than mid-fit.
    from abs.params.names import parameter_specs

    known = parameter_specs(scene)
    return replace(scene, fit_parameters=_fit_parameters(fit_fields, known),
                   fit_priors=_fit_priors(fit_fields, known))


def _object_field(fields: Fields, name: str, reserved: str) -> SceneError:
    """The error for a material field named ``pose`` or ``placement``, which would share its
    parameter name with an object's (``<name>.pose``): the contract reserves them for objects."""
    return fields.error(reserved, f"a material may not have a field named {reserved!r}: "
                                  f"parameter '{name}.{reserved}' would name the {reserved} of an "
                                  f"object called {name!r} (objects and materials may share names)")


def _unit(fields: Fields, key: str, default) -> np.ndarray:
    """A direction: three numbers, not all zero, returned normalised."""
    value = fields.array(key, (3,), default=default)
    norm = float(np.linalg.norm(value))
    if not norm > 0.0:
        raise fields.error(key, f"expected a direction (three numbers, not all zero), got {value.tolist()}")
    return value / norm


def _sensor(fields: Fields) -> SensorSpec:
    """``[sensor]``: every field optional, each defaulting to its null value."""
    fields.check_known(set(SensorSpec.FIELDS))
    values = {key: fields.vector(key, size, default=SensorSpec.null(key), lower=lower, upper=upper)
              for key, (size, _, lower, upper, _) in SensorSpec.FIELDS.items()
              if key != "colour_matrix"}
    return SensorSpec(**values, colour_matrix=_colour_matrix(fields))


def _colour_matrix(fields: Fields) -> np.ndarray:
    """``[sensor] colour_matrix``: 9 numbers row-major, or 3 rows of 3 (identity when absent).

    One number is not accepted (unlike the per-channel fields): ``colour_matrix = 1`` would
    read as the identity but mean a matrix of ones. Any finite matrix is valid (every value
    inside a parameter's bounds must load, so that fitted values can always be written back).
    """
    key = "colour_matrix"
    if not fields.has(key):
        return SensorSpec.null(key)
    value = fields.raw(key)
    nested = isinstance(value, list) and len(value) == 3 and all(isinstance(v, list) for v in value)
    if not isinstance(value, list) or (len(value) != 9 and not nested):
        raise fields.error(key, f"expected 9 numbers (row-major) or 3 rows of 3 numbers, got {value!r}")
    return (fields.array(key, (3, 3)) if nested else fields.array(key, (9,))).ravel()


def _fit_parameters(fit_fields: Fields, known: dict) -> tuple[str, ...]:
    names = fit_fields.raw("parameters", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise fit_fields.error("parameters", f"expected a list of parameter names, got {names!r}")
    for i, name in enumerate(names):
        if name not in known:
            raise fit_fields.error(f"parameters[{i}]",
                                   f"unknown parameter {name!r}; known: {', '.join(sorted(known))}")
    return tuple(names)


def _fit_priors(fit_fields: Fields, known: dict) -> dict[str, Prior]:
    """``[fit.priors."NAME"]`` tables: ``mean`` and ``sd`` (> 0) of the parameter's size."""
    table = fit_fields.sub("priors", required=False)
    if table is None:
        return {}
    priors = {}
    for name, raw in table.table.items():
        # Parameter names contain a dot, so the key is quoted in the file and in messages.
        key = f'"{name}"'
        if name not in known:
            raise table.error(key, f"unknown parameter {name!r}; known: {', '.join(sorted(known))}")
        if not isinstance(raw, dict):
            raise table.error(key, f"expected a table with mean and sd, got {raw!r}")
        size = known[name].size
        if size == -1:
            raise table.error(key, f"{name} has no fixed size (a texture); it cannot have a prior")
        fields = Fields(raw, table.source, table.path(key))
        fields.check_known({"mean", "sd"})
        mean = fields.vector("mean", size)
        sd = fields.vector("sd", size)
        if np.any(sd <= 0):
            raise fields.error("sd", f"all entries must be > 0, got {sd.tolist()}")
        priors[name] = Prior(mean, sd)
    return priors
