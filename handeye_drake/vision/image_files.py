"""Image files and buffers read safely: the size from the header before decoding (a 20000²
PNG would take gigabytes), and decoding without the decoder libraries printing on stderr."""

from __future__ import annotations

import numpy as np

#: Largest image decoded (pixels): a 20000² file would take gigabytes once decoded.
MAX_IMAGE_PIXELS = 50_000_000


def image_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG, JPEG or BMP header, without decoding; None when unknown."""
    import struct
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24:
        return struct.unpack(">II", data[16:24])
    if data[:2] == b"BM" and len(data) >= 26:
        w, h = struct.unpack("<ii", data[18:26])
        return abs(w), abs(h)
    if data[:2] == b"\xff\xd8":
        k = 2
        while k + 9 < len(data):
            if data[k] != 0xFF:
                return None
            marker = data[k + 1]
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
                k += 2
                continue
            length = struct.unpack(">H", data[k + 2:k + 4])[0]
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                h, w = struct.unpack(">HH", data[k + 5:k + 9])
                return w, h
            k += 2 + length
    return None


def decode_quietly(data: np.ndarray):
    """``cv2.imdecode`` with the decoder libraries' own messages (``libpng error: …``) caught
    from the process's stderr instead of printed: (image or None, their text)."""
    import os
    import tempfile

    import cv2
    try:
        saved = os.dup(2)
    except OSError:
        return cv2.imdecode(data, cv2.IMREAD_UNCHANGED), ""
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        sink.seek(0)
        said = " ".join(sink.read(2000).decode("utf-8", "replace").split())
    return image, said


__all__ = ["MAX_IMAGE_PIXELS", "decode_quietly", "image_size"]
