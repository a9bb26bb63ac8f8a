"""Image files read safely: the size from the header (before a huge decode), and no decoder
library message leaking on the process's stderr."""

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from handeye_drake.calibration.inputs import _read_image
from handeye_drake.vision.image_files import MAX_IMAGE_PIXELS, decode_quietly, image_size


def _png_header_only(path: Path, w: int, h: int) -> None:
    def chunk(t, b):
        return struct.pack(">I", len(b)) + t + b + struct.pack(">I", zlib.crc32(t + b))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0,
                                                                       0, 0))
                     + chunk(b"IDAT", zlib.compress(b"\x00" * (w + 1) * 4)) + chunk(b"IEND", b""))


def test_sizes_from_headers(tmp_path):
    for ext in (".png", ".jpg", ".bmp"):
        p = tmp_path / f"a{ext}"
        cv2.imwrite(str(p), np.zeros((37, 53, 3), np.uint8))
        assert image_size(p.read_bytes()) == (53, 37), ext
    assert image_size(b"not an image at all") is None


def test_a_huge_image_is_not_decoded(tmp_path):
    p = tmp_path / "huge.png"
    _png_header_only(p, 20000, 20000)
    assert 20000 * 20000 > MAX_IMAGE_PIXELS
    image, why = _read_image(p)
    assert image is None and "20000×20000 pixels" in why and "not decoded" in why


def test_a_truncated_image_says_so_without_printing(tmp_path, capfd):
    p = tmp_path / "t.png"
    cv2.imwrite(str(p), (np.random.default_rng(0).random((120, 160)) * 255).astype(np.uint8))
    data = p.read_bytes()
    p.write_bytes(data[:len(data) // 2])
    image, why = _read_image(p)
    assert image is None and "truncated" in why
    captured = capfd.readouterr()
    assert "libpng" not in captured.err and "WARN" not in captured.err
    img, said = decode_quietly(np.frombuffer(data, np.uint8))
    assert img is not None and img.shape == (120, 160) and said == ""
