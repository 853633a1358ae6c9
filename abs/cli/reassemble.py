"""``abs reassemble mesh|markers|place|deform|label|pipeline``: put glass scanned in a CT back into
its scene.

``mesh`` turns a CT volume into the cleaned glass mesh and the marker spheres (``glass.ply`` in
metres, ``markers.json`` in mm); ``markers`` finds the markers in two calibrated photographs and
triangulates them (``markers_world.json``, metres, world frame); ``place`` pairs markers measured
in the scene with the CT markers, solves the rigid transform and writes the object's
``to_world`` into a scene file; ``deform`` pushes a soft object (the tablecloth) below a hard one
where it would poke through; ``label`` gives each face of a background mesh a material label
from segmented photographs; ``pipeline`` runs mesh, markers, place and deform in that order,
each as its own command would.
See docs/reassembly.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from abs.errors import InputError, read_json


def add_parser(sub) -> None:
    p = sub.add_parser("reassemble", help="CT volume to meshes, marker placement into a scene, "
                                          "soft deformation, background labelling")
    steps = p.add_subparsers(dest="step", required=True)

    q = steps.add_parser("mesh", help="CT volume to the glass mesh and the marker spheres")
    q.add_argument("volume", type=Path, help="JSON header of a raw volume, or a folder of 16-bit "
                                             "TIFF/PNG slices (then --voxel-size)")
    q.add_argument("--out", type=Path, required=True, help="folder for glass.ply and markers.json")
    q.add_argument("--voxel-size", type=float, help="voxel size of a slice folder, mm")
    q.add_argument("--glass-threshold", type=float, help="grey value (default: from the histogram)")
    q.add_argument("--marker-threshold", type=float, help="grey value (default: from the histogram)")
    q.add_argument("--marker-radius", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="accepted marker radii, mm (default: max(0.5, 1.5 voxels) to 5)")
    q.add_argument("--epsilon", type=float, default=0.5,
                   help="carve the glass within (1 + epsilon) r of each marker (seed: 0.5 to 0.75)")
    q.add_argument("--keep", type=float, default=0.01, help="fraction of faces the first decimation keeps")
    q.add_argument("--min-faces", type=int, default=2000, help="the decimation keeps at least this many")
    q.add_argument("--rounds", type=int, default=4, help="sqrt(3)-subdivision + decimation rounds")
    q.set_defaults(run=_run_mesh)

    q = steps.add_parser("markers", help="markers in two calibrated photographs, triangulated "
                                         "(world frame, metres)")
    q.add_argument("left", type=Path, help="left photograph")
    q.add_argument("right", type=Path, help="right photograph")
    _marker_options(q)
    q.add_argument("--out", type=Path, required=True, help="markers_world.json to write")
    q.set_defaults(run=_run_markers)

    q = steps.add_parser("pipeline", help="volume + stereo photographs -> object placed in a scene "
                                          "(mesh, markers, place, deform)")
    q.add_argument("volume", type=Path, help="JSON header of a raw volume, or a folder of slices")
    q.add_argument("--voxel-size", type=float, help="voxel size of a slice folder, mm")
    q.add_argument("--left", type=Path, required=True, help="left photograph")
    q.add_argument("--right", type=Path, required=True, help="right photograph")
    _marker_options(q, glass=False)
    q.add_argument("--scene", type=Path, required=True, help="scene file to place the object in")
    q.add_argument("--object", required=True, help="object name (existing or new)")
    q.add_argument("--material", help="material of a new object (or to change an existing one's)")
    q.add_argument("--soft", help="soft object to push below the placed one (e.g. cloth); "
                                  "default: no deformation")
    q.add_argument("--max-edge", type=float, default=2.0,
                   help="refine the soft mesh to edges of at most this, mm")
    q.add_argument("--rounds", type=int, default=4, help="sqrt(3)-subdivision + decimation rounds")
    q.add_argument("--drop-suspect", action="store_true",
                   help="leave out markers the others' placement puts far off (see place)")
    q.add_argument("--work", type=Path, help="folder for the intermediate files "
                                             "(default: <out folder>/reassembly)")
    q.add_argument("--out", type=Path, required=True, help="scene file to write")
    q.set_defaults(run=_run_pipeline)

    q = steps.add_parser("place", help="pair measured markers with the CT markers, write to_world")
    q.add_argument("markers", type=Path, help="markers.json (or its folder) from `reassemble mesh`")
    q.add_argument("--measured", type=Path, required=True,
                   help='JSON with the measured marker positions: {"points_m": [[x, y, z], ...]} '
                        "(world frame, metres)")
    q.add_argument("--scene", type=Path, required=True, help="scene file to place the object in")
    q.add_argument("--object", required=True, help="object name (existing or new)")
    q.add_argument("--material", help="material of a new object (or to change an existing one's)")
    q.add_argument("--mesh", type=Path, help="object mesh in metres (default: glass.ply beside markers.json)")
    q.add_argument("--pairs", nargs="+", metavar="M:C",
                   help="pairing by hand: measured index : CT index (0-based), at least 3")
    q.add_argument("--tol", type=float, default=1.5, help="pairing tolerance, mm")
    q.add_argument("--allow-unpaired", action="store_true",
                   help="place even if some measured markers match no CT marker")
    q.add_argument("--drop-suspect", action="store_true",
                   help="leave out the markers that the others' placement puts far off (a marker "
                        "merged with its image through the glass); they are reported either way")
    q.add_argument("--out", type=Path, required=True, help="scene file to write")
    q.set_defaults(run=_run_place)

    q = steps.add_parser("label", help="one material label per face of a background mesh, from "
                                       "the photographs of a capture folder")
    q.add_argument("mesh", type=Path, nargs="?", help="background mesh (PLY/OBJ), metres, world "
                                                      "frame (or --scene and --object)")
    q.add_argument("--cameras", type=Path, required=True,
                   help="cameras.json (or its capture folder): every view's photograph is used, "
                        "with its mask")
    q.add_argument("--labels", type=int, required=True,
                   help="number of materials in the photographs (the surroundings count too)")
    q.add_argument("--images", nargs="+", metavar="VIEW=PATH",
                   help="photographs to use instead of those cameras.json names")
    q.add_argument("--scene", type=Path, help="scene holding the background object")
    q.add_argument("--object", help="the background object in --scene")
    q.add_argument("--materials", nargs="+", metavar="NAME",
                   help="material of label 1, 2, ... (labels are numbered darkest first); with "
                        "--scene, also writes OUT/scene.toml with the object split by label")
    q.add_argument("--sigma-px", type=float, default=1.0, help="blur before the edges, pixels")
    q.add_argument("--min-area-px", type=int, default=20,
                   help="smallest region between edges that seeds the watershed, pixels")
    q.add_argument("--max-faces", type=int, default=2_000_000,
                   help="refuse to subdivide beyond this many faces")
    q.add_argument("--out", type=Path, required=True,
                   help="folder for label_<k>.ply, labels.json, scene_snippet.toml")
    q.set_defaults(run=_run_label)

    q = steps.add_parser("deform", help="push a soft object below a hard one where they intersect")
    q.add_argument("--scene", type=Path, required=True)
    q.add_argument("--hard", required=True, help="the hard object (the glass)")
    q.add_argument("--soft", required=True, help="the soft object (the tablecloth)")
    q.add_argument("--fraction", type=float, default=0.07,
                   help="contact distance, fraction of the hard bounding-box diagonal")
    q.add_argument("--max-edge", type=float, default=2.0,
                   help="refine the soft mesh to edges of at most this, mm")
    q.add_argument("--margin", type=float, default=0.0, help="clearance below the hard object, mm")
    q.add_argument("--out", type=Path, required=True,
                   help="scene file to write (the deformed mesh goes beside it)")
    q.set_defaults(run=_run_deform)


def _marker_options(q, glass: bool = True) -> None:
    q.add_argument("--cameras", type=Path, required=True, help="cameras.json (or its capture folder)")
    q.add_argument("--left-camera", required=True, help="view name of the left photograph's camera")
    q.add_argument("--right-camera", required=True, help="view name of the right photograph's camera")
    q.add_argument("--tol-px", type=float, default=1.5,
                   help="largest Sampson distance of a stereo match, px")
    q.add_argument("--radius-px", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="marker radii in the photographs, px (default: 4 to a quarter of the image)")
    q.add_argument("--merge-mm", type=float, default=1.0,
                   help="triangulated points closer than this are one marker, mm")
    q.add_argument("--outlier-mm", type=float, default=0.5,
                   help="drop a point further than this from its marker's median, mm")
    if glass:
        q.add_argument("--glass-scene", type=Path,
                       help="scene file holding the glass object at a guessed placement: markers a "
                            "camera sees through it are left out")
        q.add_argument("--glass-object", help="the glass object's name in --glass-scene")
        q.add_argument("--glass-margin-mm", type=float, default=2.0,
                       help="a ray crossing the glass closer than this to the marker is not counted, mm")


def _run_mesh(args) -> int:
    from abs.reassembly.meshing import MeshingSettings, mesh_volume, write_meshing
    from abs.reassembly.volume import read_volume

    volume = read_volume(args.volume, args.voxel_size)
    settings = MeshingSettings(glass_threshold=args.glass_threshold,
                               marker_threshold=args.marker_threshold,
                               marker_radius_mm=tuple(args.marker_radius) if args.marker_radius else None,
                               epsilon=args.epsilon, keep=args.keep, min_faces=args.min_faces,
                               rounds=args.rounds)
    result = mesh_volume(volume, settings)
    path = write_meshing(result, args.out)
    print(f"{len(result.markers)} markers (radius mm: "
          f"{', '.join(f'{r:.3f}' for r in result.radii_mm)}); glass mesh "
          f"{len(result.glass.faces)} faces, watertight {result.glass.is_watertight}; "
          f"{sum(result.seconds.values()):.1f} s -> {path}")
    return 0


def _read_points(path: Path) -> np.ndarray:
    data = read_json(path, what="measured marker file", expect=(dict, list))
    points = data.get("points_m") if isinstance(data, dict) else data
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros((0,))
    if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr)):
        raise InputError(path, "points_m", "expected a list of [x, y, z] positions in metres")
    return arr


def _parse_pairs(items: list[str] | None):
    if not items:
        return None
    pairs = []
    for item in items:
        try:
            m, c = item.split(":")
            pairs.append((int(m), int(c)))
        except ValueError:
            raise InputError(None, "--pairs", f"expected MEASURED:CT indices, got {item!r}") from None
    return pairs


def _run_place(args) -> int:
    from abs.reassembly.meshing import read_markers
    from abs.reassembly.placement import place
    from abs.reassembly.scene_pose import place_object_in_scene
    from abs.reassembly.suspect_markers import suspect_pairs

    centres_mm, _ = read_markers(args.markers)
    measured = _read_points(args.measured)
    ct = centres_mm * 1e-3
    result = place(measured, ct, _parse_pairs(args.pairs), tol=args.tol * 1e-3,
                   allow_unpaired=args.allow_unpaired)
    suspect, loo = suspect_pairs(measured, ct, result.pairs)
    for (m, c), r in zip(result.pairs[suspect], loo[suspect]):
        print(f"suspect: measured {m} <-> CT {c} is {r:.3f} mm off when the other markers place the "
              f"object (their median {np.nanmedian(np.delete(loo, np.flatnonzero(suspect))):.3f} mm): a "
              "marker merged with its own image seen through the glass, or a false detection"
              + ("; left out" if args.drop_suspect else "; kept (--drop-suspect leaves it out)"))
    flagged, pairs_all = result.pairs[suspect], result.pairs
    if args.drop_suspect and suspect.any():
        if np.count_nonzero(~suspect) < 3:
            raise InputError(args.measured, "points_m", "fewer than 3 matched markers would be left "
                                                        "without the suspect ones")
        result = place(measured, ct, result.pairs[~suspect], tol=args.tol * 1e-3)
    folder = args.markers if args.markers.is_dir() else args.markers.parent
    mesh = args.mesh or folder / "glass.ply"
    out = place_object_in_scene(args.scene, args.out, args.object, result.to_world, mesh, args.material)
    report = {"pairs": result.pairs.tolist(), "residuals_mm": result.residuals_mm.tolist(),
              "mean_distance_mm": result.mean_distance_mm, "rms_mm": result.rms_mm,
              "to_world": result.to_world.tolist(), "scene": str(out),
              "leave_one_out_mm": [[int(m), int(c), float(r)] for (m, c), r in zip(pairs_all, loo)],
              "suspect": flagged.tolist(), "suspect_left_out": bool(args.drop_suspect and len(flagged))}
    placement = out.with_name(out.stem + "_placement.json")
    placement.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    for (m, c), r in zip(result.pairs, result.residuals_mm):
        print(f"measured {m} <-> CT {c}: {r:.3f} mm")
    print(f"mean marker distance {result.mean_distance_mm:.3f} mm over {len(result.pairs)} markers "
          f"-> {out} ({placement.name})")
    return 0


def _world_mesh(obj):
    import trimesh

    mesh = trimesh.load(obj.mesh, force="mesh", process=False)
    for field in ("pose", "placement"):
        if np.any(np.asarray(getattr(obj, field)) != 0):
            raise InputError(None, f"objects.{obj.name}.{field}",
                             f"deform and the glass check use to_world only; fold the {field} into "
                             f"to_world first")
    mesh.apply_transform(np.asarray(obj.to_world, dtype=np.float64))
    return mesh


def _run_deform(args) -> int:
    from abs.reassembly.deform import deform_soft, refine
    from abs.reassembly.scene_pose import place_object_in_scene
    from abs.scene import load_scene

    scene = load_scene(args.scene)
    try:
        hard, soft = _world_mesh(scene.object(args.hard)), _world_mesh(scene.object(args.soft))
    except KeyError as exc:
        raise InputError(args.scene, "objects", f"no object {exc.args[0]!r} in the scene") from None
    soft = refine(soft, args.max_edge * 1e-3)
    result = deform_soft(soft, hard, fraction=args.fraction, margin=args.margin * 1e-3)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    mesh_path = args.out.parent / f"{args.soft}_deformed.ply"
    result.mesh.export(mesh_path)
    out = place_object_in_scene(args.scene, args.out, args.soft, np.eye(4), mesh_path)
    print(f"{len(result.moved)} of {len(soft.vertices)} soft vertices pushed, at most "
          f"{result.max_push * 1e3:.3f} mm -> {out}")
    return 0


def _view(capture, name: str):
    try:
        return capture.view(name)
    except KeyError:
        raise InputError(capture.source, "views", f"no view named {name!r}; views are "
                                                  f"{', '.join(capture.names)}") from None


def _calibrated_photo(image: Path, capture, view) -> np.ndarray:
    """The photograph ``image`` of ``view``, refused unless it has the calibrated size."""
    from abs.io.images import read_image

    if not image.is_file():
        raise InputError(image, "", "photograph not found")
    pixels = read_image(image)
    if pixels.shape[:2] != (view.height, view.width):
        raise InputError(image, "", f"is {pixels.shape[1]}x{pixels.shape[0]} pixels, but camera "
                                    f"{view.name!r} of {capture.source} was calibrated at "
                                    f"{view.width}x{view.height}")
    return pixels


def _marker_image(image: Path, capture, name: str, args):
    from abs.reassembly.circles import detect_circles
    from abs.reassembly.stereo_markers import MarkerImage

    view = _view(capture, name)
    pixels = _calibrated_photo(image, capture, view)
    radius = tuple(args.radius_px) if args.radius_px else (4.0, None)
    return MarkerImage(name, str(image), view.K, view.R, view.t, detect_circles(pixels, radius_px=radius))


def _run_markers(args) -> int:
    from abs.io.capture import load_capture
    from abs.reassembly.stereo_markers import locate_markers
    from abs.scene import load_scene

    capture = load_capture(args.cameras)
    images = [_marker_image(args.left, capture, args.left_camera, args),
              _marker_image(args.right, capture, args.right_camera, args)]
    glass = None
    if args.glass_scene is not None or args.glass_object is not None:
        if args.glass_scene is None or args.glass_object is None:
            raise InputError(None, "--glass-scene", "give both --glass-scene and --glass-object")
        try:
            glass = _world_mesh(load_scene(args.glass_scene).object(args.glass_object))
        except KeyError:
            raise InputError(args.glass_scene, "objects", f"no object {args.glass_object!r}") from None
    result = locate_markers(images, tol_px=args.tol_px, merge_m=args.merge_mm * 1e-3,
                            outlier_m=args.outlier_mm * 1e-3, glass=glass,
                            glass_margin_m=args.glass_margin_mm * 1e-3)
    report = {"points_m": result.points_m.tolist(),
              "reprojection_error_px": result.error_px.tolist(),
              "sources": result.sources, "ambiguous": result.ambiguous,
              "through_glass": result.through_glass, "dropped": result.dropped,
              "images": {m.name: m.image for m in images},
              "detections_px": {m.name: np.column_stack([m.circles.centres_px, m.circles.radii_px]).tolist()
                                for m in images}}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    for amb in result.ambiguous:
        side, other = ("left", "right") if isinstance(amb["left"], int) else ("right", "left")
        print(f"ambiguous: {side} detection {amb[side]} has {len(amb[other])} {other} candidates "
              f"{amb[other]} on its epipolar line ({' / '.join(amb['cameras'])}); left out")
    for g in result.through_glass:
        print(f"seen through glass by {', '.join(g['seen_through_glass_by'])}: marker at "
              f"{np.round(np.array(g['point_m']) * 1e3, 2).tolist()} mm; left out")
    print(f"{len(result.points_m)} markers (detections: "
          f"{', '.join(f'{m.name} {len(m.circles)}' for m in images)}; reprojection error at most "
          f"{result.error_px.max():.3f} px) -> {args.out}")
    return 0


def _run_label(args) -> int:
    import trimesh

    from abs.io.capture import load_capture
    from abs.reassembly.label_files import check_label_scene, replace_with_labels, write_labelling
    from abs.reassembly.labelling import LabelCamera, label_mesh
    from abs.reassembly.segmentation import label_regions, segment_photograph
    from abs.scene import load_scene

    capture = load_capture(args.cameras)
    if (args.mesh is None) == (args.scene is None or args.object is None):
        raise InputError(None, "mesh", "give either a mesh file or --scene and --object (the "
                                       "background object of a scene)")
    if args.materials and len(args.materials) != args.labels:
        raise InputError(None, "--materials", f"{len(args.materials)} names for {args.labels} labels")
    if args.scene is not None and args.materials:
        check_label_scene(args.scene, args.object, args.materials)  # before the work, not after
    if args.mesh is not None:
        if not args.mesh.is_file():
            raise InputError(args.mesh, "", "mesh not found")
        mesh = trimesh.load(args.mesh, force="mesh", process=False)
    else:
        try:
            mesh = _world_mesh(load_scene(args.scene).object(args.object))
        except KeyError:
            raise InputError(args.scene, "objects", f"no object {args.object!r}") from None
    images = {}
    for item in args.images or []:
        name, sep, path = item.partition("=")
        if not sep:
            raise InputError(None, "--images", f"expected VIEW=PATH, got {item!r}")
        images[_view(capture, name).name] = Path(path)
    segmentations, views = [], []
    for i, view in enumerate(capture.views):
        path = images.get(view.name, view.image)
        pixels = _calibrated_photo(path, capture, view)
        segmentations.append(segment_photograph(pixels, view.read_mask(), sigma_px=args.sigma_px,
                                                min_area_px=args.min_area_px, source=path))
        views.append((i, view))
    label_images, colours = label_regions(segmentations, args.labels)
    cameras = [LabelCamera(v.name, v.K, v.R, v.t, lab, str(capture.source), f"views[{i}]")
               for (i, v), lab in zip(views, label_images)]
    result = label_mesh(mesh, cameras, args.labels, max_faces=args.max_faces)
    report = write_labelling(result, colours, args.out, args.materials, name=args.object or "background")
    counts = np.bincount(result.face_labels, minlength=args.labels + 1)[1:]
    print(f"{len(result.face_labels)} faces after {result.rounds} subdivision rounds (longest edge "
          f"{result.worst_edge_px:.2f} pixel footprints); per label: "
          f"{', '.join(f'{k}: {c}' for k, c in enumerate(counts, start=1))}; "
          f"{int(np.count_nonzero(~result.voted))} by nearest neighbour -> {report}")
    if args.scene is not None and args.materials:
        out = replace_with_labels(args.scene, args.out / "scene.toml", args.object or "background",
                                  args.out, args.materials)
        print(f"scene with {args.object} split by label -> {out}")
    return 0


def _run_step(argv: list[str]) -> int:
    """Run ``abs reassemble <argv>`` with the step's own parser, defaults and checks: the
    pipeline is the steps, not a copy of them."""
    parser = argparse.ArgumentParser(prog="abs")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["reassemble", *argv])
    return args.run(args)


def _run_pipeline(args) -> int:
    work = args.work or args.out.parent / "reassembly"
    ct = work / "ct"
    measured = work / "markers_world.json"
    mesh = [str(args.volume), "--out", str(ct), "--rounds", str(args.rounds)]
    if args.voxel_size is not None:
        mesh += ["--voxel-size", str(args.voxel_size)]
    stereo = [str(args.left), str(args.right), "--cameras", str(args.cameras),
              "--left-camera", args.left_camera, "--right-camera", args.right_camera,
              "--tol-px", str(args.tol_px), "--merge-mm", str(args.merge_mm),
              "--outlier-mm", str(args.outlier_mm)]
    if args.radius_px:
        stereo += ["--radius-px", *map(str, args.radius_px)]
    place = [str(ct), "--measured", str(measured), "--scene", str(args.scene), "--object",
             args.object, "--out", str(args.out)] + (["--material", args.material] if args.material else [])
    print("== mesh")
    _run_step(["mesh", *mesh])
    print("== markers")
    _run_step(["markers", *stereo, "--out", str(measured)])
    # Markers a camera sees through the glass are displaced by refraction, and only the placed
    # glass tells which they are: a first placement (unpaired markers allowed, as those may be
    # among them), the markers found again with that glass, the final placement without them.
    print("== place (first guess)")
    _run_step(["place", *place, "--allow-unpaired"])
    print("== markers, leaving out those seen through the placed glass")
    checked = work / "markers_world_checked.json"
    _run_step(["markers", *stereo, "--glass-scene", str(args.out), "--glass-object", args.object,
               "--out", str(checked)])
    print("== place")
    place[place.index("--measured") + 1] = str(checked)
    _run_step(["place", *place] + (["--drop-suspect"] if args.drop_suspect else []))
    if args.soft:
        print("== deform")
        _run_step(["deform", "--scene", str(args.out), "--hard", args.object, "--soft", args.soft,
                   "--max-edge", str(args.max_edge), "--out", str(args.out)])
    print(f"placed {args.object} -> {args.out} (intermediate files in {work})")
    return 0
