"""``abs appearance``: material appearance across renderers and the camera (docs/appearance.md).

    abs appearance characterise --renderer NAME [--option KEY=VALUE ...] --out DIR
    abs appearance render --renderer NAME --design heldout --out DIR
    abs appearance transfer IMAGE --geometry GEOMETRY.npz --from A.npz --to B.npz --out OUT.exr
        [--method statistics|sensor|histogram-global|histogram-local] [--shift ratio|additive]
        [--sensor] [--colour-matrix none|class|global] [--spread] [--normals]
    abs appearance environment IMAGE --geometry GEOMETRY.npz --out ENV.exr
    abs appearance geometry SCENE CAPTURE --class OBJECT=CLASS ... --out DIR

``characterise`` renders the characterisation design with a registered renderer and writes
``DIR/characterisation.npz`` (the statistics), ``DIR/characterisation.json`` (a readable summary)
and, per scene, ``DIR/scenes/NAME/{image.exr,image.png,geometry.npz}``. ``render`` writes only the
scenes of a design (the held-out ones to test a transfer on). ``transfer`` makes IMAGE, rendered by
the renderer of ``--from``, look as the renderer of ``--to`` would render it (the steps and when
to use which: docs/appearance.md, "Transfer"), and with ``--target`` scores the result against
that renderer's own image (CIEDE2000, per object).
``environment`` estimates the lighting from the image's background (objects removed, the central
circle read as the hemisphere behind the image plane and mirrored) and writes a lat-long map, with
``ENV.json`` giving its ``environment.to_world`` for the design camera. ``geometry`` writes the
geometry maps of a scene file's objects (ray cast, :mod:`abs.appearance.mesh_geometry`) for every
view of a capture folder, so that ``abs render``'s images of it can be transferred.
"""

from __future__ import annotations

import json
from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("appearance", help="characterise renderers and the camera; transfer looks")
    verbs = p.add_subparsers(dest="verb", required=True)

    def scene_options(q):
        q.add_argument("--renderer", required=True, help="registered renderer (abs, mitsuba, camera, gains; "
                                                     "mitsuba --option spectral=true renders spectrally)")
        q.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                       help="renderer option (VALUE as JSON, e.g. gains=[1.2,1,0.8]); repeatable")
        q.add_argument("--out", type=Path, required=True, help="folder to write to")
        q.add_argument("--size", type=int, default=64, help="image side, pixels (default %(default)s)")
        q.add_argument("--spp", type=int, default=32, help="samples per pixel (default %(default)s)")
        q.add_argument("--seed", type=int, default=0, help="seed of the first scene (default %(default)s)")
        q.add_argument("--environment", help="lat-long map file, or constant:V (default: the shared "
                                             "royal_esplanade map)")

    c = verbs.add_parser("characterise", help="measure a renderer's filter statistics")
    scene_options(c)
    c.add_argument("--samples", type=int, default=2, help="material samples per class, 1 or 2")
    c.add_argument("--classes", help="comma-separated subset of the material classes")
    c.add_argument("--walls", help="comma-separated subset of the wall colourings")
    c.add_argument("--bins", type=int, default=9, help="θ bins over 0-90° (default %(default)s)")
    c.set_defaults(run=run_characterise)

    r = verbs.add_parser("render", help="render the scenes of a design, with their geometry maps")
    scene_options(r)
    r.add_argument("--design", choices=("heldout", "characterisation"), default="heldout")
    r.set_defaults(run=run_render)

    t = verbs.add_parser("transfer", help="make an image of renderer A look as renderer B's")
    t.add_argument("image", type=Path, help="linear image (.exr) rendered by A")
    t.add_argument("--geometry", type=Path, required=True, help="its geometry map (.npz)")
    t.add_argument("--from", dest="source", type=Path, required=True, help="A's characterisation")
    t.add_argument("--to", dest="target", type=Path, required=True, help="B's characterisation")
    t.add_argument("--out", type=Path, required=True, help="output image (.exr)")
    t.add_argument("--method", default="statistics", choices=tuple(_METHODS),
                   help="statistics: the θ transfer (after the optional steps below); sensor: the "
                        "sensor step alone; histogram-*: the paper's failing baselines "
                        "(default %(default)s)")
    t.add_argument("--colour-matrix", default="none", choices=("none", "class", "global"),
                   help="colour-matrix step before the θ transfer (default %(default)s)")
    t.add_argument("--spread", action="store_true", help="also apply the spread term ψ")
    t.add_argument("--shift", default="ratio", choices=("ratio", "additive"),
                   help="how λ moves a bin's pixels: scaled (ratio) or shifted (additive) "
                        "(default %(default)s)")
    t.add_argument("--sensor", action="store_true",
                   help="first the sensor step: vignetting, colour matrix and response fitted on "
                        "both files' design block means (for a camera; docs/appearance.md)")
    t.add_argument("--normals", action="store_true",
                   help="last the normal step: light moved over the normal's azimuth within each θ "
                        "bin (sharper or blurrier reflections); only for images lit by the "
                        "characterisation's environment (docs/appearance.md)")
    t.add_argument("--target", dest="reference", type=Path,
                   help="B's own image of the scene: score the result against it")
    t.set_defaults(run=run_transfer)

    e = verbs.add_parser("environment", help="estimate a lat-long environment map from an image's "
                                             "background (the paper's recipe)")
    e.add_argument("image", type=Path, help="linear image (.exr)")
    e.add_argument("--geometry", type=Path, required=True, help="its geometry map (.npz): the objects")
    e.add_argument("--out", type=Path, required=True, help="output map (.exr)")
    e.add_argument("--width", type=int, default=256, help="map width, pixels (default %(default)s)")
    e.set_defaults(run=run_environment)

    g = verbs.add_parser("geometry", help="geometry maps of a scene file's objects for each view "
                                          "of a capture folder (to transfer its renderings)")
    g.add_argument("scene", type=Path, help="scene file (TOML)")
    g.add_argument("capture", type=Path, help="capture folder with cameras.json")
    g.add_argument("--class", dest="classes", action="append", required=True, metavar="OBJECT=CLASS",
                   help="material class of an object (e.g. sphere=glass); repeatable; objects not "
                        "named are background")
    g.add_argument("--out", type=Path, required=True, help="folder for VIEW.npz")
    g.set_defaults(run=run_geometry)


def _options(pairs: list[str]) -> dict:
    from abs.errors import InputError

    out = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise InputError(None, "--option", f"expected KEY=VALUE, got {pair!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def _check(args) -> None:
    from abs.errors import InputError

    if args.size < 8:
        raise InputError(None, "--size", f"must be at least 8, got {args.size}")
    if args.spp < 1:
        raise InputError(None, "--spp", f"must be at least 1, got {args.spp}")
    if args.out.exists() and not args.out.is_dir():
        raise InputError(args.out, "--out", "exists and is not a folder")


def _scene_writer(out: Path):
    from abs.appearance.files import write_geometry
    from abs.io.images import write_exr, write_png

    def write(spec, image, geometry):
        folder = out / "scenes" / spec.name
        folder.mkdir(parents=True, exist_ok=True)
        write_exr(folder / "image.exr", image)
        write_png(folder / "image.png", image)
        write_geometry(folder / "geometry.npz", geometry)
        (folder / "scene.json").write_text(json.dumps(spec.to_json(), indent=2) + "\n", encoding="utf-8")
        print(f"  {spec.name}", flush=True)

    return write


def _subset(value: str | None, known, field: str):
    from abs.errors import InputError

    if value is None:
        return None
    names = tuple(v.strip() for v in value.split(",") if v.strip())
    for name in names:
        if name not in known:
            raise InputError(None, field, f"unknown {name!r}; expected some of {sorted(known)}")
    return names


def run_characterise(args) -> int:
    import numpy as np

    from abs.appearance import characterise, characterisation_design, renderer, write_characterisation
    from abs.appearance.design import MATERIAL_CLASSES, WALL_COLOURS
    from abs.appearance.environment import load_environment
    from abs.errors import InputError

    _check(args)
    if not 1 <= args.samples <= 2:
        raise InputError(None, "--samples", f"expected 1 or 2 (the third is held out), got {args.samples}")
    if not 1 <= args.bins <= 90:
        raise InputError(None, "--bins", f"expected 1 to 90, got {args.bins}")
    scenes = characterisation_design(args.samples, _subset(args.classes, MATERIAL_CLASSES, "--classes"),
                                     _subset(args.walls, WALL_COLOURS, "--walls"))
    r = renderer(args.renderer, _options(args.option))
    env, env_name = load_environment(args.environment)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"abs appearance characterise: {r.name}, {len(scenes)} scenes", flush=True)
    c = characterise(r, scenes, env, size=args.size, spp=args.spp, seed=args.seed, n_bins=args.bins,
                     on_image=_scene_writer(args.out), settings={"environment": env_name})
    write_characterisation(args.out / "characterisation.npz", c)
    centres = np.degrees(0.5 * (c.theta_edges[1:] + c.theta_edges[:-1]))

    def table(a):
        return {cls: {f"{t:.0f}": None if not np.isfinite(v).all() else [round(float(x), 5) for x in v]
                      for t, v in zip(centres, a[i])} for i, cls in enumerate(c.classes)}

    summary = {"renderer": c.renderer, "options": c.options, "design": c.design,
               "settings": c.settings, "theta_bin_centres_deg": [round(float(t), 2) for t in centres],
               "alpha": table(c.alpha), "lambda": table(c.lam), "psi": table(c.psi),
               "pixels": {cls: c.counts[i].tolist() for i, cls in enumerate(c.classes)}}
    (args.out / "characterisation.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(f"abs appearance characterise: -> {args.out / 'characterisation.npz'}")
    return 0


def run_render(args) -> int:
    from abs.appearance import characterisation_design, heldout_design, render_design, renderer
    from abs.appearance.environment import load_environment

    _check(args)
    scenes = heldout_design() if args.design == "heldout" else characterisation_design()
    r = renderer(args.renderer, _options(args.option))
    env, _ = load_environment(args.environment)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"abs appearance render: {r.name}, {len(scenes)} {args.design} scenes", flush=True)
    render_design(r, scenes, env, args.size, args.spp, args.seed, _scene_writer(args.out))
    return 0


def _statistics(image, geometry, source, target, args):
    from abs.appearance import transfer
    from abs.appearance.transfer import normal_step, sensor_step

    sensor = sensor_step(source, target) if args.sensor else None
    out = transfer(image, geometry, source, target, args.colour_matrix, args.spread, args.shift,
                   sensor or False, normals=args.normals)
    # Which classes got the normal step, and the split test that decided it.
    report = normal_step(source, target, sensor)[1] if args.normals else None
    return out, {"sensor": sensor.to_json() if sensor else None, "normal_step": report}


def _sensor_only(image, geometry, source, target, args):
    from abs.appearance import transfer
    from abs.appearance.transfer import sensor_step

    sensor = sensor_step(source, target)
    return (transfer(image, geometry, source, target, sensor=sensor, theta=False),
            {"sensor": sensor.to_json(), "normal_step": None})


def _histogram(kind):
    def run(image, geometry, source, target, args):
        from abs.appearance.histogram import match_global, match_local

        out = {"global": match_global, "local": match_local}[kind](image, geometry, target)
        return out, {"sensor": None, "normal_step": None}
    return run


# --method: what makes the image look like the target's. Each returns the image and what its
# fitted steps were (for the summary JSON).
_METHODS = {"statistics": _statistics, "sensor": _sensor_only,
            "histogram-global": _histogram("global"), "histogram-local": _histogram("local")}


def run_transfer(args) -> int:
    from abs.appearance import read_characterisation, read_geometry
    from abs.appearance.score import object_scores
    from abs.errors import InputError
    from abs.io.images import read_image, write_exr, write_png

    if args.out.suffix.lower() != ".exr":
        raise InputError(args.out, "--out", "expected an .exr file name")
    image = read_image(args.image)
    geometry = read_geometry(args.geometry, image.shape[:2])
    source, target = read_characterisation(args.source), read_characterisation(args.target)
    if args.method != "statistics" and (args.normals or args.sensor or args.colour_matrix != "none"):
        raise InputError(None, "--method", f"--sensor, --normals and --colour-matrix are steps of "
                                           f"--method statistics, not of {args.method}")
    out, steps = _METHODS[args.method](image, geometry, source, target, args)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_exr(args.out, out)
    write_png(args.out.with_suffix(".png"), out)
    summary = {"image": str(args.image), "from": source.renderer, "to": target.renderer,
               "method": args.method, "colour_matrix": args.colour_matrix, "spread": args.spread,
               "shift": args.shift, "normals": args.normals, **steps}
    if args.reference is not None:
        reference = read_image(args.reference)
        if reference.shape != image.shape:
            raise InputError(args.reference, "--target", f"shape {reference.shape} differs from the image's")
        summary["before"] = object_scores(image, reference, geometry)
        summary["after"] = object_scores(out, reference, geometry)
        for b, a in zip(summary["before"], summary["after"]):
            print(f"  object {a['object']} ({a['class']}): ΔE00 {b['mean']:.2f} -> {a['mean']:.2f} "
                  f"(profile {b['profile']:.2f} -> {a['profile']:.2f})")
    args.out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(f"abs appearance transfer: {source.renderer} -> {target.renderer} -> {args.out}")
    return 0


def run_environment(args) -> int:
    from abs.appearance import read_geometry
    from abs.appearance.background import background_to_world, environment_from_background
    from abs.appearance.scenes import design_camera
    from abs.errors import InputError
    from abs.io.images import read_image, write_exr, write_png

    if args.width < 8 or args.width % 2:
        raise InputError(None, "--width", f"expected an even width of at least 8, got {args.width}")
    if args.out.suffix.lower() != ".exr":
        raise InputError(args.out, "--out", "expected an .exr file name")
    image = read_image(args.image)
    geometry = read_geometry(args.geometry, image.shape[:2])
    env = environment_from_background(image, geometry, args.width)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_exr(args.out, env)
    write_png(args.out.with_suffix(".png"), env)
    to_world = background_to_world(design_camera(image.shape[1]).R)
    args.out.with_suffix(".json").write_text(json.dumps(
        {"image": str(args.image), "frame": "camera looking along +z, +y up (docs/appearance.md)",
         "to_world_for_design_camera": to_world.tolist()}, indent=2) + "\n", encoding="utf-8")
    print(f"abs appearance environment: -> {args.out}")
    return 0


def run_geometry(args) -> int:
    from abs.appearance.design import MATERIAL_CLASSES
    from abs.appearance.files import write_geometry
    from abs.appearance.mesh_geometry import mesh_scene_geometry
    from abs.errors import InputError
    from abs.io.capture import load_capture
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    classes = {}
    for pair in args.classes:
        name, sep, cls = pair.partition("=")
        if not sep or not name:
            raise InputError(None, "--class", f"expected OBJECT=CLASS, got {pair!r}")
        if cls not in MATERIAL_CLASSES:
            raise InputError(None, "--class", f"unknown class {cls!r}; expected one of {list(MATERIAL_CLASSES)}")
        classes[name] = cls
    compiled = compile_scene(load_scene(args.scene))
    capture = load_capture(args.capture)
    if args.out.exists() and not args.out.is_dir():
        raise InputError(args.out, "--out", "exists and is not a folder")
    args.out.mkdir(parents=True, exist_ok=True)
    for view in capture.views:
        geometry = mesh_scene_geometry(compiled, Camera.from_view(view), classes)
        write_geometry(args.out / f"{view.name}.npz", geometry)
        print(f"  {view.name}: {int((geometry.ids > 0).sum())} object pixels", flush=True)
    print(f"abs appearance geometry: {len(capture.views)} views -> {args.out}")
    return 0
