"""``abs reassemble mesh|place|deform``: put glass scanned in a CT back into its scene.

``mesh`` turns a CT volume into the cleaned glass mesh and the marker spheres (``glass.ply`` in
metres, ``markers.json`` in mm); ``place`` pairs markers measured in the scene (metres, world
frame) with the CT markers, solves the rigid transform and writes the object's ``to_world`` into
a scene file; ``deform`` pushes a soft object (the tablecloth) below a hard one where it would
poke through. See docs/reassembly.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from abs.errors import InputError, read_json


def add_parser(sub) -> None:
    p = sub.add_parser("reassemble", help="CT volume to meshes, marker placement into a scene, "
                                          "soft deformation")
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
    q.add_argument("--out", type=Path, required=True, help="scene file to write")
    q.set_defaults(run=_run_place)

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

    centres_mm, _ = read_markers(args.markers)
    measured = _read_points(args.measured)
    result = place(measured, centres_mm * 1e-3, _parse_pairs(args.pairs), tol=args.tol * 1e-3,
                   allow_unpaired=args.allow_unpaired)
    folder = args.markers if args.markers.is_dir() else args.markers.parent
    mesh = args.mesh or folder / "glass.ply"
    out = place_object_in_scene(args.scene, args.out, args.object, result.to_world, mesh, args.material)
    report = {"pairs": result.pairs.tolist(), "residuals_mm": result.residuals_mm.tolist(),
              "mean_distance_mm": result.mean_distance_mm, "rms_mm": result.rms_mm,
              "to_world": result.to_world.tolist(), "scene": str(out)}
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
    if np.any(np.asarray(obj.pose) != 0):
        raise InputError(None, f"objects.{obj.name}.pose",
                         "deform uses to_world only; fold the pose into to_world first")
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
