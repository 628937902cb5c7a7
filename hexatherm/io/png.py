"""PNG files of RGBA pixels, written with the standard library (zlib).

The report's and diagnose's figures are drawn by matplotlib's Agg canvas into RGBA
pixels; :func:`png_bytes` writes them as a PNG (8-bit RGBA, no interlace) with every
row unfiltered (filter type 0) and one zlib stream: Pillow, which ``savefig`` uses,
tries the five PNG filters on every row and keeps the best, which takes about twice as
long as the compression itself on these mostly white pictures, for files no smaller
(diagnose's four figures: 1.42 MB unfiltered at zlib level 3, 1.49 MB by Pillow). The
pixels are the same (a PNG is lossless; tests decode both).
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import numpy.typing as npt

#: the 8 bytes every PNG file starts with
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

_INCH_M = 0.0254


def _chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk: length, type, data, CRC-32 of type and data."""
    return (
        struct.pack(">I", len(data))
        + kind
        + data
        + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    )


def png_bytes(rgba: npt.NDArray[np.uint8], dpi: float | None = None, level: int = 6) -> bytes:
    """The PNG file of ``rgba`` (height x width x 4, uint8, top row first).

    Parameters
    ----------
    rgba : ndarray of uint8, shape (H, W, 4)
    dpi : float, optional
        Written as the pixels' physical size (a ``pHYs`` chunk, pixels per metre rounded
        as Pillow rounds them), which viewers and printers size the picture by.
    level : int
        zlib's compression level, 0-9 (the pixels are the same at every level).
    """
    pixels = np.asarray(rgba)
    height, width = pixels.shape[:2]
    rows = np.zeros((height, 1 + 4 * width), dtype=np.uint8)  # a 0 (no filter) per row
    rows[:, 1:] = pixels.reshape(height, 4 * width)
    chunks = [_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))]
    if dpi is not None:
        per_metre = int(dpi / _INCH_M + 0.5)
        chunks.append(_chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1)))
    chunks.append(_chunk(b"IDAT", zlib.compress(rows.tobytes(), level)))
    chunks.append(_chunk(b"IEND", b""))
    return PNG_SIGNATURE + b"".join(chunks)
