"""A :class:`~abs.scene.scene.Scene` compiled to a differentiable Mitsuba scene.

:class:`CompiledScene` is the one bridge between abs's scene representation and Dr.Jit: it owns
the Mitsuba scene, the environment, and the bindings that write each named parameter
(``glass.ior``, ``sphere.pose``...) into them. Any value written may be attached to the AD graph;
renders then differentiate with respect to it::

    cs = compile_scene(load_scene("scenes/default/scene.toml"))
    x = mi.Float([2.0, 1.0, 0.5]); dr.enable_grad(x)
    cs.set("glass.absorption", x)
    image = cs.render(camera, spp=16, seed=0)
    dr.backward(dr.mean(image, axis=None)); dr.grad(x)
"""

from __future__ import annotations

import os
from dataclasses import replace

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.errors import SceneError
from abs.params.names import OBJECT_FIELDS, PLACEMENT_FIELD, POSE_FIELD, Parameter, parameter_specs
from abs.params.setters import NormalSmoothingSetter
from abs.render import bsdfs as _bsdfs  # noqa: F401  (registers abs's BSDF plugins)
from abs.render.brdf_tables import bind_coefficients
from abs.render.camera import Camera
from abs.render.edges import MovingMesh, edge_adjacency, neighbour_mean
from abs.render.environment import Environment
from abs.render.integrator import PathTracer
from abs.render.jit import from_numpy, in_use, opaque
from abs.render.path_lengths import (DEFAULT_NODES, JOINT_NODES, MAX_MATERIALS,
                                     PathLengthRecording, length_bins, reweight)
from abs.render.rotation import rotation_matrix
from abs.render.sensor import Sensor
from abs.render.variant import current_backend
from abs.scene.scene import Scene

__all__ = ["CompiledScene", "compile_scene", "rotation_matrix", "shape_ids"]

# Camera samples per launch, by Dr.Jit backend (``$ABS_SAMPLES_IN_FLIGHT`` overrides). Every render
# mode (primal, forward, replay, recording) splits spp alike, so the same seed gives the same
# samples in each. On the CPU, 2^21 keeps the forward mode's doubled loop state well under a
# gigabyte, and larger launches are no faster on a few threads. On a GPU, launches of 2^21 lanes
# left an H100 half idle (measured at 1280x960, 64 spp: 0.52x the samples per second of Mitsuba's
# ``path`` at 2^21, 0.87x at 2^23, 1.06x at 2^24); 2^24 lanes of forward-mode state fit a GPU of
# a few gigabytes.
SAMPLES_IN_FLIGHT = {"llvm": 1 << 21, "cuda": 1 << 24}


def samples_in_flight() -> int:
    """Camera samples per render launch for the active backend (see :data:`SAMPLES_IN_FLIGHT`)."""
    override = os.environ.get("ABS_SAMPLES_IN_FLIGHT")
    if override:
        try:
            value = int(override)
        except ValueError:
            value = 0
        if value < 1:
            raise ValueError(f"$ABS_SAMPLES_IN_FLIGHT must be a positive integer, not {override!r}")
        return value
    return SAMPLES_IN_FLIGHT[current_backend()]

# Material fields whose Mitsuba value is computed from the parameter in Dr.Jit, by material type.
# The computation lives here, in the renderer bridge, because abs.scene (where the materials are)
# sits below abs.render and must not import it (docs/architecture.md).
_DRJIT_BINDINGS = {"brdf_pca": bind_coefficients}


def _mesh_dict(obj) -> dict:
    kind = "ply" if obj.mesh.suffix.lower() == ".ply" else "obj"
    return {"type": kind, "filename": str(obj.mesh),
            "to_world": mi.ScalarTransform4f(obj.to_world.astype(np.float64)),
            "bsdf": {"type": "ref", "id": obj.material}}


def shape_ids(scene: Scene) -> dict[str, str]:
    """The Mitsuba id of each object's shape, by object name.

    The object's name, unless a material has the same name: the scene-file contract allows that
    (``cloth.pose`` is the object's parameter, every other ``cloth.<field>`` the material's), but
    Mitsuba keeps BSDFs and shapes in one namespace of ids. The shape then becomes
    ``<name>:object``; ``:`` cannot occur in a scene-file name, so no other id can equal it.
    BSDF ids are always the material names (``<material>.<mitsuba_key>`` parameter keys).
    """
    return {obj.name: f"{obj.name}:object" if obj.name in scene.materials else obj.name
            for obj in scene.objects}


class CompiledScene:
    """A scene ready to render and differentiate. Build it with :func:`compile_scene`."""

    def __init__(self, scene: Scene):
        from abs.io.images import read_image

        self.scene = scene
        self.specs: dict[str, Parameter] = parameter_specs(scene)
        self.shape_ids: dict[str, str] = shape_ids(scene)
        spec = scene.environment
        self.environment = Environment(read_image(spec.file), spec.scale, spec.to_world, spec.rotation,
                                       spec.inverse_distance, spec.center, spec.orientation,
                                       spec.probe_fresnel, spec.probe_view, spec.probe_ior, spec.probe_k)
        self.sensor = Sensor(scene.sensor.vignetting, scene.sensor.response, scene.sensor.stray_light,
                             scene.sensor.colour_matrix, scene.sensor.intrinsics_offset,
                             scene.sensor.camera_turn)
        self.mitsuba_scene = self._load(self.mitsuba_dict(include_environment=False))
        self.params = mi.traverse(self.mitsuba_scene)
        self._rest = {}
        for obj in scene.objects:
            sid = self.shape_ids[obj.name]
            pos = np.array(self.params[f"{sid}.vertex_positions"]).reshape(-1, 3)
            normals_key = f"{sid}.vertex_normals"
            normals = (np.array(self.params[normals_key]).reshape(-1, 3)
                       if normals_key in self.params and dr.width(self.params[normals_key]) else None)
            self._rest[obj.name] = (pos, normals, pos.mean(axis=0))
        self._posed: dict[str, mi.Float] = {}
        self._adjacency: dict[str, tuple] = {}
        self._smoothing: dict[str, mi.Float] = {}     # material -> its normal_smoothing
        self._normal_detail: dict[str, np.ndarray] = {}  # object -> neighbours' mean minus normal
        self.values: dict[str, object] = {}
        for name, p in self.specs.items():
            if p.initial is not None:
                self.values[name] = opaque(mi.Float, np.asarray(p.initial, np.float32))
        for obj in scene.objects:
            for field, value in ((POSE_FIELD, obj.pose), (PLACEMENT_FIELD, obj.placement)):
                if np.any(value != 0):
                    self.set(f"{obj.name}.{field}", from_numpy(mi.Float, value))
        for name, spec in self.specs.items():
            # Fields that reshape meshes rather than set a BSDF value: Mitsuba loaded the meshes
            # as they are, so a scene file's non-null value is written into them here.
            if isinstance(spec.setter, NormalSmoothingSetter) and not spec.at_null():
                self.set(name, from_numpy(mi.Float, spec.initial))
        for name, material in scene.materials.items():
            for field in material.parameters():
                # Every value goes through set() once: Mitsuba builds plugins with their values as
                # kernel literals, and the first set() would otherwise compile every kernel anew.
                # (brdf_pca computes its table from the coefficients here.)
                if f"{name}.{field}" in self.values:
                    self.set(f"{name}.{field}", self.values[f"{name}.{field}"])

    # ------------------------------------------------------------- building
    def _load(self, d: dict) -> mi.Scene:
        try:
            # optimize=False: Mitsuba would otherwise merge meshes that share a BSDF into one
            # shape, and each object must stay its own shape for its pose parameter.
            return mi.load_dict(d, optimize=False)
        except RuntimeError as exc:  # Mitsuba names the file but not the scene field; add it.
            for obj in self.scene.objects:
                if str(obj.mesh) in str(exc) or obj.mesh.name in str(exc):
                    raise SceneError(self.scene.source, f"objects.{obj.name}.mesh",
                                     f"cannot load mesh {obj.mesh}: {exc}") from None
            raise SceneError(self.scene.source, "", f"Mitsuba could not build the scene: {exc}") from None

    def mitsuba_dict(self, include_environment: bool = True) -> dict:
        """The scene as a Mitsuba dictionary (BSDFs with material names as ids, shapes with the ids
        of :attr:`shape_ids`: object names, unless a material shares one), for use with stock
        Mitsuba integrators and sensors."""
        d: dict = {"type": "scene"}
        for name, material in self.scene.materials.items():
            d[name] = {**material.to_mitsuba(), "id": name}
        for obj in self.scene.objects:
            sid = self.shape_ids[obj.name]
            d[sid] = {**_mesh_dict(obj), "id": sid}
        if include_environment:
            d["environment"] = self.environment.mitsuba_dict()
        return d

    # ----------------------------------------------------------- parameters
    def get(self, name: str) -> np.ndarray:
        """Current value of a parameter as a float64 numpy array."""
        self._spec(name)
        if name in self.values:
            return np.array(dr.detach(self.values[name]), dtype=np.float64).ravel()
        return np.array(dr.detach(self._mitsuba_value(name)), dtype=np.float64).ravel()

    def set(self, name: str, value) -> None:
        """Write a parameter. ``value`` may be a Dr.Jit ``Float`` attached to the AD graph."""
        spec = self._spec(name)
        if not isinstance(value, mi.Float):
            value = opaque(mi.Float, np.asarray(value, np.float32).ravel())
        if spec.size > 0 and dr.width(value) != spec.size:
            raise ValueError(f"{name}: expected {spec.size} values, got {dr.width(value)}")
        self.values[name] = value
        # The parameter's owner chose how it is written (abs.params.setters): environment and
        # sensor members, a pose, a Mitsuba key, or the material's own binding.
        spec.setter(self, value)
        self.params.update()

    def bind_material(self, name: str, field: str, value) -> None:
        """Write material ``name``'s ``field`` that has no Mitsuba key: through the renderer's
        Dr.Jit binding for the material's type (``_DRJIT_BINDINGS``: a PCA table from its
        coefficients), else the material's own :meth:`~abs.scene.materials.Material.apply`."""
        material = self.scene.materials[name]
        binding = _DRJIT_BINDINGS.get(material.type_name)
        if binding is not None:
            binding(material, field, value, self.params)
        else:
            material.apply(field, value, self.params)

    def write_mitsuba(self, key: str, value: mi.Float) -> None:
        """Write ``value`` into the Mitsuba scene parameter ``key`` (``glass.ior``), converted to
        its type: a tensor keeps its shape, a one-value ``Float`` takes the first entry, a colour
        takes three entries (or one for all channels). :meth:`update` is left to the caller."""
        target = self.params[key]
        if isinstance(target, mi.TensorXf):
            self.params[key] = mi.TensorXf(value, target.shape)
        elif isinstance(target, mi.Float):
            self.params[key] = value if dr.width(target) == dr.width(value) else value[0]
        else:
            self.params[key] = type(target)(*[dr.gather(mi.Float, value, i) for i in range(3)]) \
                if dr.width(value) == 3 else type(target)(value)

    def _mitsuba_value(self, name: str):
        spec = self._spec(name)
        mspec = self.scene.materials[spec.owner].parameters()[spec.field]
        target = self.params[f"{spec.owner}.{mspec.mitsuba_key}"]
        return target.array if isinstance(target, mi.TensorXf) else target

    def set_normal_smoothing(self, material: str, value: mi.Float) -> None:
        """Smooth the shading normals of every mesh of ``material`` (``<material>.normal_smoothing``;
        use :meth:`set`, which records the value): vertex normal ``n + s (m - n)``, ``m`` the
        mean of its edge neighbours' normals as loaded, ``s`` the value (Mitsuba normalises the
        interpolated normal). At ``s = 0`` the normals are the loaded ones exactly
        (``n + 0 (m - n)``). An object's pose turns the smoothed normals."""
        self._smoothing[material] = value
        for obj in self.scene.objects:
            if obj.material != material or self._rest[obj.name][1] is None:
                continue
            if self._moved(obj.name):
                self.move_object(obj.name)  # writes the smoothed normals, turned
            else:
                self.params[f"{self.shape_ids[obj.name]}.vertex_normals"] = dr.ravel(self._normals(obj.name))

    def _normals(self, obj: str) -> mi.Vector3f:
        """Object ``obj``'s vertex normals before its pose: as loaded, smoothed by its material's
        ``normal_smoothing`` when one was set."""
        normals = self._rest[obj][1]
        n = mi.Vector3f(*[from_numpy(mi.Float, normals[:, i]) for i in range(3)])
        material = next(o.material for o in self.scene.objects if o.name == obj)
        if material not in self._smoothing:
            return n
        if obj not in self._normal_detail:
            faces = np.array(self.params[f"{self.shape_ids[obj]}.faces"], np.int64).reshape(-1, 3)
            self._normal_detail[obj] = neighbour_mean(normals, faces) - normals
        detail = self._normal_detail[obj]
        s = dr.gather(mi.Float, self._smoothing[material], mi.UInt32(0))
        return n + s * mi.Vector3f(*[from_numpy(mi.Float, detail[:, i]) for i in range(3)])

    def _moved(self, obj: str) -> bool:
        """Whether object ``obj`` has a pose or placement that is non-zero or being differentiated."""
        values = (self.values.get(f"{obj}.{field}") for field in OBJECT_FIELDS)
        return any(value is not None and in_use(value) for value in values)

    def move_object(self, obj: str) -> None:
        """Move object ``obj``'s mesh rigidly from where the scene file puts it by its recorded
        pose (``[tx, ty, tz, rx, ry, rz]``, metres and a rotation vector about the mesh's
        centroid) and placement (``[tx, tz, ry]``: the pose ``[tx, 0, tz, 0, ry, 0]``), composed
        as ``x' = R(r_pose) R_y(ry) (x - c) + c + t_placement + t_pose``
        (``docs/conventions.md``). :meth:`set` (``<obj>.pose``, ``<obj>.placement``) records a
        value and calls this."""
        pos, normals, centre = self._rest[obj]
        positions = mi.Vector3f(*[from_numpy(mi.Float, pos[:, i]) for i in range(3)])
        n = None if normals is None else self._normals(obj)
        # Back at the null values (and detached) the mesh stays the loaded one bit for bit,
        # which (p - c) + c in floating point is not.
        if self._moved(obj):
            rot, t = self._motion(obj)
            c = mi.Vector3f(*[float(x) for x in centre])
            positions = rot @ (positions - c) + c + t
            n = None if n is None else rot @ n
        sid = self.shape_ids[obj]
        self._posed[obj] = dr.ravel(positions)
        self.params[f"{sid}.vertex_positions"] = self._posed[obj]
        if n is not None:
            self.params[f"{sid}.vertex_normals"] = dr.ravel(n)

    def _motion(self, obj: str) -> tuple[mi.Matrix3f, mi.Vector3f]:
        """``(R(r_pose) R_y(ry), t_placement + t_pose)`` of object ``obj``'s recorded values."""
        zero = mi.Float(0.0)
        pose = self.values.get(f"{obj}.{POSE_FIELD}")
        placement = self.values.get(f"{obj}.{PLACEMENT_FIELD}")
        t = mi.Vector3f(0.0)
        rot = mi.Matrix3f(1.0)
        if placement is not None:
            # The placement first: its turn is about the vertical through the centroid, whatever
            # the pose's tilt then does.
            slide = [dr.gather(mi.Float, placement, i) for i in range(3)]
            t = mi.Vector3f(slide[0], zero, slide[1])
            rot = rotation_matrix(mi.Vector3f(zero, slide[2], zero))
        if pose is not None:
            t = t + mi.Vector3f(*[dr.gather(mi.Float, pose, i) for i in range(3)])
            rot = rotation_matrix(mi.Vector3f(*[dr.gather(mi.Float, pose, i) for i in range(3, 6)])) @ rot
        return rot, t

    def set_difference_step(self, name: str, step: float) -> None:
        """Take ``name``'s derivative by central differences of ``step`` (its units) from now on
        (:func:`abs.model.difference_steps.choose_difference_steps` chooses one per fit)."""
        spec = self._spec(name)
        if spec.difference_step is None:
            raise ValueError(f"{name} takes its derivative by forward mode, not by differences")
        if not (np.isfinite(step) and step > 0.0):
            raise ValueError(f"{name}: a difference step must be a positive number, not {step}")
        self.specs[name] = replace(spec, difference_step=float(step))

    def _spec(self, name: str) -> Parameter:
        if name not in self.specs:
            raise KeyError(f"unknown parameter {name!r}; known: {', '.join(sorted(self.specs))}")
        return self.specs[name]

    def moving_meshes(self) -> list[MovingMesh]:
        """Meshes whose pose or placement is attached to the AD graph (their silhouettes need
        edge sampling)."""
        out = []
        for obj in self.scene.objects:
            values = [self.values.get(f"{obj.name}.{field}") for field in OBJECT_FIELDS]
            if not any(v is not None and dr.grad_enabled(v) for v in values):
                continue
            if obj.name not in self._adjacency:
                faces = np.array(self.params[f"{self.shape_ids[obj.name]}.faces"],
                                 np.int64).reshape(-1, 3)
                self._adjacency[obj.name] = (faces, *edge_adjacency(faces))
            faces, edges, edge_faces = self._adjacency[obj.name]
            out.append(MovingMesh(self._posed[obj.name], edges, edge_faces, faces))
        return out

    def subsurface(self) -> list[tuple]:
        """``(shape, spread)`` of objects whose material's ``subsurface`` is non-zero or being
        differentiated, for :class:`PathTracer`; empty at the null value (the plain model)."""
        out = []
        shapes = {shape.id(): shape for shape in self.mitsuba_scene.shapes()}
        for obj in self.scene.objects:
            value = self.values.get(f"{obj.material}.subsurface")
            if value is None or not (dr.grad_enabled(value) or float(dr.detach(value)[0]) > 0.0):
                continue
            out.append((mi.ShapePtr(shapes[self.shape_ids[obj.name]]), value))
        return out

    # -------------------------------------------------------------- render
    def _tracer(self, max_depth: int | None) -> PathTracer:
        return PathTracer(max_depth=max_depth or self.scene.render.max_depth,
                          subsurface=self.subsurface())

    @staticmethod
    def _batches(camera: Camera, spp: int, samples_in_flight: int) -> list[int]:
        """spp split into batches of at most ``samples_in_flight`` camera samples."""
        per = max(1, min(spp, samples_in_flight // camera.samples(1)))
        return [per] * (spp // per) + ([spp % per] if spp % per else [])

    def render(self, camera: Camera, spp: int | None = None, seed: int = 0,
               max_depth: int | None = None) -> mi.TensorXf:
        """Render ``camera``'s view at the scene's ``[render]`` settings unless overridden.

        Returns a ``TensorXf`` of shape ``(height, width, 3)``: the radiance as the sensor records
        it (``[sensor]``: vignetting, stray light, colour matrix, response; linear RGB radiance
        when those are at their null values), attached to the AD graph of every parameter set with gradients enabled
        (then ``dr.backward`` and ``dr.forward_to`` work on it; for one directional derivative,
        :meth:`render_forward` is faster and needs far less memory).
        """
        return self.sensor.apply(self._radiance(camera, spp or self.scene.render.spp, seed, max_depth),
                                 camera)

    def _radiance(self, camera: Camera, spp: int, seed: int, max_depth: int | None) -> mi.TensorXf:
        """The path tracer's image (before the sensor), in batches of bounded samples in flight."""
        tracer = self._tracer(max_depth)
        # Bound the wavefront (samples in flight) so large renders fit in memory; each batch gets
        # its own seed and the batches are averaged.
        batches = self._batches(camera, spp, samples_in_flight())
        image = None
        for i, n in enumerate(batches):
            part = tracer.render(self.mitsuba_scene, self.environment, camera, n,
                                 seed * 7919 + i if len(batches) > 1 else seed,
                                 moving=self.moving_meshes()) * opaque(mi.Float, n / spp)
            image = part if image is None else image + part
            dr.eval(image)
        return image

    def _push_tangents(self, tangents: dict) -> list:
        """Set every named parameter to an attached leaf holding its tangent, and push the tangents
        into the scene's members (BSDF fields, vertex positions, ...), cutting the edges that led
        there: the path loop reads those members inside its own AD scope, which may not reach back
        across edges made outside it."""
        leaves = []
        for name, tangent in tangents.items():
            spec = self._spec(name)
            value = from_numpy(mi.Float, self.get(name))
            dr.enable_grad(value)
            self.set(name, value)
            tangent = np.asarray(tangent, np.float32).ravel()
            if tangent.size != dr.width(value):
                raise ValueError(f"{name}: tangent has {tangent.size} values, the parameter {spec.size}")
            dr.set_grad(value, from_numpy(mi.Float, tangent))
            leaves.append(value)
        dr.enqueue(dr.ADMode.Forward, leaves)
        dr.traverse(dr.ADMode.Forward, dr.ADFlag.ClearEdges)
        return leaves

    def _detach(self, names) -> None:
        """Write the named parameters' current values back detached (ends what
        :meth:`_push_tangents` or an attached leaf started)."""
        for name in names:
            self.set(name, from_numpy(mi.Float, self.get(name)))

    def _through_sensor_forward(self, camera: Camera, image, derivative):
        """The sensor applied to an image and its derivative (the sensor's own tangents added)."""
        with dr.resume_grad():
            radiance = mi.TensorXf(image)
            dr.enable_grad(radiance)
            dr.set_grad(radiance, derivative)
            recorded = self.sensor.apply(radiance, camera)
            derivative = dr.forward_to(recorded, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
        return dr.detach(recorded), mi.TensorXf(derivative)

    def render_forward(self, camera: Camera, tangents: dict, spp: int | None = None, seed: int = 0,
                       max_depth: int | None = None, differences: bool = True,
                       image_needed: bool = True) -> tuple[mi.TensorXf | None, mi.TensorXf]:
        """A rendering and its derivative along ``tangents``, by forward mode inside the path loop.

        Parameters
        ----------
        tangents : dict of str to array-like
            Parameter name to its tangent (the direction of change, in the parameter's units);
            parameters not named are held fixed.
        differences : bool
            Parameters with a ``difference_step`` (an IOR) take their derivative from central
            differences with common random numbers (:meth:`_central_difference`), which include
            the boundary terms of edges seen through refraction. ``False``: forward mode for
            every parameter (tangents inside the path loop; exact for glass that sees no edges).
        image_needed : bool
            ``False`` when the caller has the image already (a path-length recording at these
            values): central differences on both sides then skip the render at ``p``, and
            ``image`` is ``None`` where it was not rendered anyway.

        Returns
        -------
        image, derivative : TensorXf, shape (height, width, 3)
            Detached; ``derivative`` is ``sum_k d image / d p_k * tangent_k``. The same ``seed``
            gives the same samples as :meth:`render` (common random numbers) when no dispersive
            glass is being differentiated.
        """
        spp = spp or self.scene.render.spp
        differenced = self._differenced(tangents, differences)
        if differenced:
            traced = {n: t for n, t in tangents.items() if n not in differenced}
            if any(np.any(np.asarray(t) != 0) for t in traced.values()):
                image, derivative = self.render_forward(camera, traced, spp, seed, max_depth)
            elif image_needed or len(self._difference_signs(differenced)[1]) < 2:
                # A one-sided difference starts from the render at p, with the same samples.
                image, derivative = self.render(camera, spp, seed, max_depth), None
            else:
                image = derivative = None
            difference = self._central_difference(camera, differenced, spp, seed, max_depth, image)
            return image, difference if derivative is None else derivative + difference
        self._push_tangents(tangents)
        try:
            tracer = self._tracer(max_depth)
            batches = self._batches(camera, spp, samples_in_flight())
            image = derivative = None
            for i, n in enumerate(batches):
                part, d_part = tracer.render_forward(
                    self.mitsuba_scene, self.environment, camera, n,
                    seed * 7919 + i if len(batches) > 1 else seed, moving=self.moving_meshes())
                share = opaque(mi.Float, n / spp)
                image = part * share if image is None else image + part * share
                derivative = d_part * share if derivative is None else derivative + d_part * share
                dr.eval(image, derivative)
            return self._through_sensor_forward(camera, image, derivative)
        finally:
            self._detach(tangents)

    def forward_renders(self, tangents: dict, differences: bool = True,
                        image_needed: bool = True) -> int:
        """How many renders :meth:`render_forward` makes for ``tangents`` (the same arguments):
        one; with a moving parameter that has a ``difference_step``, its renders at ``p + h``
        and ``p - h`` (one of them when the other side leaves the bounds), and the render at
        ``p`` unless the image is not needed and the difference is two-sided. For render
        accounting."""
        differenced = self._differenced(tangents, differences)
        if not differenced:
            return 1
        sides = len(self._difference_signs(differenced)[1])
        traced = any(np.any(np.asarray(t) != 0) for n, t in tangents.items()
                     if n not in differenced)
        return sides + (1 if traced or image_needed or sides < 2 else 0)

    def _differenced(self, tangents: dict, differences: bool) -> dict:
        """The tangents that :meth:`render_forward` takes by central differences: nonzero, on
        parameters with a ``difference_step`` (none when ``differences`` is off)."""
        if not differences:
            return {}
        return {n: np.asarray(t, np.float64) for n, t in tangents.items()
                if self._spec(n).difference_step is not None and np.any(np.asarray(t) != 0)}

    def _central_difference(self, camera: Camera, tangents: dict, spp: int, seed: int,
                            max_depth: int | None, image) -> mi.TensorXf:
        """``d image / d p . tangent`` by central differences with common random numbers, for
        parameters with a ``difference_step`` (:class:`~abs.params.names.Parameter`).

        The step ``h`` moves the parameter with the largest tangent by its ``difference_step``.
        With the same samples at ``p +- h t``, a sample whose path keeps its structure contributes
        its smooth change, and one that crosses an edge seen through the glass contributes the
        jump: together the exact derivative of the image averaged over ``[p - h t, p + h t]``,
        boundary terms included, which forward mode leaves out. A step that would leave the
        parameter's bounds becomes one-sided, from ``image`` (the render at ``p``).
        """
        base = {n: self.get(n).astype(np.float64) for n in tangents}
        h, signs = self._difference_signs(tangents)

        def at(sign):
            for n, t in tangents.items():
                self.set(n, from_numpy(mi.Float, (base[n] + sign * h * t).astype(np.float32)))
            return self.render(camera, spp, seed, max_depth)

        try:
            upper = at(signs[0]) if signs[0] == 1 else image
            lower = at(-1) if -1 in signs else image
            width = h * (2 if len(signs) == 2 else 1)
            result = (upper - lower) / opaque(mi.Float, width)
            dr.eval(result)
            return result
        finally:
            for n in tangents:
                self.set(n, from_numpy(mi.Float, base[n].astype(np.float32)))

    def _difference_signs(self, tangents: dict) -> tuple[float, list[int]]:
        """The central difference's step ``h`` along ``tangents`` (the parameter with the largest
        tangent moves by its ``difference_step``) and the sides ``+1``, ``-1`` whose step stays
        within the bounds (``[1]`` when neither does)."""
        base = {n: self.get(n).astype(np.float64) for n in tangents}
        h = min(self._spec(n).difference_step / float(np.max(np.abs(t))) for n, t in tangents.items())

        def inside(sign):
            return all(np.all((self._spec(n).lower <= base[n] + sign * h * t)
                              & (base[n] + sign * h * t <= self._spec(n).upper))
                       for n, t in tangents.items())

        return h, [s for s in (1, -1) if inside(s)] or [1]

    def render_backward(self, camera: Camera, weight, names, spp: int | None = None, seed: int = 0,
                        max_depth: int | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The gradient of ``sum(weight * rendering)`` with respect to ``names``, by path replay.

        Parameters
        ----------
        weight : array-like, shape (height, width, 3)
            The loss's derivative with respect to the (sensor-applied) rendering.
        names : sequence of str
            Parameters to differentiate; none may move paths (``Parameter.moves_paths``: IOR,
            roughness, pose), whose derivatives need :meth:`render_forward`.

        Returns
        -------
        image : ndarray, shape (height, width, 3)
            The rendering the gradient belongs to (float64).
        gradient : dict of str to ndarray
            One array per name, in the parameter's units.
        """
        moving = [n for n in names if self._spec(n).moves_paths]
        if moving:
            raise ValueError(f"{', '.join(moving)} move light paths: path replay cannot "
                             "differentiate them; use render_forward")
        weight = mi.TensorXf(from_numpy(mi.Float, weight), (camera.height, camera.width, 3))
        leaves = {}
        for name in names:
            value = from_numpy(mi.Float, self.get(name))
            dr.enable_grad(value)
            self.set(name, value)
            leaves[name] = value
        tracer = self._tracer(max_depth)
        spp = spp or self.scene.render.spp
        batches = self._batches(camera, spp, samples_in_flight())

        def through_sensor(radiance):
            # d loss / d radiance through the sensor model; the sensor's own parameters (if
            # differentiated) receive their part here.
            with dr.resume_grad():
                radiance = mi.TensorXf(radiance)
                dr.enable_grad(radiance)
                dr.backward_from(self.sensor.apply(radiance, camera) * weight)
                return dr.grad(radiance)

        try:
            if len(batches) == 1:
                image = tracer.render_backward(self.mitsuba_scene, self.environment, camera, spp,
                                               seed, through_sensor)
            else:
                # A non-linear sensor is linearised at the whole image, which must be rendered
                # before any batch replays its paths. A linear one has the same adjoint at every
                # image, so the batches' own primal renders make the image (one primal render
                # fewer: measured on an H100, a gradient cost 2.99 primal renders with it).
                linear = self.sensor.is_linear()
                if linear:
                    image = None
                    adjoint = through_sensor(dr.zeros(mi.TensorXf, (camera.height, camera.width, 3)))
                else:
                    with dr.suspend_grad():
                        image = self._radiance(camera, spp, seed, max_depth)
                    adjoint = through_sensor(image)
                for i, n in enumerate(batches):
                    part = tracer.render_backward(self.mitsuba_scene, self.environment, camera, n,
                                                  seed * 7919 + i,
                                                  lambda img: adjoint * opaque(mi.Float, n / spp))
                    if linear:
                        # Summed as _radiance sums its batches: the same image bit for bit.
                        part = part * opaque(mi.Float, n / spp)
                        image = part if image is None else image + part
                        dr.eval(image)
            dr.traverse(dr.ADMode.Backward)
            with dr.suspend_grad():
                recorded = self.sensor.apply(image, camera).numpy().astype(np.float64)
            return recorded, {name: dr.grad(leaves[name]).numpy().astype(np.float64) for name in names}
        finally:
            self._detach(names)


    # ------------------------------------------------------- recordings
    def transmissive_bounds(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """World bounding boxes ``(lower, upper)`` (m) of the objects made of a transmissive
        material (glass): where a camera sees refraction."""
        transmissive = {name for name, m in self.scene.materials.items() if m.transmissive}
        return [(np.array(s.bbox().min, float).ravel(), np.array(s.bbox().max, float).ravel())
                for s in self.mitsuba_scene.shapes() if s.bsdf().id() in transmissive]

    def glass_material(self) -> str | None:
        """The one glass material whose absorption a recording reweights by default: the only
        transmissive material with an absorption field, ``None`` without glass."""
        glass = [name for name, m in self.scene.materials.items()
                 if m.transmissive and "absorption" in m.parameters()]
        if len(glass) > 1:
            raise ValueError(f"several glass materials ({', '.join(glass)}): name the one whose "
                             "path lengths to record")
        return glass[0] if glass else None

    def record(self, camera: Camera, spp: int | None = None, seed: int = 0,
               materials="auto", bins=None, absorption_per_m=0.0,
               max_depth: int | None = None) -> PathLengthRecording:
        """Render ``camera``'s view recording its light by path length inside ``materials``.

        :func:`~abs.render.path_lengths.reweight` (:meth:`render_recorded`) then gives the view
        at any absorptions of those materials and any environment scale and sensor, with no
        further render (see :mod:`abs.render.path_lengths`).

        Parameters
        ----------
        materials : str, sequence of str, or ``"auto"``
            The glass materials, at most :data:`~abs.render.path_lengths.MAX_MATERIALS`
            (``"auto"``: :meth:`glass_material`; empty or ``None``: no lengths, only scale and
            sensor reweight).
        bins : sequence of LengthBins, optional
            One per material. Default: up to 4 diagonals of the bounding box of the material's
            objects, 32 nodes for one material, ``JOINT_NODES`` each for several.
        absorption_per_m : float, array-like of 3, or one row of 3 per material
            The absorptions (1/m) to record at; 0 (the default) makes every reweighting an
            attenuation, whose variance is at most the recording's.

        Returns
        -------
        PathLengthRecording
        """
        spp = spp or self.scene.render.spp
        if materials == "auto":
            materials = self.glass_material()
        materials = (() if materials is None else (materials,) if isinstance(materials, str)
                     else tuple(materials))
        if len(materials) > MAX_MATERIALS or len(set(materials)) != len(materials):
            raise ValueError(f"record at most {MAX_MATERIALS} distinct glass materials, not "
                             f"{', '.join(materials)}")
        nodes = DEFAULT_NODES if len(materials) == 1 else JOINT_NODES
        glasses, default_bins = [], []
        for material in materials:
            if "absorption" not in self.scene.materials[material].parameters():
                raise ValueError(f"material {material!r} has no absorption to record lengths for")
            shapes = [s for s in self.mitsuba_scene.shapes() if s.bsdf().id() == material]
            if not shapes:
                raise ValueError(f"no object of the scene is made of {material!r}")
            glasses.append(shapes[0].bsdf())
            box = mi.ScalarBoundingBox3f()
            for shape in shapes:
                box.expand(shape.bbox())
            default_bins.append(length_bins(float(dr.norm(box.extents())), nodes))
        bins = tuple(default_bins if bins is None else bins)
        if len(bins) != len(materials):
            raise ValueError(f"{len(bins)} length bins for {len(materials)} materials")
        value = np.asarray(absorption_per_m, np.float64)
        recorded = np.broadcast_to(value if value.ndim == 2 else np.broadcast_to(value, 3),
                                   (len(materials), 3)).copy()
        names = [f"{m}.absorption" for m in materials]
        before = [self.get(n) for n in names]
        tracer = self._tracer(max_depth)
        batches = self._batches(camera, spp, samples_in_flight())
        histogram = None
        try:
            for name, value in zip(names, recorded):
                self.set(name, value)
            with dr.suspend_grad():
                for i, n in enumerate(batches):
                    part = tracer.record(self.mitsuba_scene, self.environment, camera, n,
                                         seed * 7919 + i if len(batches) > 1 else seed, glasses,
                                         bins)
                    part = part * opaque(mi.Float, n / spp)
                    histogram = part if histogram is None else histogram + part
                    dr.eval(histogram)
                env_scale = float(dr.detach(self.environment.scale)[0])
        finally:
            for name, value in zip(names, before):
                self.set(name, value)
        histogram = histogram.numpy().reshape(camera.height, camera.width, 3, -1)
        return PathLengthRecording(histogram, bins, materials, recorded, env_scale, spp, seed)

    def needs_render(self, names, materials) -> list[str]:
        """Those of ``names`` whose new values need a new render: the parameters a recording of
        ``materials``' path lengths does not reweight (empty: it gives every one)."""
        out = []
        for name in names:
            how = self._spec(name).reweighting
            if how is None or (how == "absorption" and self._spec(name).owner not in materials):
                out.append(name)
        return out

    def render_recorded(self, recording: PathLengthRecording, camera: Camera) -> mi.TensorXf:
        """The view of ``recording`` at the current absorption, environment scale and sensor.

        Every other parameter must be as it was during the recording, which the caller ensures
        (:class:`~abs.model.FitProblem` keys its recordings by them).
        """
        radiance, _ = reweight(recording, *self._recorded_values(recording, camera))
        return self.sensor.apply(mi.TensorXf(from_numpy(mi.Float, radiance), radiance.shape), camera)

    def _recorded_values(self, recording: PathLengthRecording, camera: Camera):
        if (camera.width, camera.height) != (recording.width, recording.height):
            raise ValueError(f"the recording is {recording.width}x{recording.height}, the camera "
                             f"{camera.width}x{camera.height}")
        absorption = np.array([self.get(f"{m}.absorption") for m in recording.materials]).reshape(-1, 3)
        return absorption, float(self.get("environment.scale")[0])

    def render_recorded_forward(self, recording: PathLengthRecording, camera: Camera,
                                tangents: dict) -> tuple[mi.TensorXf, mi.TensorXf]:
        """:meth:`render_forward` from a recording: the view and its derivative along
        ``tangents``, which may name only parameters the recording reweights (the absorption in
        closed form, the scale, the sensor by forward mode through it)."""
        others = self.needs_render(tangents, recording.materials)
        if others:
            raise ValueError(f"{', '.join(others)} change the light paths (or are not recorded): "
                             "a recording cannot differentiate them")
        d_absorption = np.array([np.broadcast_to(np.asarray(tangents.get(f"{m}.absorption", 0.0),
                                                            np.float64), 3)
                                 for m in recording.materials]).reshape(-1, 3)
        d_scale = float(np.asarray(tangents.get("environment.scale", 0.0)).ravel()[0])
        radiance, derivative = reweight(recording, *self._recorded_values(recording, camera),
                                        d_absorption=d_absorption, d_scale=d_scale)
        sensor = {n: t for n, t in tangents.items() if self._spec(n).reweighting == "after_paths"}
        self._push_tangents(sensor)
        try:
            return self._through_sensor_forward(
                camera, mi.TensorXf(from_numpy(mi.Float, radiance), radiance.shape),
                mi.TensorXf(from_numpy(mi.Float, derivative), derivative.shape))
        finally:
            self._detach(sensor)


def compile_scene(scene: Scene) -> CompiledScene:
    """Compile a :class:`Scene` to Mitsuba (activate a variant first, see :func:`abs.set_variant`)."""
    return CompiledScene(scene)
