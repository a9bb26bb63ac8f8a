import re

import cv2
import numpy as np
import pytest

from handeye_drake.vision.targets import (
    AprilGridTarget,
    AprilTagTarget,
    CharucoTarget,
    ChessboardTarget,
    charuco_board,
    format_target,
    get_dictionary,
    grid_board,
    object_points,
    parse_target,
    pattern_extent,
    png_pixels_per_metre,
    render_target,
    target_dictionary_name,
    write_printable,
)

CANONICAL_SPECS = [
    "chessboard:9x6:0.0236",
    "chessboard:7x4:0.05",
    "charuco:5x7:0.036195:0.018256:DICT_6X6_250",
    "charuco:6x6:0.03:0.022:DICT_5X5_100:legacy",
    "charuco:8x5:0.03:0.02:DICT_APRILTAG_36h11",
    "apriltag:36h11:0.048:10",
    "apriltag:16h5:0.1",
    "aprilgrid:36h11:6x6:0.088:0.3",
    "aprilgrid:25h9:3x2:0.04:0.25:7",
]


@pytest.mark.parametrize("spec", CANONICAL_SPECS)
def test_spec_round_trip(spec):
    target = parse_target(spec)
    assert format_target(target) == spec
    assert parse_target(format_target(target)) == target


def test_parse_values_and_normalization():
    assert parse_target("chessboard:9x6:0.0236") == ChessboardTarget(9, 6, 0.0236)
    assert parse_target("charuco:5x7:0.036195:0.018256:DICT_6X6_250") == CharucoTarget(
        5, 7, 0.036195, 0.018256, "DICT_6X6_250", False)
    assert parse_target("apriltag:36h11:0.048:10") == AprilTagTarget("36h11", 0.048, 10)
    assert parse_target("aprilgrid:36h11:6x6:0.088:0.3") == AprilGridTarget(
        "36h11", 6, 6, 0.088, 0.3, 0)
    # Case-insensitive dictionary, tag-prefixed family; written back canonically.
    assert format_target(parse_target("charuco:5x7:0.04:0.02:dict_apriltag_36H11:LEGACY")) == \
        "charuco:5x7:0.04:0.02:DICT_APRILTAG_36h11:legacy"
    assert parse_target("apriltag:tag36h11:0.048").family == "36h11"


@pytest.mark.parametrize("spec, message", [
    ("checkerboard:9x6:0.02", r"unknown target type 'checkerboard'.*chessboard:COLSxROWS"),
    ("chessboard:9x6", r"expected 3 ':'-separated fields, got 2"),
    ("chessboard:9by6:0.02", r"field 2 \(COLSxROWS\) '9by6' is not of the form NxM"),
    ("chessboard:2x6:0.02", r"field 2 \(COLSxROWS\) '2x6': both numbers must be ≥ 3"),
    ("chessboard:9x6:-0.02", r"field 3 \(SQUARE\) '-0.02' is not a length > 0"),
    ("chessboard:9x6:abc", r"field 3 \(SQUARE\) 'abc' is not a length"),
    ("charuco:5x7:0.02:0.03:DICT_6X6_250", r"field 4 \(MARKER\) '0.03' must be smaller"),
    ("charuco:5x7:0.04:0.02:DICT_9X9_1", r"field 5 \(DICT\) unknown ArUco dictionary 'DICT_9X9_1'"
                                         r".*DICT_6X6_250"),
    ("charuco:5x7:0.04:0.02:DICT_6X6_250:old", r"field 6 \(legacy\) 'old' must be 'legacy'"),
    ("charuco:20x20:0.04:0.02:DICT_4X4_50", r"DICT_4X4_50 has 50 markers, a 20x20 board needs "
                                            r"200"),
    ("apriltag:36h12:0.05", r"field 2 \(FAMILY\) '36h12' is not one of 16h5, 25h9, 36h10, 36h11"),
    ("apriltag:36h11:0.05:587", r"field 4 \(ID\) 587 is out of range: family 36h11 has ids "
                                r"0…586"),
    ("apriltag:36h11:0.05:-1", r"field 4 \(ID\) '-1' is not a non-negative integer"),
    ("aprilgrid:16h5:6x6:0.05:0.3", r"needs ids up to 35 but family 16h5 has ids 0…29"),
    ("aprilgrid:36h11:6x6:0.05:0", r"field 5 \(SPACING\) '0' is not a length > 0"),
])
def test_spec_errors_name_the_field_and_form(spec, message):
    with pytest.raises(ValueError) as info:
        parse_target(spec)
    text = str(info.value)
    assert text.startswith(f"target spec {spec!r}")
    assert re.search(message, text), text
    assert "expected" in text  # every message shows the expected form or the allowed values


def test_constructed_targets_are_validated_and_normalized():
    target = parse_target(ChessboardTarget(9.0, 6, 1))
    assert type(target.cols) is int and type(target.square) is float
    assert object_points(target)[0].dtype.kind == "i"
    assert parse_target(AprilTagTarget("36h11", 0.05, np.int64(3))).id == 3


def test_constructed_targets_are_validated():
    with pytest.raises(ValueError, match=r"ChessboardTarget.cols: must be ≥ 3, got 1"):
        object_points(ChessboardTarget(1, 6, 0.02))
    with pytest.raises(ValueError, match=r"CharucoTarget.dictionary: use OpenCV's spelling "
                                         r"'DICT_6X6_250'"):
        object_points(CharucoTarget(5, 7, 0.04, 0.02, "dict_6x6_250"))
    with pytest.raises(ValueError, match=r"target: expected one of ChessboardTarget"):
        object_points(42)


# ----------------------------------------------------------------------------------------------
# Object points against OpenCV's own boards and detectors


def test_charuco_object_points_equal_opencv_board():
    for legacy in (False, True):
        target = CharucoTarget(6, 6, 0.03, 0.022, "DICT_5X5_100", legacy)
        ids, p = object_points(target)
        board = charuco_board(target)
        np.testing.assert_array_equal(ids, np.arange(25))
        np.testing.assert_allclose(p, board.getChessboardCorners(), atol=1e-7)


def test_aprilgrid_object_points_equal_opencv_grid_board():
    target = parse_target("aprilgrid:36h11:4x3:0.04:0.3:5")
    ids, p = object_points(target)
    board = grid_board(target)
    expected_ids = (4 * np.asarray(board.getIds()).reshape(-1, 1) + np.arange(4)).ravel()
    np.testing.assert_array_equal(ids, expected_ids)
    np.testing.assert_allclose(p, np.concatenate(board.getObjPoints()), atol=1e-7)


@pytest.mark.parametrize("spec", ["charuco:5x7:0.04:0.02:DICT_6X6_250",
                                  "charuco:6x6:0.04:0.02:DICT_6X6_250:legacy",
                                  "charuco:6x6:0.04:0.02:DICT_6X6_250"])
def test_charuco_render_is_pixel_identical_to_opencv_generate_image(spec):
    # 0.02 m marker of 6+2 cells → 2.5 mm cells; 4000 px/m gives 10 px per cell, where OpenCV's
    # generator is exact too.
    target = parse_target(spec)
    image, A = render_target(target, 4000.0)
    expected = charuco_board(target).generateImage((image.shape[1], image.shape[0]),
                                                   marginSize=0, borderBits=1)
    np.testing.assert_array_equal(image, expected)
    np.testing.assert_allclose(A, [[4000, 0, -0.5], [0, 4000, -0.5], [0, 0, 1]])


def test_aprilgrid_and_tag_render_match_opencv_generators():
    grid = parse_target("aprilgrid:36h11:3x2:0.04:0.25:2")  # 5 mm cells, 10 mm gaps
    image, _ = render_target(grid, 2000.0)
    expected = grid_board(grid).generateImage((image.shape[1], image.shape[0]), marginSize=0,
                                              borderBits=1)
    np.testing.assert_array_equal(image, expected)
    tag = parse_target("apriltag:36h11:0.08:10")
    image, A = render_target(tag, 1000.0)
    expected = get_dictionary("DICT_APRILTAG_36h11").generateImageMarker(10, 80, borderBits=1)
    np.testing.assert_array_equal(image, expected)
    # Corner 0 (top-left) of the tag at (−s/2, −s/2) maps to the image's top-left edge.
    np.testing.assert_allclose(A @ [-0.04, -0.04, 1.0], [-0.5, -0.5, 1.0])


def test_chessboard_object_points_follow_find_chessboard_corners_order():
    target = parse_target("chessboard:9x6:0.02")
    ids, p = object_points(target)
    image, A = render_target(target, 2500.0 * 1.37, margin=0.02)  # 68.5 px squares, off-grid
    expected = (p[:, :2] @ A[:2, :2].T) + A[:2, 2]
    for rot in range(4):  # the order is tied to the print, not to the image orientation
        img = np.rot90(image, rot).copy()
        found, corners = cv2.findChessboardCorners(img, (9, 6))
        assert found
        corners = cv2.cornerSubPix(img, corners, (7, 7), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
        h, w = image.shape
        exp = expected.copy()
        for _ in range(rot):  # np.rot90 (counter-clockwise) in pixel-centre coordinates
            exp = np.stack([exp[:, 1], (w - 1) - exp[:, 0]], axis=1)
            h, w = w, h
        np.testing.assert_allclose(corners.reshape(-1, 2), exp, atol=0.05)


def test_aruco_corners_follow_object_point_ids():
    for spec in ["apriltag:36h11:0.05:10", "aprilgrid:36h11:3x2:0.04:0.3:5"]:
        target = parse_target(spec)
        ids, p = object_points(target)
        image, A = render_target(target, 3000.0, margin=0.01)
        detector = cv2.aruco.ArucoDetector(get_dictionary(target_dictionary_name(target)))
        corners, marker_ids, _ = detector.detectMarkers(image)
        found = {}
        for c, m in zip(corners, marker_ids.ravel()):
            for k in range(4):
                found[4 * int(m) + k] = c.reshape(4, 2)[k]
        assert sorted(found) == ids.tolist()
        expected = p[:, :2] @ A[:2, :2].T + A[:2, 2]
        # ArUco's pixel-level corners sit within a pixel of the true outer border corners.
        np.testing.assert_allclose(np.array([found[i] for i in ids]), expected, atol=1.0)


# ----------------------------------------------------------------------------------------------
# Rendering scale and printable files


def _edges_along(profile: np.ndarray, half_window: int = 3) -> np.ndarray:
    """Sub-pixel positions (pixel-centre coordinates) of the black/white edges of a grey profile
    of an area-sampled image: the amount of black (or white) in a window around each crossing
    of mid-grey is the edge's distance from the window start."""
    v = profile.astype(float) / 255.0
    edges = []
    for i in np.nonzero(np.sign(v[:-1] - 0.5) != np.sign(v[1:] - 0.5))[0]:
        a, b = i - half_window + 1, i + half_window + 1
        window = v[a:b]
        dark_first = v[i] < v[i + 1]
        edges.append(a - 0.5 + np.sum(1.0 - window if dark_first else window))
    return np.array(edges)


def test_render_extent_margin_and_affine():
    target = parse_target("chessboard:9x6:0.0236")
    assert pattern_extent(target) == pytest.approx((-0.0236, -0.0236, 0.2124, 0.1416))
    ppm = 1234.5
    image, A = render_target(target, ppm, margin=0.01)
    assert image.shape == (int(np.ceil(0.1852 * ppm)), int(np.ceil(0.2560 * ppm)))
    # Inner corner (i, j) at A·(i s, j s): the crossings along the row through the middle of
    # the first square row are exactly at the column edges of the squares.
    row = int(round((A @ [0, -0.0118, 1])[1]))
    edges = _edges_along(image[row])
    expected = [(A @ [x, 0, 1])[0] for x in np.arange(-1, 9) * 0.0236]  # last square white
    np.testing.assert_allclose(edges, expected, atol=0.01)


def test_render_rejects_bad_arguments():
    with pytest.raises(ValueError, match=r"pixels_per_metre: expected a finite number > 0"):
        render_target("chessboard:9x6:0.02", 0.0)
    with pytest.raises(ValueError, match=r"margin: must be a finite length ≥ 0 m, got -1"):
        render_target("chessboard:9x6:0.02", 1000.0, margin=-1)
    with pytest.raises(ValueError, match=r"pixels_per_metre: .* more than 2e8 pixels"):
        render_target("chessboard:9x6:0.02", 1e6)


def test_write_printable_png_dpi_and_exact_scale(tmp_path):
    target = parse_target("charuco:5x7:0.036195:0.018256:DICT_6X6_250")
    paths = write_printable(target, tmp_path / "board.png", dpi=300, margin=0.01)
    assert [p.name for p in paths] == ["board.png", "board.svg", "board.pdf"]
    png, svg, pdf = paths
    assert png_pixels_per_metre(png) == (11811, 11811)  # 300 dpi
    from PIL import Image
    with Image.open(png) as im:  # an independent PNG reader sees the same DPI
        assert im.info["dpi"] == pytest.approx((300, 300), abs=0.01)
    image = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    ppm = 300 / 0.0254
    # The board spans 5 × 36.195 mm horizontally, after a 10 mm margin.
    assert image.shape[1] == int(np.ceil((5 * 0.036195 + 0.02) * ppm))
    # Measure squares along a row of the last row of squares above its markers (markers fill
    # the middle half of the white squares).
    row = int(round((0.01 + 6.1 * 0.036195) * ppm))
    edges = _edges_along(image[row])
    widths = np.diff(edges)
    square_px = 0.036195 * ppm  # 427.50 px
    assert len(widths) == 5  # the 5 squares of the row, between margin and margin
    np.testing.assert_allclose(widths, square_px, atol=0.01)
    np.testing.assert_allclose(edges[0], 0.01 * ppm - 0.5, atol=0.02)
    # The caption (spec + scale) is drawn below the board, not on it.
    assert image.shape[0] > int(np.ceil((7 * 0.036195 + 0.02) * ppm))
    text = svg.read_text()
    assert 'width="200.975000mm"' in text  # 5 squares + 2 margins
    assert "charuco:5x7:0.036195:0.018256:DICT_6X6_250" in text
    assert 'width="36.195000" height="36.195000"' in text
    mediabox = re.search(rb"/MediaBox \[\s*0 0 ([\d.]+) ([\d.]+)\s*\]", pdf.read_bytes())
    assert float(mediabox.group(1)) == pytest.approx(0.200975 / 0.0254 * 72, abs=0.01)


def test_write_printable_errors(tmp_path):
    with pytest.raises(ValueError, match=r"path: expected a .png file name"):
        write_printable("chessboard:9x6:0.02", tmp_path / "board.jpg")
    with pytest.raises(ValueError, match=r"path: directory .* does not exist"):
        write_printable("chessboard:9x6:0.02", tmp_path / "missing" / "board.png")
    with pytest.raises(ValueError, match=r"dpi: expected a finite number > 0"):
        write_printable("chessboard:9x6:0.02", tmp_path / "board.png", dpi=-3)


def test_vision_modules_do_not_load_drake():
    import subprocess
    import sys
    code = ("import sys\n"
            "import handeye_drake.vision.targets, handeye_drake.vision.intrinsics\n"
            "import handeye_drake.vision.detection\n"
            "assert not any(m.startswith('pydrake') for m in sys.modules), 'pydrake loaded'")
    subprocess.run([sys.executable, "-c", code], check=True)


def _board_in_mm(rng):
    """A plausible board (in metres) and its spec written in millimetres."""
    kind = ["chessboard", "charuco", "apriltag", "aprilgrid"][int(rng.integers(4))]
    square = float(np.round(rng.uniform(0.01, 0.08), 4))
    if kind == "chessboard":
        return f"chessboard:9x6:{square}", f"chessboard:9x6:{square * 1000:g}"
    if kind == "charuco":
        marker = float(np.round(0.75 * square, 4))
        return (f"charuco:7x5:{square}:{marker}:DICT_5X5_100",
                f"charuco:7x5:{square * 1000:g}:{marker * 1000:g}:DICT_5X5_100")
    if kind == "apriltag":
        return f"apriltag:36h11:{square}", f"apriltag:36h11:{square * 1000:g}"
    return (f"aprilgrid:36h11:6x6:{square}:0.3", f"aprilgrid:36h11:6x6:{square * 1000:g}:0.3")


@pytest.mark.parametrize("seed", range(8))
def test_sizes_in_millimetres_are_named_with_the_spec_in_metres(seed):
    metres, millimetres = _board_in_mm(np.random.default_rng(seed))
    with pytest.raises(ValueError) as info:
        parse_target(millimetres)
    text = str(info.value)
    assert text.startswith(f"target spec {millimetres!r}") and "\n" not in text
    assert "the sizes look like millimetres" in text and "translation-scale" not in text
    suggested = re.search(r"sizes are in metres: (\S+);", text).group(1)
    got, want = parse_target(suggested), parse_target(metres)
    assert type(got) is type(want) and all(
        a == (pytest.approx(b, rel=1e-12) if isinstance(b, float) else b)
        for a, b in zip(got.__dict__.values(), want.__dict__.values()))


def test_a_board_too_large_to_be_millimetres_is_refused_naming_its_size():
    with pytest.raises(ValueError, match=r"the pattern would be 11.2 m × 8 m, larger than the 10 "
                                         r"m a target may be \(sizes are in metres\)"):
        parse_target("charuco:7x5:1.6:1.2:DICT_5X5_100")
    with pytest.raises(ValueError, match=r"ChessboardTarget: the sizes look like millimetres"):
        object_points(ChessboardTarget(9, 6, 24.0))
    assert parse_target("charuco:7x5:1.4:1:DICT_5X5_100").square == 1.4  # 9.8 m: taken
