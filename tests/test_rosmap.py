"""ROS map_server maps (``io.map_server``, ``io.map_saver``): map_server conformance, the turtlebot3
map, write/read round trips."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from PIL import Image

from aogm_cli.core.errors import InputError, OutputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.io.map_saver import write_map
from aogm_cli.io.map_server import RosMap, pixels_to_occupancy, read_map_yaml

TESTMAPS = Path("data/ros_map_server_testmaps")  # in ../shared: require.shared(TESTMAPS / name)
TURTLEBOT = Path("data/floorplans/turtlebot3_world/map.yaml")


def write_yaml(folder: Path, image: str | None, name: str = "m.yaml", **overrides) -> Path:
    """A map_server YAML in ``folder``; a key given as None is left out."""
    keys = {
        "image": image,
        "resolution": "0.1",
        "origin": "[0.0, 0.0, 0.0]",
        "negate": "0",
        "occupied_thresh": "0.65",
        "free_thresh": "0.196",
    }
    keys.update(overrides)
    text = "".join(f"{k}: {v}\n" for k, v in keys.items() if v is not None)
    path = folder / name
    path.write_text(text)
    return path


# ------------------------------------------------------------------ map_server conformance


@pytest.mark.parametrize("name", ["testmap.yaml", "testmap2.yaml"])
def test_map_server_testmaps_match_expected(require, name):
    expected = json.loads(require.shared(TESTMAPS / "expected.json").read_text())[name]
    m = read_map_yaml(require.shared(TESTMAPS / name))
    assert m.width == expected["width"] and m.height == expected["height"]
    assert m.resolution == pytest.approx(expected["resolution"])
    assert m.origin == pytest.approx(tuple(expected["origin"]))
    assert m.mode == "trinary"
    assert m.data.dtype == np.int8
    assert_array_equal(m.data, np.array(expected["data_rows_bottom_first"], dtype=np.int8))


def test_bmp_testmap_loads_like_the_png_and_absolute_image_path_works(require, tmp_path):
    expected = json.loads(require.shared(TESTMAPS / "expected.json").read_text())["testmap.yaml"]
    bmp = require.shared(TESTMAPS / "testmap.bmp")
    path = write_yaml(tmp_path, str(bmp), origin="[2.0, 3.0, 1.0]")
    m = read_map_yaml(path)
    assert m.image == str(bmp)
    assert_array_equal(m.data, np.array(expected["data_rows_bottom_first"], dtype=np.int8))


def spectrum(require, tmp_path: Path, **overrides) -> RosMap:
    return read_map_yaml(write_yaml(tmp_path, str(require.shared(TESTMAPS / "spectrum.png")), **overrides))


def test_spectrum_trinary_thresholds_are_strict(require, tmp_path):
    # spectrum.png: 16x16 grey, the bottom image row is 0..15, the top one 240..255; so with
    # row 0 = bottom image row, the pixel under data[r, c] is 16 r + c.
    m = spectrum(require, tmp_path)
    pixel = np.arange(256).reshape(16, 16)
    # occ = (255 - v)/255: v <= 89 gives occ > 0.65; v >= 206 gives occ < 0.196;
    # v = 205 gives occ = 50/255 = 0.19608, not < 0.196, so unknown.
    expected = np.where(pixel <= 89, 100, np.where(pixel >= 206, 0, -1))
    assert_array_equal(m.data, expected)
    assert m.occupancy_probability[pixel == 205][0] == pytest.approx(50 / 255)
    assert_array_equal(m.occupied(), pixel <= 89)


def test_spectrum_scale_and_raw_modes(require, tmp_path):
    m = spectrum(require, tmp_path, mode="scale")
    pixel = np.arange(256).reshape(16, 16)
    value = dict(zip(pixel.ravel().tolist(), m.data.ravel().tolist(), strict=True))
    assert value[89] == 100 and value[206] == 0
    assert value[150] == 47  # occ 105/255, ratio 0.47525, int(1 + 98 * 0.47525) = 47
    assert value[100] == 89  # occ 155/255, ratio 0.90714, int(89.9) = 89
    assert value[205] == 1  # ratio 0.0002 -> 1
    raw = spectrum(require, tmp_path, mode="raw")
    assert_array_equal(raw.data, pixel.astype(np.uint8).view(np.int8))  # 255 reads as -1, 200 as -56
    negated = spectrum(require, tmp_path, mode="raw", negate="1")
    assert_array_equal(negated.data, (255 - pixel).astype(np.uint8).view(np.int8))


# ------------------------------------------------------------------ the pixel loop on tiny cases


def test_pixels_alpha_is_averaged_in_trinary_but_not_in_scale():
    # grey + alpha as SDL stores it: R, G, B, A. White fully transparent.
    px = np.array([[[255, 255, 255, 0]]], np.uint8)
    data, occ = pixels_to_occupancy(px, True, negate=False, occupied_thresh=0.65, free_thresh=0.196, mode="trinary")
    assert occ[0, 0] == pytest.approx((255 - 191.25) / 255) and data[0, 0] == -1
    data, occ = pixels_to_occupancy(px, True, negate=False, occupied_thresh=0.65, free_thresh=0.196, mode="scale")
    assert occ[0, 0] == 0.0 and data[0, 0] == 0
    # Mid grey, transparent: -1 in scale mode; opaque: scaled.
    px = np.array([[[100, 100, 100, 0], [100, 100, 100, 255]]], np.uint8)
    data, _ = pixels_to_occupancy(px, True, negate=False, occupied_thresh=0.65, free_thresh=0.196, mode="scale")
    assert_array_equal(data, [[-1, 89]])


def test_pixels_last_byte_zero_counts_as_transparent_in_scale_mode_as_in_map_server():
    # RGB without alpha mask: map_server still reads the last byte as "alpha".
    px = np.array([[[150, 150, 0], [100, 100, 100]]], np.uint8)  # both have mean 100
    data, _ = pixels_to_occupancy(px, False, negate=False, occupied_thresh=0.65, free_thresh=0.196, mode="scale")
    assert_array_equal(data, [[-1, 89]])


def test_pixels_negate_and_row_order():
    px = np.array([[0], [255]], np.uint8)  # top black, bottom white
    data, _ = pixels_to_occupancy(px, False, negate=False, occupied_thresh=0.65, free_thresh=0.196)
    assert_array_equal(data, [[0], [100]])  # row 0 = bottom image row = white = free
    data, _ = pixels_to_occupancy(px, False, negate=True, occupied_thresh=0.65, free_thresh=0.196)
    assert_array_equal(data, [[100], [0]])


# ------------------------------------------------------------------ image formats as SDL_image reads them


def test_palette_png_and_low_depth_bmp_give_palette_index(tmp_path):
    img = Image.new("P", (2, 1))
    img.putpalette([255, 255, 255, 0, 0, 0])  # index 0 white, index 1 black
    img.putpixel((0, 0), 0)
    img.putpixel((1, 0), 1)
    img.save(tmp_path / "p.png")
    m = read_map_yaml(write_yaml(tmp_path, "p.png", mode="raw"))
    assert_array_equal(m.data, [[0, 1]])
    bmp = Image.new("1", (2, 1))
    bmp.putpixel((1, 0), 1)
    bmp.save(tmp_path / "b.bmp")
    m = read_map_yaml(write_yaml(tmp_path, "b.bmp", mode="raw"))
    assert_array_equal(m.data, [[0, 1]])


def test_pgm_with_small_maxval_scales_like_sdl_image(tmp_path):
    (tmp_path / "g.pgm").write_bytes(b"P5\n3 1\n100\n" + bytes([1, 50, 100]))
    m = read_map_yaml(write_yaml(tmp_path, "g.pgm", mode="raw"))
    assert_array_equal(m.data.view(np.uint8), [[2, 127, 255]])  # v * 255 // 100


def test_pbm_gives_the_file_bit(tmp_path):
    (tmp_path / "b.pbm").write_bytes(b"P1\n2 1\n1 0\n")
    m = read_map_yaml(write_yaml(tmp_path, "b.pbm", mode="raw"))
    assert_array_equal(m.data, [[1, 0]])


def test_sixteen_bit_pgm_is_refused(tmp_path):
    (tmp_path / "g.pgm").write_bytes(b"P5\n1 1\n65535\n\x00\x01")
    with pytest.raises(InputError) as err:
        read_map_yaml(write_yaml(tmp_path, "g.pgm"))
    assert err.value.key == "image"


# ------------------------------------------------------------------ turtlebot3 map_saver output


def test_turtlebot3_map_loads(require):
    turtlebot = require.shared(TURTLEBOT)
    m = read_map_yaml(turtlebot)
    assert (m.height, m.width) == (384, 384)
    assert m.resolution == pytest.approx(0.05)
    assert m.origin == pytest.approx((-10.0, -10.0, 0.0))
    assert m.grid_spec() == GridSpec(-10.0, -10.0, 0.05, 384, 384)
    pgm = np.asarray(Image.open(turtlebot.parent / "map.pgm"))
    assert set(np.unique(pgm).tolist()) == {0, 205, 254}
    assert (m.data == 100).sum() == (pgm == 0).sum() > 0
    assert (m.data == 0).sum() == (pgm == 254).sum() > 0
    assert (m.data == -1).sum() == (pgm == 205).sum() > 0
    assert_array_equal(m.data[::-1] == 100, pgm == 0)


def test_rosmap_is_frozen_and_read_only(require):
    m = read_map_yaml(require.shared(TESTMAPS / "testmap.yaml"))
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.resolution = 1.0
    with pytest.raises(ValueError):
        m.data[0, 0] = 5


# ------------------------------------------------------------------ writing and round trips


PROB = np.array(
    [
        [0.0, 0.1, 0.196, 0.3, 0.5],
        [0.65, 0.66, 0.9, 1.0, 0.195],
        [0.42, 0.8, 0.05, 0.7, 0.2],
    ]
)
OBSERVED = np.array(
    [
        [True, True, True, True, True],
        [True, True, True, True, True],
        [False, False, True, True, False],
    ]
)
# p > 0.65 occupied, p < 0.196 free, else (and wherever unobserved) unknown.
TRINARY = np.array(
    [
        [0, 0, -1, -1, -1],
        [-1, 100, 100, 100, 0],
        [-1, -1, 0, 100, -1],
    ],
    dtype=np.int8,
)


def test_write_map_round_trip_trinary(tmp_path):
    paths = write_map(tmp_path / "out", PROB, OBSERVED, 0.25, (1.5, -2.0))
    assert paths == [tmp_path / n for n in ("out.pgm", "out.yaml", "out.png", "out_scale.yaml")]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in paths)  # no temporaries left
    assert (tmp_path / "out.pgm").read_bytes().startswith(b"P5\n")
    pgm = np.asarray(Image.open(tmp_path / "out.pgm"))
    assert pgm[0, 3] == 0 and pgm[-1, 0] == 254 and pgm[0, 0] == 205  # top image row = highest y
    m = read_map_yaml(tmp_path / "out.yaml")
    assert m.mode == "trinary"
    assert m.image == str(tmp_path / "out.pgm")
    assert m.grid_spec() == GridSpec(1.5, -2.0, 0.25, 3, 5)
    assert m.origin == (1.5, -2.0, 0.0)
    assert_array_equal(m.data, TRINARY)


def test_write_map_round_trip_scale_png(tmp_path):
    write_map(tmp_path / "out", PROB, OBSERVED, 0.25, (1.5, -2.0, 0.0))
    assert Image.open(tmp_path / "out.png").mode == "LA"
    m = read_map_yaml(tmp_path / "out_scale.yaml")
    assert m.mode == "scale" and m.image == str(tmp_path / "out.png")
    assert np.all(np.abs(m.occupancy_probability[OBSERVED] - PROB[OBSERVED]) <= 1 / 255)
    assert np.all(m.data[~OBSERVED] == -1)
    assert_array_equal(m.data[OBSERVED & (PROB > 0.66)], 100)
    assert_array_equal(m.data[OBSERVED & (PROB < 0.19)], 0)
    between = m.data[OBSERVED & (PROB > 0.2) & (PROB < 0.6)]
    assert np.all((between >= 1) & (between <= 99))


def test_write_map_custom_thresholds(tmp_path):
    write_map(tmp_path / "c", PROB, OBSERVED, 0.1, (0.0, 0.0), occupied_thresh=0.85, free_thresh=0.35)
    m = read_map_yaml(tmp_path / "c.yaml")
    expected = np.full(PROB.shape, -1, np.int8)
    expected[OBSERVED & (PROB > 0.85)] = 100
    expected[OBSERVED & (PROB < 0.35)] = 0
    assert_array_equal(m.data, expected)
    s = read_map_yaml(tmp_path / "c_scale.yaml")
    assert (s.occupied_thresh, s.free_thresh) == (0.85, 0.35)
    assert np.all(s.data[~OBSERVED] == -1)


def test_write_map_leaves_nothing_on_failure(tmp_path, monkeypatch):
    bad = PROB.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError) as err:
        write_map(tmp_path / "out", bad, OBSERVED, 0.25, (0.0, 0.0))
    assert err.value.key == "probability"
    assert list(tmp_path.iterdir()) == []

    import aogm_cli.io.atomic as atomic

    real = atomic._temporary_beside
    calls = []

    def failing(target):
        calls.append(target)
        if len(calls) == 3:
            raise OSError("disk full")
        return real(target)

    monkeypatch.setattr(atomic, "_temporary_beside", failing)
    with pytest.raises(OutputError, match="disk full"):
        write_map(tmp_path / "out", PROB, OBSERVED, 0.25, (0.0, 0.0))
    assert list(tmp_path.iterdir()) == []


def test_write_map_rejects_bad_arguments(tmp_path):
    with pytest.raises(InputError) as err:
        write_map(tmp_path / "out", PROB, OBSERVED, -0.1, (0.0, 0.0))
    assert err.value.key == "resolution"
    with pytest.raises(InputError) as err:
        write_map(tmp_path / "out", PROB, OBSERVED[:2], 0.1, (0.0, 0.0))
    assert err.value.key == "observed"
    with pytest.raises(InputError):
        write_map(tmp_path / "missing" / "out", PROB, OBSERVED, 0.1, (0.0, 0.0))
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ bad input


@pytest.fixture
def grey_png(tmp_path) -> Path:
    Image.new("L", (2, 2), 255).save(tmp_path / "g.png")
    return tmp_path


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"resolution": None}, "resolution"),
        ({"resolution": "-0.05"}, "resolution"),
        ({"resolution": "abc"}, "resolution"),
        ({"negate": None}, "negate"),
        ({"negate": "maybe"}, "negate"),
        ({"occupied_thresh": None}, "occupied_thresh"),
        ({"free_thresh": "1.5"}, "free_thresh"),
        ({"free_thresh": "0.9"}, "free_thresh"),
        ({"mode": "fancy"}, "mode"),
        ({"origin": "[1.0, 2.0]"}, "origin"),
        ({"origin": "[1.0, x, 0.0]"}, "origin[1]"),
        ({"image": None}, "image"),
        ({"image": '""'}, "image"),
        ({"image": "nothere.png"}, "image"),
    ],
)
def test_bad_yaml_names_the_key(grey_png, overrides, key):
    overrides = dict(overrides)
    path = write_yaml(grey_png, overrides.pop("image", "g.png"), **overrides)
    with pytest.raises(InputError) as err:
        read_map_yaml(path)
    assert err.value.key == key
    assert err.value.file == str(path)
    assert str(path) in str(err.value) and key in str(err.value)


def test_unknown_keys_are_ignored_and_image_is_relative_to_the_yaml(grey_png):
    sub = grey_png / "maps"
    sub.mkdir()
    path = write_yaml(sub, "../g.png", extra_key="whatever")
    m = read_map_yaml(path)
    assert m.image == str(grey_png / "g.png")
    assert_array_equal(m.data, np.zeros((2, 2), np.int8))


def test_unreadable_image_and_bad_files(tmp_path):
    (tmp_path / "junk.png").write_text("not an image")
    with pytest.raises(InputError) as err:
        read_map_yaml(write_yaml(tmp_path, "junk.png"))
    assert err.value.key == "image" and "junk.png" in str(err.value)

    with pytest.raises(InputError) as err:
        read_map_yaml(tmp_path / "absent.yaml")
    assert err.value.file == str(tmp_path / "absent.yaml")

    broken = tmp_path / "broken.yaml"
    broken.write_text("image: [unclosed\nresolution: 0.1\n")
    with pytest.raises(InputError, match="not valid YAML") as err:
        read_map_yaml(broken)
    assert err.value.file == str(broken)

    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("just text\n")
    with pytest.raises(InputError, match="expected a mapping"):
        read_map_yaml(scalar)
