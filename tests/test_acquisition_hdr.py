"""Raw reading, bilinear demosaicing and the bracket merge.

Real checks: colour-demosaicing's reference bilinear outputs (../shared/data/demosaic_lighthouse)
and the Llanos ColorChecker raw stacks (../shared/data/colorchecker_bandpass_llanos); each skips
when its folder is absent.
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from abs.acquisition.demosaic import CFA_PATTERNS, cfa_masks, demosaic_bilinear
from abs.acquisition.hdr import merge_brackets
from abs.acquisition.raw import read_raw
from abs.errors import InputError
from abs.io.images import read_image
from abs.io.shared_data import shared_data_dir

LIGHTHOUSE = shared_data_dir() / "demosaic_lighthouse"
LLANOS = shared_data_dir() / "colorchecker_bandpass_llanos"


def test_demosaic_keeps_a_linear_ramp_exact():
    # Bilinear interpolation reproduces any linear function away from the border.
    v, u = np.mgrid[0:24, 0:32].astype(np.float64)
    rgb = np.stack([0.1 + 0.01 * u, 0.2 + 0.02 * v, 0.3 + 0.005 * (u + v)], -1)
    for pattern in CFA_PATTERNS:
        masks = cfa_masks((24, 32), pattern)
        mosaic = np.sum(rgb * masks, axis=-1)
        out = demosaic_bilinear(mosaic, pattern)
        np.testing.assert_allclose(out[2:-2, 2:-2], rgb[2:-2, 2:-2], atol=1e-6)
        inner = masks.copy()
        inner[[0, -1]] = False
        inner[:, [0, -1]] = False
        # Measured sites keep their value (at the border, reflection adds the site to itself).
        np.testing.assert_allclose(out[inner], rgb[inner], atol=1e-6)
    with pytest.raises(InputError, match="not a Bayer pattern"):
        demosaic_bilinear(mosaic, "RGBG")


@pytest.mark.skipif(not LIGHTHOUSE.is_dir(), reason=f"shared data absent: {LIGHTHOUSE}")
@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_demosaic_matches_colour_demosaicing_reference(pattern):
    mosaic = read_image(LIGHTHOUSE / f"Lighthouse_CFA_{pattern}.exr")[..., 0]
    reference = read_image(LIGHTHOUSE / f"Lighthouse_Bilinear_{pattern}.exr")
    out = demosaic_bilinear(mosaic, pattern)
    # The reference is stored as half floats: agree to half-float rounding (2^-11 relative).
    np.testing.assert_allclose(out, reference, rtol=2 ** -10, atol=1e-4)


def _sensor(radiance, t, rng, white=4095.0, read_noise=2.0, dark=64.0):
    signal = rng.poisson(radiance * t).astype(np.float64)
    return np.clip(signal + dark + rng.normal(0, read_noise, radiance.shape), 0, white).round()


def test_merge_recovers_linear_truth_within_noise():
    rng = np.random.default_rng(0)
    radiance = np.exp(rng.uniform(np.log(50), np.log(2e6), (48, 64)))  # DN/s over 4.6 decades
    t = 0.001 * 2.0 ** np.arange(11)  # 1 ms to 2048 ms, one stop apart (the seed's bracket)
    frames = [_sensor(radiance, ti, rng) for ti in t]
    darks = [np.full((48, 64), 64.0)] * len(t)
    merged = merge_brackets(frames, t, 4095.0, darks)
    assert not merged.saturated_everywhere.any()
    # Expected relative standard error: shot noise over the total exposure used.
    expected = 1.0 / np.sqrt(radiance * merged.weight)
    rel = (merged.radiance - radiance) / radiance
    assert np.sqrt(np.mean((rel / expected) ** 2)) < 1.5  # errors are the size of the noise
    assert abs(np.mean(rel)) < 0.01  # no bias from clipped or dark frames
    # A pixel bright enough to saturate the long frames used only the short ones.
    bright = np.unravel_index(np.argmax(radiance), radiance.shape)
    assert not merged.used[-1][bright] and merged.used[0][bright]


def test_merge_variance_is_the_scatter_of_repeated_merges():
    # 300 brackets of the same pixels (4.6 decades of radiance, shot noise at one electron per
    # data number and 2 DN of read noise): the merge's stated variance is their scatter.
    rng = np.random.default_rng(4)
    radiance = np.exp(np.linspace(np.log(50), np.log(2e6), 40))
    t = 0.001 * 4.0 ** np.arange(6)
    darks = [np.full(radiance.shape, 64.0)] * len(t)
    merges = [merge_brackets([_sensor(radiance, ti, rng) for ti in t], t, 4095.0, darks,
                             read_noise_dn=2.0) for _ in range(300)]
    scatter = np.var([m.radiance for m in merges], axis=0, ddof=1)
    stated = np.mean([m.variance for m in merges], axis=0)
    ratio = scatter / stated
    # 300 draws: a variance's ratio scatters by sqrt(2/299) = 8 %; rounding to whole DN adds
    # 1/12 DN^2 to the read noise's 4.
    assert np.all(np.abs(ratio - 1) < 0.3), ratio
    assert abs(np.mean(ratio) - 1) < 0.05, np.mean(ratio)
    # Relative noise falls with light up to the frames' saturation, then stays (the bracket
    # keeps each pixel near full well): equal weights would let the brightest pixels dominate.
    relative = np.sqrt(stated) / radiance
    assert relative[0] > 4 * relative[-1] and relative[-1] < 0.03
    # A pixel saturated even in the shortest frame is a lower bound: its noise is its own size.
    merged = merge_brackets([_sensor(np.array([1e7]), ti, rng) for ti in t], t, 4095.0,
                            [np.full(1, 64.0)] * len(t))
    assert merged.saturated_everywhere[0]
    assert np.sqrt(merged.variance[0]) >= merged.radiance[0] * (1 - 1e-6)


def test_merge_without_exclusion_would_be_biased():
    rng = np.random.default_rng(1)
    radiance = np.full((8, 8), 1e5)
    t = np.array([0.001, 0.01, 0.1])
    frames = [_sensor(radiance, ti, rng, dark=0.0) for ti in t]
    merged = merge_brackets(frames, t, 4095.0)
    assert merged.radiance.mean() == pytest.approx(1e5, rel=0.02)
    naive = sum(frames) / t.sum()  # the clipped 100 ms frame pulls the naive merge down
    assert naive.mean() < 0.5e5


def test_non_increasing_exposures_refused():
    frames = [np.zeros((4, 4))] * 3
    with pytest.raises(InputError, match=r"frame 2 has 0.01 s after 0.02 s"):
        merge_brackets(frames, [0.01, 0.02, 0.01], 255.0)
    with pytest.raises(InputError, match="must increase strictly"):
        merge_brackets(frames, [0.01, 0.01, 0.02], 255.0)


def test_unreadable_raw_formats(tmp_path: Path):
    with pytest.raises(InputError, match=r"scene.xyz: unreadable raw format '.xyz'"):
        read_raw(tmp_path / "scene.xyz")
    bad = tmp_path / "broken.tif"
    bad.write_bytes(b"not a tiff")
    with pytest.raises(InputError, match="broken.tif: cannot read"):
        read_raw(bad)
    rgb = tmp_path / "rgb.png"
    cv2.imwrite(str(rgb), np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(InputError, match="single-channel raw mosaic"):
        read_raw(rgb)
    cr2 = tmp_path / "photo.cr2"
    cr2.write_bytes(b"\0" * 64)
    with pytest.raises(InputError, match="photo.cr2"):
        read_raw(cr2)


def _llanos_stack(band: str):
    folder = LLANOS / "captured_images"
    def ms(path: Path) -> int:
        return int(re.search(r"_(\d+)ms_", path.name).group(1))
    files = sorted((folder / "images_filtered_light" / "color_checker").glob(f"*_{band}_*.tif"),
                   key=ms)
    frames = [read_raw(f) for f in files]
    darks = [np.mean([read_raw(d).mosaic for d in
                      sorted((folder / "dark_frames").glob(f"d2_dark_{ms(f)}ms_*.tif"))], axis=0)
             for f in files]
    return frames, darks, np.array([ms(f) for f in files]) / 1000.0


@pytest.mark.skipif(not LLANOS.is_dir(), reason=f"shared data absent: {LLANOS}")
def test_real_colorchecker_stack_is_consistent_and_linear():
    labels = cv2.imread(str(LLANOS / "colorChecker_labels" / "d2_colorChecker30cm_550nm_labels.png"),
                        cv2.IMREAD_UNCHANGED)
    frames, darks, t = _llanos_stack("550nm")
    assert len(frames) == 7 and np.all(np.diff(t) > 0)
    merged = merge_brackets([f.mosaic for f in frames], t, frames[0].white_level, darks)
    spreads, fit_errors = [], []
    for patch in range(1, 25):
        sel = labels == patch
        # Per-exposure estimates of the patch's mean rate from frames unsaturated on the patch.
        usable = [i for i in range(len(t)) if frames[i].mosaic[sel].max() < 0.95 * 255
                  and (frames[i].mosaic[sel] - darks[i][sel]).mean() > 10]
        if len(usable) < 2:
            continue
        means = np.array([(frames[i].mosaic[sel] - darks[i][sel]).mean() for i in usable])
        rates = means / t[usable]
        spreads.append(rates.std() / rates.mean())
        # Linear in exposure time: mean = rate * t through the origin, rate from the merge.
        predicted = merged.radiance[sel].mean() * t[usable]
        fit_errors.append(np.max(np.abs(means / predicted - 1)))
    assert len(spreads) >= 20
    # Measured: median 0.27 %, worst 0.46 % relative spread across exposures.
    assert np.median(spreads) < 0.01 and np.max(spreads) < 0.02
    assert np.max(fit_errors) < 0.03


FROBISHER = shared_data_dir() / "hdr_frobisher_ldr"


def _log_disagreement(frames, t, to_linear):
    """Median |log ratio| of per-frame radiance estimates of neighbouring exposures, using only
    codes away from clipping (20..235)."""
    out = []
    for a, b in ((0, 1), (1, 2)):
        ok = (frames[a] > 20) & (frames[a] < 235) & (frames[b] > 20) & (frames[b] < 235)
        ea, eb = to_linear(frames[a]) / t[a], to_linear(frames[b]) / t[b]
        out.append(float(np.median(np.abs(np.log(ea[ok] / eb[ok])))))
    return max(out)


def test_debevec_recovers_a_known_response_and_merges_to_truth():
    from abs.acquisition.response import merge_ldr, recover_response

    rng = np.random.default_rng(2)
    v, u = np.mgrid[0:48, 0:64]
    radiance = np.exp(np.stack([np.log(0.02) + 6.0 * (u / 63) * (0.5 + 0.5 * v / 47)] * 3, -1)
                      + rng.normal(0, 0.05, (48, 64, 3)))
    t = np.array([0.25, 1.0, 4.0])
    gamma = 1 / 2.2  # a non-linear camera response (then 8-bit quantisation)
    frames = [np.clip(np.round(255 * np.clip(radiance * ti, 0, 1) ** gamma), 0, 255).astype(np.uint8)
              for ti in t]
    response = recover_response(frames, t, samples=300)
    merged = merge_ldr(frames, t, response)
    # Up to the merge's unknown scale, the merged radiance matches the linear truth.
    log_err = np.log(merged / radiance)
    ok = (radiance * t[0] < 0.9) & (radiance * t[-1] > 0.02)  # seen unclipped by some frame
    log_err = log_err[ok] - np.median(log_err[ok])
    assert np.median(np.abs(log_err)) < 0.03
    assert np.percentile(np.abs(log_err), 95) < 0.1


@pytest.mark.skipif(not FROBISHER.is_dir(), reason=f"shared data absent: {FROBISHER}")
def test_debevec_on_real_jpeg_bracket():
    from abs.acquisition.response import recover_response
    from abs.colour.srgb import srgb_to_linear

    frames = []
    for name in ("IMG_2600.jpg", "IMG_2601.jpg", "IMG_2602.jpg"):
        bgr = cv2.imread(str(FROBISHER / name))
        small = cv2.resize(bgr, (bgr.shape[1] // 4, bgr.shape[0] // 4), interpolation=cv2.INTER_AREA)
        frames.append(small[..., ::-1].copy())
    t = np.array([1 / 8, 1.0, 8.0])  # EXIF exposure times (SOURCE.txt)
    response = recover_response(frames, t)
    channel = np.arange(3)
    recovered = _log_disagreement(frames, t, lambda f: response[f, channel])
    assumed_srgb = _log_disagreement(frames, t, lambda f: srgb_to_linear(f / 255.0))
    # Measured: 2.6 % with the recovered response against 56 % assuming a plain sRGB curve.
    assert recovered < 0.05 and assumed_srgb > 0.3


def test_mixed_frame_sizes_refused():
    frames = [np.zeros((4, 4)), np.zeros((4, 5))]
    with pytest.raises(InputError, match=r"frames\[1\]: mixed image sizes"):
        merge_brackets(frames, [0.01, 0.02], 255.0)
    with pytest.raises(InputError, match=r"darks\[1\]: mixed image sizes"):
        merge_brackets([np.zeros((4, 4))] * 2, [0.01, 0.02], 255.0,
                       darks=[np.zeros((4, 4)), np.zeros((3, 4))])


def test_ldr_bracket_bad_inputs_refused():
    from abs.acquisition.response import merge_ldr, recover_response

    frames = [np.zeros((8, 8, 3), np.uint8)] * 3
    with pytest.raises(InputError, match="must increase strictly"):
        recover_response(frames, [0.1, 0.4, 0.2])
    with pytest.raises(InputError, match=r"frames\[1\].*mixed image sizes"):
        merge_ldr([frames[0], np.zeros((8, 6, 3), np.uint8)], [0.1, 0.2],
                  np.ones((256, 3), np.float32))
