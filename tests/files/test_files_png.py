"""PNG frames as written by rigsim.files: lossless, readable by OpenCV and Pillow, not larger than
OpenCV's default encoding."""

from __future__ import annotations

import io

import cv2
import numpy as np
import pytest
from PIL import Image

from rigsim.files import read_image, write_image
from rigsim.files.images import encode_image


def _frames():
    rng = np.random.default_rng(4)
    v, u = np.mgrid[:300, :400]
    spot = 3000.0 * np.exp(-((u - 210.3) ** 2 + (v - 140.8) ** 2) / (2 * 9.0 ** 2))
    noisy16 = np.clip(rng.poisson(spot + 20.0) + 64 + rng.normal(0, 2, spot.shape), 0, 4095).astype(np.uint16)
    full16 = rng.integers(0, 65536, (64, 96), dtype=np.uint16)  # every bit in use, incl. the top code
    full16[0, 0], full16[0, 1] = 0, 65535
    noisy8 = np.clip(spot / 12 + rng.normal(8, 2, spot.shape), 0, 255).astype(np.uint8)
    return {"noisy16": noisy16, "full16": full16, "noisy8": noisy8, "odd": noisy16[:17, :33].copy()}


@pytest.mark.parametrize("name", ["noisy16", "full16", "noisy8", "odd"])
def test_png_is_lossless_for_opencv_and_pillow(name, tmp_path):
    img = _frames()[name]
    data = encode_image(img, ".png")
    back = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert back.dtype == img.dtype
    np.testing.assert_array_equal(back, img)
    pil = np.asarray(Image.open(io.BytesIO(data)))
    np.testing.assert_array_equal(pil.astype(img.dtype), img)
    p = write_image(tmp_path / f"{name}.png", img)
    np.testing.assert_array_equal(read_image(p), img)


def test_png_not_larger_than_opencv_default():
    img = _frames()["noisy16"]
    ok, default = cv2.imencode(".png", img)
    assert ok and len(encode_image(img, ".png")) <= len(default)
