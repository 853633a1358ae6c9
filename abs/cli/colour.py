"""``abs colour calibrate|apply``: colour-chart calibration and its application to images.

``calibrate`` takes the linear camera RGB of the 24 ColorChecker patches (from a JSON table, or
from a photograph with corner points or a label mask, :mod:`abs.colour.chart`), fits the
root-polynomial correction, refines it by ΔE00 and writes the correction file
(:mod:`abs.colour.correction_file`). ``apply`` maps linear camera EXR images through it.
"""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    from abs.colour.correction import OUTPUT_SPACES

    p = sub.add_parser("colour", help="colour-chart calibration: camera RGB -> XYZ -> CIE RGB")
    commands = p.add_subparsers(dest="colour_command", required=True)
    cal = commands.add_parser("calibrate", help="fit a correction to the 24 patches of a ColorChecker")
    src = cal.add_mutually_exclusive_group(required=True)
    src.add_argument("--patches", type=Path, help='JSON {"rgb": 24 x [R, G, B]} of linear camera '
                     'RGB (optionally with "xyz" and "white_xyz": your own measured references)')
    src.add_argument("--image", type=Path, help="linear photograph of the chart (EXR/HDR)")
    cal.add_argument("--corners", help="with --image: u,v pixel centres of patches 1, 6, 24, 19 "
                                       "as 'u1,v1,u6,v6,u24,v24,u19,v19'")
    cal.add_argument("--labels", type=Path, help="with --image: label mask (pixel value = patch 1..24)")
    cal.add_argument("--degree", type=int, choices=(1, 2), default=2,
                     help="1: linear 3x3, 2: root-polynomial (default)")
    cal.add_argument("--no-refine", action="store_true", help="skip the ΔE00 (BFGS) refinement")
    cal.add_argument("--space", choices=OUTPUT_SPACES, default="CIE RGB",
                     help="output colour space (default %(default)s)")
    cal.add_argument("--out", type=Path, required=True, help="correction file to write (.json)")
    cal.set_defaults(run=run_calibrate)

    app = commands.add_parser("apply", help="map linear camera images through a correction")
    app.add_argument("correction", type=Path, help="file written by `abs colour calibrate`")
    app.add_argument("images", type=Path, nargs="+", help="linear camera images (EXR/HDR)")
    app.add_argument("--out", type=Path, required=True, help="folder for the corrected EXR files")
    app.set_defaults(run=run_apply)


def _patches_file(path: Path):
    import numpy as np

    from abs.colour.chart import check_patches
    from abs.errors import InputError, read_json

    doc = read_json(path, what="patch file")
    if "rgb" not in doc:
        raise InputError(path, "rgb", "missing: expected 24 rows [R, G, B] of linear camera RGB")
    try:
        rgb = np.array(doc["rgb"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(path, "rgb", "not a table of numbers (every patch needs 3 "
                                      "numbers)") from exc
    rgb = check_patches(rgb, path, "rgb")
    xyz = white = None
    if "xyz" in doc:
        xyz = check_patches(np.array(doc["xyz"], dtype=np.float64), path, "xyz")
        if "white_xyz" not in doc:
            raise InputError(path, "white_xyz", "required with your own xyz (the reference white)")
        white = np.array(doc["white_xyz"], dtype=np.float64)
        if white.shape != (3,) or not np.all(white > 0):
            raise InputError(path, "white_xyz", "expected 3 positive numbers")
    return rgb, xyz, white


def run_calibrate(args) -> int:
    import numpy as np

    from abs.colour.chart import (REFERENCE_CHART, check_patches, patch_rgb_from_corners,
                                  patch_rgb_from_labels, reference_white_xyz, reference_xyz)
    from abs.colour.correction import calibrate
    from abs.colour.correction_file import write_correction
    from abs.errors import InputError
    from abs.io.images import read_image

    xyz = white = None
    if args.patches:
        rgb, xyz, white = _patches_file(args.patches)
        inputs = {"patches": str(args.patches)}
    else:
        image = read_image(args.image)
        if args.corners:
            try:
                corners = np.array([float(x) for x in args.corners.split(",")]).reshape(4, 2)
            except ValueError as exc:
                raise InputError(None, "--corners", "expected 8 numbers u1,v1,u6,v6,u24,v24,u19,v19") from exc
            rgb = check_patches(patch_rgb_from_corners(image, corners), args.image, "--corners")
            inputs = {"image": str(args.image), "corners": corners.tolist()}
        elif args.labels:
            labels = _read_labels(args.labels, image.shape)
            rgb = check_patches(patch_rgb_from_labels(image, labels), args.labels, "labels")
            inputs = {"image": str(args.image), "labels": str(args.labels)}
        else:
            raise InputError(None, "--image", "needs --corners or --labels to find the patches")
    if xyz is None:
        xyz, white = reference_xyz(), reference_white_xyz()
        inputs["reference"] = f"colour-science {REFERENCE_CHART} (D50)"
    else:
        inputs["reference"] = "xyz and white_xyz of the patches file"
    correction = calibrate(rgb, xyz, white, degree=args.degree, refine=not args.no_refine,
                           space=args.space)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_correction(args.out, correction, inputs)
    b, a = correction.delta_e_before, correction.delta_e_after
    print(f"wrote {args.out}: ΔE00 {b.mean():.2f} ± {b.std(ddof=1):.2f} (least squares) -> "
          f"{a.mean():.2f} ± {a.std(ddof=1):.2f} (refined), {len(a)} patches")
    return 0


def _read_labels(path: Path, shape):
    import cv2
    import numpy as np

    from abs.errors import InputError

    labels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if labels is None:
        raise InputError(path, "", "cannot read the label mask (PNG, 8 or 16 bit, one channel)")
    if labels.ndim == 3:
        labels = labels[:, :, 0]
    if labels.shape != tuple(shape[:2]):
        raise InputError(path, "size", f"mask is {labels.shape[1]}x{labels.shape[0]}, its image "
                                       f"{shape[1]}x{shape[0]}")
    return np.asarray(labels)


def run_apply(args) -> int:
    from abs.colour.correction_file import read_correction
    from abs.io.images import read_image, write_exr

    correction = read_correction(args.correction)
    args.out.mkdir(parents=True, exist_ok=True)
    for path in args.images:
        out = args.out / (path.stem + ".exr")
        write_exr(out, correction.apply(read_image(path)))
        print(f"wrote {out} ({correction.space})")
    return 0
