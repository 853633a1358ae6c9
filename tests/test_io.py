"""Tests for abs.io.images: EXR/HDR/PNG reading, writing, tone mapping and masks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

from abs.colour.srgb import linear_to_srgb, srgb_to_linear
from abs.colour.tonemap import tonemap
from abs.errors import InputError
from abs.io.images import image_size, read_image, read_mask, write_exr, write_mask, write_png

SHARED_EXR = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
              / "blender_studiolights_world_cc0").resolve()


def _rgb(h: int = 5, w: int = 7) -> np.ndarray:
    rng = np.random.default_rng(1)
    return (rng.uniform(0, 40, (h, w, 3)) * [1.0, 0.5, 0.25]).astype(np.float32)


def test_exr_roundtrip_exact(tmp_path):
    rgb = _rgb()
    write_exr(tmp_path / "a.exr", rgb)
    back = read_image(tmp_path / "a.exr")
    assert back.dtype == np.float32 and back.shape == (5, 7, 3)
    np.testing.assert_array_equal(back, rgb)
    assert image_size(tmp_path / "a.exr") == (7, 5)
    with OpenEXR.File(str(tmp_path / "a.exr"), header_only=True) as f:
        assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION
    flipped = rgb[:, ::-1]  # a strided view must be written as the pixels it shows
    write_exr(tmp_path / "b.exr", flipped)
    np.testing.assert_array_equal(read_image(tmp_path / "b.exr"), flipped)


def test_exr_half_rgba(tmp_path):
    rgb = _rgb().astype(np.float16)
    alpha = np.full(rgb.shape[:2], 0.5, np.float16)
    # Contiguous planes: the OpenEXR writer ignores numpy strides (a slice rgb[..., 0] would be
    # written as the first H*W halves of the interleaved buffer).
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    channels["A"] = alpha
    header = {"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(str(tmp_path / "h.exr"))
    back = read_image(tmp_path / "h.exr")
    assert back.dtype == np.float32 and back.shape == (5, 7, 3)
    np.testing.assert_array_equal(back, rgb.astype(np.float32))


def test_png_srgb_decode_known_values(tmp_path):
    values = np.array([0, 10, 128, 255], np.uint8)
    img = np.zeros((1, 4, 3), np.uint8)
    img[0, :, 0] = values  # red channel carries the test values; cv2 writes BGR
    cv2.imwrite(str(tmp_path / "a.png"), img[:, :, ::-1])
    back = read_image(tmp_path / "a.png")
    expected = [0.0, 10 / 255 / 12.92, ((128 / 255 + 0.055) / 1.055) ** 2.4, 1.0]
    np.testing.assert_allclose(back[0, :, 0], expected, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(back[0, :, 1:], 0.0)
    assert image_size(tmp_path / "a.png") == (4, 1)


def test_png16_and_jpeg_sizes(tmp_path):
    img16 = np.full((3, 2), 65535, np.uint16)
    cv2.imwrite(str(tmp_path / "g.png"), img16)
    np.testing.assert_allclose(read_image(tmp_path / "g.png"), 1.0)
    cv2.imwrite(str(tmp_path / "c.jpg"), np.zeros((9, 11, 3), np.uint8))
    assert image_size(tmp_path / "c.jpg") == (11, 9)
    assert read_image(tmp_path / "c.jpg").shape == (9, 11, 3)


def test_hdr_is_rgb(tmp_path):
    rgb = np.zeros((4, 6, 3), np.float32)
    rgb[..., 0] = 3.0  # pure red
    ok, buf = cv2.imencode(".hdr", rgb[:, :, ::-1])
    (tmp_path / "r.hdr").write_bytes(buf.tobytes())
    back = read_image(tmp_path / "r.hdr")
    np.testing.assert_allclose(back, rgb, rtol=1e-2)
    assert image_size(tmp_path / "r.hdr") == (6, 4)


def test_srgb_functions_invert():
    x = np.linspace(0, 1, 101, dtype=np.float32)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-6)


def test_nan_photo_error_names_file(tmp_path):
    rgb = _rgb()
    rgb[0, 0, 0] = np.nan
    rgb[1, 1, 2] = np.inf
    path = tmp_path / "bad.exr"
    with pytest.raises(InputError):
        write_exr(path, rgb)
    write_exr(path, rgb, allow_nonfinite=True)
    with pytest.raises(InputError) as err:
        read_image(path)
    assert "bad.exr" in str(err.value) and err.value.field == "pixels"
    assert "2 non-finite" in str(err.value)


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(InputError, match="nope.exr.*no such file"):
        read_image(tmp_path / "nope.exr")
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match="junk.png.*cannot decode"):
        read_image(tmp_path / "junk.png")
    (tmp_path / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(InputError, match="junk.exr"):
        read_image(tmp_path / "junk.exr")
    (tmp_path / "a.bmp").write_bytes(b"")
    with pytest.raises(InputError, match="unsupported"):
        read_image(tmp_path / "a.bmp")


def test_tonemap_and_png(tmp_path):
    rgb = np.full((10, 10, 3), 2.0, np.float32)
    out = tonemap(rgb)
    assert out.dtype == np.uint8 and out.shape == (10, 10, 3)
    assert int(out[0, 0, 0]) == round(float(linear_to_srgb(np.float32(0.9))) * 255)
    assert int(tonemap(rgb, exposure=1.0)[0, 0, 0]) == 255  # clipped
    assert int(tonemap(rgb, exposure=0.0)[0, 0, 0]) == 0
    write_png(tmp_path / "p.png", rgb, exposure=0.25)
    back = cv2.imread(str(tmp_path / "p.png"))
    assert back.shape == (10, 10, 3)
    assert int(back[0, 0, 0]) == round(float(linear_to_srgb(np.float32(0.5))) * 255)


def test_mask_read_any_channels(tmp_path):
    rgb = np.zeros((4, 5, 3), np.uint8)
    rgb[1, 2, 0] = 7  # only the blue channel (BGR order) is set
    cv2.imwrite(str(tmp_path / "m.png"), rgb)
    mask = read_mask(tmp_path / "m.png", (4, 5, 3))
    assert mask.dtype == bool and mask.shape == (4, 5)
    assert mask.sum() == 1 and mask[1, 2]
    grey = np.zeros((4, 5), bool)
    grey[0] = True
    write_mask(tmp_path / "g.png", grey)
    np.testing.assert_array_equal(read_mask(tmp_path / "g.png", (4, 5)), grey)


def test_mask_shape_mismatch(tmp_path):
    write_mask(tmp_path / "m.png", np.ones((4, 5), bool))
    with pytest.raises(InputError) as err:
        read_mask(tmp_path / "m.png", (4, 6, 3))
    assert "m.png" in str(err.value) and err.value.field == "size"
    assert "5x4" in str(err.value) and "6x4" in str(err.value)


def test_mask_all_zero(tmp_path):
    write_mask(tmp_path / "z.png", np.zeros((4, 5), bool))
    with pytest.raises(InputError, match="z.png.*all zero"):
        read_mask(tmp_path / "z.png", (4, 5))


def test_real_dwab_exr():
    if not SHARED_EXR.is_dir():
        pytest.skip(f"shared data not present at {SHARED_EXR}")
    path = SHARED_EXR / "studio.exr"
    with OpenEXR.File(str(path), header_only=True) as f:
        assert f.header()["compression"] == OpenEXR.DWAB_COMPRESSION  # lossy codec exercised
    rgb = read_image(path)
    assert rgb.dtype == np.float32 and rgb.shape == (512, 1024, 3)
    assert np.isfinite(rgb).all() and rgb.max() > 1.0  # HDR content, not clipped to [0, 1]
    assert image_size(path) == (1024, 512)
