"""hexatherm.io.png: PNG files of RGBA pixels, read back by Pillow (an independent decoder)."""

from __future__ import annotations

import io
import zlib

import numpy as np
import pytest
from PIL import Image

from hexatherm.io.png import PNG_SIGNATURE, png_bytes


def _decoded(data: bytes) -> tuple[np.ndarray, dict[str, object]]:
    with Image.open(io.BytesIO(data)) as image:
        image.load()  # checks every chunk's CRC and the zlib stream
        assert image.mode == "RGBA"
        return np.asarray(image), dict(image.info)


@pytest.mark.parametrize("shape", [(1, 1), (3, 7), (64, 33), (200, 301)])
def test_the_pixels_come_back(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    rgba = rng.integers(0, 256, size=(*shape, 4), dtype=np.uint8)
    for level in (0, 3, 9):
        data = png_bytes(rgba, level=level)
        assert data.startswith(PNG_SIGNATURE)
        pixels, _ = _decoded(data)
        np.testing.assert_array_equal(pixels, rgba)


def test_a_picture_like_a_figure_comes_back() -> None:
    # mostly white, a few lines and grey steps: what the figures are
    rgba = np.full((300, 400, 4), 255, dtype=np.uint8)
    rgba[::37, :, :3] = 176
    rgba[:, 50:52, :3] = (31, 119, 180)
    rgba[100:110, 100:300, :3] = np.arange(200, dtype=np.uint8)[None, :, None]
    np.testing.assert_array_equal(_decoded(png_bytes(rgba, level=3))[0], rgba)


def test_the_resolution_is_written_as_pillow_writes_it() -> None:
    rgba = np.zeros((2, 2, 4), dtype=np.uint8)
    for dpi in (50, 150, 300):
        pillow = io.BytesIO()
        Image.fromarray(rgba, "RGBA").save(pillow, format="png", dpi=(dpi, dpi))
        _, info = _decoded(png_bytes(rgba, dpi=dpi))
        assert info["dpi"] == _decoded(pillow.getvalue())[1]["dpi"]
        assert info["dpi"] == pytest.approx((dpi, dpi), rel=1e-3)
    _, info = _decoded(png_bytes(rgba))
    assert "dpi" not in info


def test_the_compression_level_is_zlibs() -> None:
    rgba = np.full((20, 20, 4), 200, dtype=np.uint8)
    data = png_bytes(rgba, level=3)
    start = data.index(b"IDAT") + 4
    # the zlib header's FLEVEL: 0 for levels 0-1, 1 for 2-5, 2 for 6, 3 for 7-9
    assert data[start + 1] >> 6 == 1
    assert data[start:].startswith(zlib.compress(b"", 3)[:1])
