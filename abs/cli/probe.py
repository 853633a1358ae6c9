"""``abs probe unwrap``: environment map (lat-long EXR) from calibrated photographs of a chrome ball."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    from abs.probe.unwrap import MODELS

    p = sub.add_parser("probe", help="light probes: unwrap mirror-ball photographs")
    commands = p.add_subparsers(dest="probe_command", required=True)
    un = commands.add_parser("unwrap", help="capture folder of a chrome ball -> lat-long EXR in the "
                                            "scene file's environment convention")
    un.add_argument("capture", type=Path, help="capture folder (cameras.json with K, R, t, images)")
    un.add_argument("--center", help="ball centre in world metres, 'x,y,z' (with --radius)")
    un.add_argument("--radius", type=float, help="ball radius, metres (with --center)")
    un.add_argument("--outlines", type=Path, help='instead of --center/--radius: JSON {"VIEW": '
                    '[[u, v], ...]} of pixels on the ball\'s outline in two or more views; the ball '
                    'is triangulated from them')
    un.add_argument("--width", type=int, default=512, help="map width (height = width/2; default %(default)s)")
    un.add_argument("--model", choices=MODELS, default="pinhole", help="camera model (default %(default)s)")
    un.add_argument("--fresnel", type=Path, help="refractiveindex.info YAML of the ball's metal (e.g. "
                                                  "chromium): divide by its Fresnel reflectance")
    un.add_argument("--views", help="comma-separated view names (default: all)")
    un.add_argument("--out", type=Path, required=True, help="environment map to write (.exr)")
    un.add_argument("--weight-out", type=Path, help="also write the merged weight (0 = unrecovered) as EXR")
    un.set_defaults(run=run_unwrap)


def run_unwrap(args) -> int:
    import numpy as np

    from abs.errors import InputError
    from abs.io.capture import load_capture
    from abs.io.images import write_exr
    from abs.probe import ProbeView, latlong_directions, merge_views, unwrap_view

    capture = load_capture(args.capture)
    if args.outlines:
        centre, radius = _triangulate(args.outlines, capture)
        print(f"ball from its outlines: centre {np.round(centre, 5).tolist()} m, radius {radius:.5f} m")
    else:
        if args.center is None or args.radius is None:
            raise InputError(None, "--center", "give --center and --radius, or --outlines")
        try:
            centre = np.array([float(x) for x in args.center.split(",")])
            assert centre.shape == (3,)
        except (ValueError, AssertionError) as exc:
            raise InputError(None, "--center", "expected 3 numbers 'x,y,z' in metres") from exc
        if not args.radius > 0:
            raise InputError(None, "--radius", "must be positive (metres)")
        radius = args.radius
    eta = k = None
    if args.fresnel:
        from abs.colour import optical_constants_rgb, read_refractiveindex_yaml

        values = optical_constants_rgb(read_refractiveindex_yaml(args.fresnel))
        eta, k = values["ior_rgb"], values["k_rgb"]
    names = [n.strip() for n in args.views.split(",")] if args.views else list(capture.names)
    dirs = latlong_directions(args.width, max(args.width // 2, 2))
    results = []
    for name in names:
        if name not in capture.names:
            raise InputError(None, "--views", f"no view named {name!r} in {capture.source}; views "
                                              f"are {', '.join(capture.names)}")
        view = capture.view(name)
        probe = ProbeView(str(view.image), view.read_image(), view.K, view.R, view.t)
        results.append(unwrap_view(probe, centre, radius, dirs, model=args.model,
                                   eta_rgb=eta, k_rgb=k))
    radiance, weight = merge_views(results)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_exr(args.out, radiance)
    if args.weight_out:
        write_exr(args.weight_out, np.repeat(weight[..., None], 3, axis=-1))
    print(f"wrote {args.out}: {len(results)} views, {100 * np.mean(weight > 0):.1f} % of the "
          f"texels recovered ({args.model}{', Fresnel-divided' if eta is not None else ''})")
    return 0


def _triangulate(path: Path, capture):
    import numpy as np

    from abs.errors import InputError, read_json
    from abs.probe import triangulate_ball

    doc = read_json(path, what="outline file")
    if len(doc) < 2:
        raise InputError(path, "", "expected {view name: [[u, v], ...]} for at least two views")
    cameras, outlines = [], []
    for name, points in doc.items():
        if name not in capture.names:
            raise InputError(path, name, f"no such view in {capture.source}")
        try:
            pts = np.array(points, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(path, name, "expected a list of [u, v] pixel pairs") from exc
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise InputError(path, name, f"expected at least 3 [u, v] pairs, got shape {pts.shape}")
        view = capture.view(name)
        cameras.append((view.K, view.R, view.t))
        outlines.append(pts)
    return triangulate_ball(cameras, outlines)
