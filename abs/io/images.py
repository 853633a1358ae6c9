"""Read and write images as linear RGB ``float32`` arrays.

Every array here follows docs/conventions.md: shape ``(height, width, 3)``, row 0 at the top,
linear Rec. 709 / sRGB-primaries RGB, channels ordered R, G, B.

Formats
-------
- OpenEXR (``.exr``): read through the ``OpenEXR`` package, so every compression it supports
  works, lossy DWAA/DWAB included. Half and float channels, RGB or RGBA (alpha dropped) or a
  single luminance channel ``Y`` (replicated). Values are taken as linear Rec. 709; a
  ``chromaticities`` attribute is not applied (Poly Haven/Blender maps carry the ICC D50-adapted
  sRGB primaries, which denote plain sRGB).
- Radiance (``.hdr``): read through OpenCV (BGR → RGB).
- PNG / JPEG (``.png``, ``.jpg``, ``.jpeg``): 8- or 16-bit, taken as sRGB-encoded and decoded
  with the exact sRGB EOTF. EXIF orientation is ignored: pixels are used as stored, which is
  the frame camera calibrations refer to.

Errors about a file are :class:`abs.errors.InputError` naming the file.
"""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import OpenEXR

# The sRGB transfer functions decode PNG/JPEG files and tone mapping encodes previews; both are
# colour science, kept in abs.colour (below io in docs/architecture.md), not copied here.
from abs.colour.srgb import as_rgb_image, srgb_to_linear
from abs.colour.tonemap import tonemap
from abs.errors import InputError

__all__ = [
    "IMAGE_EXTENSIONS",
    "image_size",
    "read_image",
    "write_exr",
    "write_png",
    "read_mask",
    "write_mask",
]

#: File extensions :func:`read_image` understands (lower case).
IMAGE_EXTENSIONS = (".exr", ".hdr", ".png", ".jpg", ".jpeg")
_MASK_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".exr")

# --------------------------------------------------------------------------------------------
# Reading


def _check_file(path: Path, extensions: tuple[str, ...]) -> str:
    """Return the lower-case extension of ``path`` after checking it exists and is supported."""
    if not path.is_file():
        what = "is a directory, not an image file" if path.is_dir() else "no such file"
        raise InputError(path, "", what)
    ext = path.suffix.lower()
    if ext not in extensions:
        raise InputError(path, "", f"unsupported image format {ext or '(none)'!r}; "
                                   f"expected one of {', '.join(extensions)}")
    return ext


def _png_size(head: bytes) -> tuple[int, int] | None:
    # PNG: 8-byte signature, then the IHDR chunk whose data starts with width, height (big endian).
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return struct.unpack(">II", head[16:24])
    return None


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    # Walk the marker segments up to the first start-of-frame (SOF0..SOF15 bar DHT, JPG, DAC).
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        length = struct.unpack(">H", data[i + 2:i + 4])[0]
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            height, width = struct.unpack(">HH", data[i + 5:i + 9])
            return width, height
        i += 2 + length
    return None


def _hdr_size(data: bytes) -> tuple[int, int] | None:
    # Radiance header: text lines, a blank line, then the resolution line "-Y H +X W".
    end = data.find(b"\n\n")
    if end < 0:
        return None
    line_end = data.find(b"\n", end + 2)
    tokens = data[end + 2:line_end if line_end >= 0 else None].split()
    if len(tokens) == 4 and tokens[0] == b"-Y" and tokens[2] == b"+X":
        return int(tokens[3]), int(tokens[1])
    return None


def image_size(path: str | Path) -> tuple[int, int]:
    """Width and height in pixels of an image, read from its header where the format allows.

    EXR (``dataWindow``), PNG, JPEG and Radiance headers are parsed without decoding pixels; other
    layouts fall back to decoding the image.

    Parameters
    ----------
    path : str or Path
        Image file, one of :data:`IMAGE_EXTENSIONS` (masks may also be ``.bmp``/``.tif``).

    Returns
    -------
    (int, int)
        ``(width, height)`` in pixels.

    Raises
    ------
    InputError
        If the file is missing, unsupported or unreadable.
    """
    path = Path(path)
    ext = _check_file(path, _MASK_EXTENSIONS + (".hdr",))
    if ext == ".exr":
        try:
            with OpenEXR.File(str(path), header_only=True) as exr:
                lo, hi = exr.header()["dataWindow"]
        except Exception as exc:  # noqa: BLE001 - OpenEXR raises bare RuntimeErrors
            raise InputError(path, "", f"cannot read the OpenEXR header: {exc}") from exc
        return int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
    with path.open("rb") as f:
        head = f.read(1 << 16)  # headers of PNG/HDR, and nearly always a JPEG's SOF, lie here
    size = _png_size(head) or _jpeg_size(head) or (_hdr_size(head) if ext == ".hdr" else None)
    if size is not None:
        return size
    pixels = _decode_cv2(path)
    return pixels.shape[1], pixels.shape[0]


def _decode_cv2(path: Path) -> np.ndarray:
    # imdecode on bytes, rather than imread, so that errors are ours and any path name works.
    data = np.frombuffer(path.read_bytes(), dtype=np.uint8)
    pixels = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if pixels is None:
        raise InputError(path, "", "cannot decode the image (corrupt or not the format its "
                                   "extension says)")
    return pixels


def _to_rgb(pixels: np.ndarray) -> np.ndarray:
    """OpenCV channel layout (grey, grey+alpha, BGR, BGRA) to RGB, same dtype."""
    if pixels.ndim == 2:
        return np.repeat(pixels[:, :, None], 3, axis=2)
    channels = pixels.shape[2]
    if channels in (1, 2):  # grey (+ alpha)
        return np.repeat(pixels[:, :, :1], 3, axis=2)
    return np.ascontiguousarray(pixels[:, :, 2::-1])  # BGR(A) -> RGB, alpha dropped


def _read_exr(path: Path) -> np.ndarray:
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: ch for name, ch in exr.channels().items()}
            found = sorted(channels)
            if all(c in channels for c in "RGB"):
                names = ["R", "G", "B"]
            elif "Y" in channels:
                names = ["Y", "Y", "Y"]
            else:
                raise InputError(path, "channels", f"expected R, G, B (or Y) channels, found "
                                                   f"{', '.join(found) or 'none'}")
            for name in set(names):
                ch = channels[name]
                if ch.xSampling != 1 or ch.ySampling != 1:
                    raise InputError(path, f"channels.{name}",
                                     "subsampled channels are not supported")
            planes = [np.asarray(channels[n].pixels, dtype=np.float32) for n in names]
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - OpenEXR raises bare RuntimeErrors
        raise InputError(path, "", f"cannot read the OpenEXR file: {exc}") from exc
    return np.stack(planes, axis=-1)


def read_image(path: str | Path) -> np.ndarray:
    """Read a photograph or rendering as linear RGB.

    Parameters
    ----------
    path : str or Path
        ``.exr``, ``.hdr``, ``.png``, ``.jpg`` or ``.jpeg`` file.

    Returns
    -------
    np.ndarray
        ``float32`` array of shape ``(height, width, 3)``, linear RGB (radiance units as stored
        for EXR/HDR; [0, 1] for PNG/JPEG).

    Raises
    ------
    InputError
        If the file is missing, unsupported or undecodable, or (field ``pixels``) if any value is
        NaN or infinite.
    """
    path = Path(path)
    ext = _check_file(path, IMAGE_EXTENSIONS)
    if ext == ".exr":
        rgb = _read_exr(path)
    else:
        pixels = _to_rgb(_decode_cv2(path))
        if ext == ".hdr":
            rgb = pixels.astype(np.float32)
        elif pixels.dtype == np.uint8:
            rgb = srgb_to_linear(pixels.astype(np.float32) / 255.0)
        elif pixels.dtype == np.uint16:
            rgb = srgb_to_linear(pixels.astype(np.float32) / 65535.0)
        else:
            raise InputError(path, "pixels", f"unsupported sample type {pixels.dtype} for an "
                                             "sRGB image; expected 8 or 16 bits")
    bad = int(np.count_nonzero(~np.isfinite(rgb)))
    if bad:
        raise InputError(path, "pixels", f"{bad} non-finite values (NaN or Inf) in a "
                                         f"{rgb.shape[1]}x{rgb.shape[0]} image")
    return np.ascontiguousarray(rgb, dtype=np.float32)


# --------------------------------------------------------------------------------------------
# Writing


def write_exr(path: str | Path, rgb: np.ndarray, *, allow_nonfinite: bool = False) -> None:
    """Write linear RGB as a ``float32`` OpenEXR file with lossless ZIP compression.

    Parameters
    ----------
    path : str or Path
        Destination ``.exr`` file; its folder must exist.
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB.
    allow_nonfinite : bool
        Write NaN/Inf values (for debugging renders) instead of refusing them; such a file is
        refused again by :func:`read_image`.

    Raises
    ------
    InputError
        If ``rgb`` has the wrong shape or non-finite values.
    """
    arr = np.ascontiguousarray(as_rgb_image(rgb), dtype=np.float32)
    if not allow_nonfinite:
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        if bad:
            raise InputError(None, "rgb", f"{bad} non-finite values (NaN or Inf); pass "
                                          "allow_nonfinite=True to write them anyway")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": arr}) as exr:
        exr.write(str(path))


def _write_png_bytes(path: Path, pixels: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", pixels)
    if not ok:
        raise OSError(f"{path}: PNG encoding failed")
    path.write_bytes(buf.tobytes())


def write_png(path: str | Path, rgb: np.ndarray, exposure: float | None = None) -> None:
    """Write a tone-mapped 8-bit sRGB PNG preview of linear RGB.

    Parameters
    ----------
    path : str or Path
        Destination ``.png`` file.
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB, tone-mapped with :func:`tonemap`; a ``uint8`` array is
        taken as already sRGB-encoded and written as is.
    exposure : float, optional
        Passed to :func:`tonemap`.
    """
    arr = as_rgb_image(rgb)
    srgb = arr if arr.dtype == np.uint8 else tonemap(arr, exposure)
    _write_png_bytes(Path(path), np.ascontiguousarray(srgb[:, :, ::-1]))


# --------------------------------------------------------------------------------------------
# Masks


def read_mask(path: str | Path, shape: tuple[int, ...]) -> np.ndarray:
    """Read a comparison mask: nonzero pixels are compared, zero pixels ignored.

    Any channel count is accepted: a pixel is selected when any colour channel is nonzero (an
    alpha channel, i.e. the 2nd of 2 or the 4th of 4, is ignored). 8/16-bit images, and EXR.

    Parameters
    ----------
    path : str or Path
        Mask image (``.png`` recommended; JPEG artefacts make "nonzero" unreliable).
    shape : tuple of int
        Shape of the photograph the mask belongs to, ``(height, width)`` or
        ``(height, width, channels)``.

    Returns
    -------
    np.ndarray
        ``bool`` array of shape ``(height, width)``.

    Raises
    ------
    InputError
        If the file is missing or unreadable, its size differs from ``shape`` (field ``size``),
        or it selects no pixel at all (field ``pixels``).
    """
    path = Path(path)
    ext = _check_file(path, _MASK_EXTENSIONS)
    if ext == ".exr":
        try:
            with OpenEXR.File(str(path), separate_channels=True) as exr:
                planes = [np.asarray(ch.pixels) for name, ch in exr.channels().items()
                          if name != "A" and not name.endswith(".A")]
        except Exception as exc:  # noqa: BLE001 - OpenEXR raises bare RuntimeErrors
            raise InputError(path, "", f"cannot read the OpenEXR file: {exc}") from exc
        if not planes:
            raise InputError(path, "channels", "no colour channel in the mask")
        mask = np.any(np.stack(planes, axis=-1) != 0, axis=-1)
    else:
        pixels = _decode_cv2(path)
        if pixels.ndim == 3 and pixels.shape[2] in (2, 4):
            pixels = pixels[:, :, :-1]
        mask = pixels != 0 if pixels.ndim == 2 else np.any(pixels != 0, axis=-1)
    height, width = int(shape[0]), int(shape[1])
    if mask.shape != (height, width):
        raise InputError(path, "size", f"mask is {mask.shape[1]}x{mask.shape[0]} pixels but its "
                                       f"photograph is {width}x{height}")
    if not mask.any():
        raise InputError(path, "pixels", "mask is all zero, so no pixel would be compared "
                                         "(nonzero marks the pixels to compare)")
    return mask


def write_mask(path: str | Path, mask: np.ndarray) -> None:
    """Write a boolean mask as an 8-bit greyscale PNG (255 = compared, 0 = ignored).

    Parameters
    ----------
    path : str or Path
        Destination ``.png`` file.
    mask : np.ndarray
        ``(height, width)`` array; nonzero entries are written as 255.
    """
    arr = np.asarray(mask)
    if arr.ndim != 2:
        raise InputError(None, "mask", f"expected an array of shape (height, width), got "
                                       f"{arr.shape}")
    _write_png_bytes(Path(path), np.where(arr != 0, 255, 0).astype(np.uint8))
