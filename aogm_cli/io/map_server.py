"""ROS map_server maps in: reads a map YAML and its image as ROS1 map_server does.

Grids here follow the OccupancyGrid convention of aogm_cli.core.grid: row 0 is the lowest y;
``aogm_cli.io.map_saver`` writes what map_saver writes.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, UnidentifiedImageError

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.io.yamlfile import read_yaml

MODES = ("trinary", "scale", "raw")

# What map_saver writes into every YAML: 0 / 254 / 205 pixels read back as 100 / 0 / -1.
MAP_SAVER_OCCUPIED_THRESH = 0.65
MAP_SAVER_FREE_THRESH = 0.196
PGM_OCCUPIED, PGM_FREE, PGM_UNKNOWN = 0, 254, 205


@dataclass(frozen=True, eq=False)
class RosMap:
    """A map as ROS1 map_server loads it from a YAML file and its image.

    ``data`` (H, W) int8 is the nav_msgs/OccupancyGrid data: row 0 is the bottom image row
    (lowest y); trinary mode gives 100 occupied, 0 free, -1 unknown; scale mode adds 1..99
    between the thresholds; raw mode gives the (negated) pixel mean, stored as int8 exactly
    as ROS does (so pixel 255 reads as -1). ``occupancy_probability`` (H, W) float64 is
    map_server's ``occ = (255 - mean) / 255`` per pixel before thresholding (after negate),
    computed in every mode. ``origin`` is (x, y, yaw) of the lower-left corner of cell [0, 0];
    ``image`` is the absolute path of the image. Both arrays are read-only.
    """

    data: np.ndarray
    occupancy_probability: np.ndarray
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str
    image: str

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    def grid_spec(self) -> GridSpec:
        """The aogm grid of this map: origin x, y, resolution and shape.

        The yaw of ``origin`` is NOT applied: aogm grids are axis-aligned, so a map whose yaw
        is not 0 is treated as if it were 0 (callers that care should check ``origin[2]``).
        """
        return GridSpec(float(self.origin[0]), float(self.origin[1]), float(self.resolution), self.height, self.width)

    def occupied(self) -> np.ndarray:
        """Boolean (H, W): cells whose value is 100 (the occupied cells of a trinary map)."""
        return self.data == 100


# --------------------------------------------------------------------------------------------
# Reading


def read_map_yaml(path: str | Path) -> RosMap:
    """Read a ROS map_server YAML and its image exactly as ROS1 map_server (Noetic) does.

    Keys: ``image`` (relative to the YAML's folder, or absolute), ``resolution``, ``origin``
    [x, y, yaw], ``negate``, ``occupied_thresh``, ``free_thresh`` are required; ``mode``
    (trinary, scale or raw) defaults to trinary; other keys are ignored, as map_server does.
    Stricter than map_server: resolution must be positive, thresholds must satisfy
    0 <= free_thresh <= occupied_thresh <= 1, origin must have exactly three numbers.

    Raises
    ------
    InputError
        Naming the file and the key, for a missing file, invalid YAML, a missing or invalid
        key, or an image that is missing or cannot be read.
    """
    path = Path(path)
    file = str(path)
    _, doc = read_yaml(path)
    if not isinstance(doc, dict):
        raise InputError(f"expected a mapping of map_server keys, got {_describe(doc)}", file=file)

    resolution = _number(doc, "resolution", file)
    if resolution <= 0:
        raise InputError(f"expected a positive number, got {resolution!r}", file=file, key="resolution")
    negate = _negate(doc, file)
    occupied_thresh, free_thresh = _thresholds(doc, file)
    mode = _mode(doc, file)
    origin = _origin(doc, file)
    image = _image_path(doc, path, file)

    pixels, has_alpha_channel = _load_image(image, file)
    data, probability = pixels_to_occupancy(
        pixels,
        has_alpha_channel,
        negate=negate,
        occupied_thresh=occupied_thresh,
        free_thresh=free_thresh,
        mode=mode,
    )
    data.setflags(write=False)
    probability.setflags(write=False)
    return RosMap(
        data=data,
        occupancy_probability=probability,
        resolution=resolution,
        origin=origin,
        negate=negate,
        occupied_thresh=occupied_thresh,
        free_thresh=free_thresh,
        mode=mode,
        image=image,
    )


def _thresholds(doc: dict, file: str) -> tuple[float, float]:
    """(occupied_thresh, free_thresh), each in [0, 1] and free below occupied."""
    occupied_thresh = _number(doc, "occupied_thresh", file)
    free_thresh = _number(doc, "free_thresh", file)
    for key, value in (("occupied_thresh", occupied_thresh), ("free_thresh", free_thresh)):
        if not 0.0 <= value <= 1.0:
            raise InputError(f"expected a number in [0, 1], got {value!r}", file=file, key=key)
    if free_thresh > occupied_thresh:
        raise InputError(
            f"expected free_thresh <= occupied_thresh ({occupied_thresh!r}), got {free_thresh!r}",
            file=file,
            key="free_thresh",
        )
    return occupied_thresh, free_thresh


def pixels_to_occupancy(
    pixels: np.ndarray,
    has_alpha_channel: bool,
    *,
    negate: bool,
    occupied_thresh: float,
    free_thresh: float,
    mode: str = "trinary",
) -> tuple[np.ndarray, np.ndarray]:
    """The loop of map_server's ``loadMapFromFile`` on image bytes, vectorised.

    ``pixels`` (H, W) or (H, W, C) uint8: each pixel's bytes in SDL_image's order, top image row
    first; ``has_alpha_channel``: SDL gave the surface an alpha mask (the last byte); the rest as
    in the YAML. Returns (data (H, W) int8, occupancy_probability (H, W) float64), row 0 = bottom.

    Notes
    -----
    Per pixel: ``mean`` = mean of all C bytes (trinary mode, or no alpha mask) or of the first
    C-1 bytes (scale/raw with an alpha mask); ``mean = 255 - mean`` when negate;
    ``occ = (255 - mean) / 255``. Trinary: 100 if occ > occupied_thresh, 0 if
    occ < free_thresh, else -1. Scale: the same, except that between the thresholds a pixel
    whose last byte is not 0 (always, for one-byte pixels) gets ``int(1 + 98 * ratio)``,
    ``ratio = (occ - free) / (occupied - free)``, and one whose last byte is 0 gets -1 — even
    when that byte is blue, not alpha, as in map_server. Raw: ``int(mean)`` as int8.

    Examples
    --------
    >>> data, occ = pixels_to_occupancy(np.array([[0, 128, 255]], np.uint8), False,
    ...                                 negate=False, occupied_thresh=0.65, free_thresh=0.196)
    >>> data
    array([[100,  -1,   0]], dtype=int8)
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    pixels = np.asarray(pixels)
    if pixels.dtype != np.uint8:
        raise ValueError(f"pixels must be uint8, got {pixels.dtype}")
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[2] < 1:
        raise ValueError(f"pixels must have shape (H, W) or (H, W, C), got {pixels.shape}")
    n_channels = pixels.shape[2]
    avg_channels = n_channels if (mode == "trinary" or not has_alpha_channel) else n_channels - 1
    color_sum = pixels[:, :, :avg_channels].sum(axis=2, dtype=np.int64)
    color_avg = color_sum / float(avg_channels)
    if negate:
        color_avg = 255 - color_avg
    occ = (255 - color_avg) / 255.0

    if mode == "raw":
        data = color_avg.astype(np.uint8).view(np.int8)  # C: unsigned char value = color_avg
    else:
        last = None if n_channels == 1 else pixels[:, :, n_channels - 1]
        data = _classified(occ, occupied_thresh, free_thresh, last if mode == "scale" else None, mode == "scale")
    return np.ascontiguousarray(data[::-1]), np.ascontiguousarray(occ[::-1])


def _classified(occ: np.ndarray, occupied_thresh: float, free_thresh: float, last: np.ndarray | None,
                scale: bool) -> np.ndarray:
    """map_server's trinary values of ``occ`` (100, 0, -1), and with ``scale`` 1..99 between the
    thresholds where the pixel's last byte (``last``; None: one-byte pixels) is not 0."""
    data = np.full(occ.shape, -1, dtype=np.int8)
    is_occupied = occ > occupied_thresh
    is_free = ~is_occupied & (occ < free_thresh)
    data[is_occupied] = 100
    data[is_free] = 0
    if scale:
        opaque = np.ones(occ.shape, bool) if last is None else last >= 1
        between = ~is_occupied & ~is_free & opaque
        if occupied_thresh > free_thresh:
            ratio = (occ[between] - free_thresh) / (occupied_thresh - free_thresh)
            data[between] = (1 + 98 * ratio).astype(np.uint8)
        # equal thresholds: map_server divides 0 by 0 there; we leave those cells at -1
    return data


def _describe(value: Any) -> str:
    if value is None:
        return "nothing"
    return f"{type(value).__name__} {value!r}"


def _number(doc: dict, key: str, file: str) -> float:
    """A finite number; numeric strings are accepted, as yaml-cpp's ``as<double>`` does."""
    if key not in doc:
        raise InputError("missing key (map_server requires it)", file=file, key=key)
    return finite_number(doc[key], key, file)


def finite_number(value: Any, key: str, file: str | None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise InputError(f"expected a number, got {_describe(value)}", file=file, key=key)
    try:
        number = float(value)
    except ValueError:
        raise InputError(f"expected a number, got {_describe(value)}", file=file, key=key) from None
    if not math.isfinite(number):
        raise InputError(f"expected a finite number, got {value!r}", file=file, key=key)
    return number


def _negate(doc: dict, file: str) -> bool:
    """map_server reads negate as an int (non-zero means negate); true/false are accepted too."""
    if "negate" not in doc:
        raise InputError("missing key (map_server requires it)", file=file, key="negate")
    value = doc["negate"]
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return value != 0
    if isinstance(value, str) and re.fullmatch(r"\s*[-+]?\d+\s*", value):
        return int(value) != 0
    raise InputError(f"expected 0 or 1, got {_describe(value)}", file=file, key="negate")


def _mode(doc: dict, file: str) -> str:
    if "mode" not in doc:
        return "trinary"
    value = doc["mode"]
    if not isinstance(value, str) or value not in MODES:
        raise InputError(f"expected one of trinary, scale, raw, got {_describe(value)}", file=file, key="mode")
    return value


def _origin(doc: dict, file: str) -> tuple[float, float, float]:
    if "origin" not in doc:
        raise InputError("missing key (map_server requires it)", file=file, key="origin")
    value = doc["origin"]
    if not isinstance(value, list) or len(value) != 3:
        raise InputError(f"expected [x, y, yaw], got {_describe(value)}", file=file, key="origin")
    x, y, yaw = (finite_number(v, f"origin[{i}]", file) for i, v in enumerate(value))
    return (x, y, yaw)


def _image_path(doc: dict, yaml_path: Path, file: str) -> str:
    if "image" not in doc:
        raise InputError("missing key (map_server requires it)", file=file, key="image")
    value = doc["image"]
    if not isinstance(value, str):
        raise InputError(f"expected a file name, got {_describe(value)}", file=file, key="image")
    if not value:
        raise InputError("the image file name cannot be empty", file=file, key="image")
    if os.path.isabs(value):
        return os.path.abspath(value)
    return os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(yaml_path)), value))


# --------------------------------------------------------------------------------------------
# Image bytes as SDL_image 1.2 (the loader of ROS1 map_server) stores them


def _load_image(image: str, file: str) -> tuple[np.ndarray, bool]:
    if not os.path.exists(image):
        raise InputError(f"image file {image} does not exist", file=file, key="image")
    try:
        with Image.open(image) as img:
            fmt = img.format or ""
            tile_args = img.tile[0][3] if img.tile else None
            img.load()
            return _sdl_pixels(img, fmt, tile_args, image, file)
    except InputError:
        raise
    except (OSError, ValueError, SyntaxError, UnidentifiedImageError, Image.DecompressionBombError) as exc:
        raise InputError(f"cannot read image {image}: {exc}", file=file, key="image") from None


def _sdl_pixels(img: Image.Image, fmt: str, tile_args: Any, image: str, file: str) -> tuple[np.ndarray, bool]:
    """(H, W, C) uint8 bytes as SDL_image 1.2 lays them out, and whether SDL sets an alpha mask.

    Faithful for the usual map images: PNG (grey of any depth, grey+alpha, RGB, RGBA, palette:
    palette images give the palette INDEX, as SDL keeps them 8-bit indexed), BMP up to 24 bit
    (<= 8 bit: palette index; 24 bit: B, G, R byte order), PGM/PPM/PBM (maxval <= 255, scaled
    down with integer division as SDL_image does; PBM gives 1 for black, 0 for white).
    Other formats are best effort.
    """
    mode = img.mode
    if fmt == "PNG":
        return _png_pixels(img, image)
    if fmt == "BMP":
        if mode in ("1", "L", "P"):  # SDL keeps <= 8 bit BMPs indexed
            return np.asarray(img).astype(np.uint8)[:, :, None], False
        if mode == "RGBA":
            arr = np.asarray(img)
            return np.ascontiguousarray(arr[:, :, [2, 1, 0, 3]]), True
        return np.ascontiguousarray(np.asarray(img.convert("RGB"))[:, :, ::-1]), False
    if fmt == "PPM":
        if mode == "1":  # PBM: SDL stores the file's bit, 1 = black
            return (~np.asarray(img)).astype(np.uint8)[:, :, None], False
        maxval = tile_args[-1] if isinstance(tile_args, tuple) and isinstance(tile_args[-1], int) else 255
        if mode in ("I", "I;16", "I;16B") or maxval > 255:
            raise InputError(
                f"cannot read image {image}: maxval {maxval} > 255 (ROS1 map_server's SDL_image refuses it)",
                file=file,
                key="image",
            )
        arr = np.asarray(img.convert("RGB") if mode not in ("L", "RGB") else img).astype(np.int64)
        if maxval < 255:
            raw = np.rint(arr * maxval / 255.0)  # Pillow rounded raw*255/maxval; this inverts it
            arr = (raw * 255) // maxval  # SDL_image: row[i] * 255 / maxval (integer division)
        arr = arr.astype(np.uint8)
        return (arr[:, :, None], False) if arr.ndim == 2 else (arr, False)
    if fmt == "JPEG":  # SDL_image decodes every JPEG to 24-bit RGB
        return np.asarray(img.convert("RGB")), False
    if fmt == "TIFF":  # SDL_image decodes every TIFF to 32-bit RGBA
        return np.asarray(img.convert("RGBA")), True
    if mode == "P":  # GIF, PCX, TGA ...: SDL keeps 8-bit images indexed
        return np.asarray(img).astype(np.uint8)[:, :, None], False
    if mode in ("1", "L"):
        return np.asarray(img.convert("L"))[:, :, None], False
    if mode == "LA":
        return _la_as_rgba(np.asarray(img)), True
    if mode == "RGBA" or "A" in mode or "transparency" in img.info:
        return np.asarray(img.convert("RGBA")), True
    return np.asarray(img.convert("RGB")), False


def _la_as_rgba(arr: np.ndarray) -> np.ndarray:
    grey, alpha = arr[:, :, 0], arr[:, :, 1]
    return np.stack([grey, grey, grey, alpha], axis=2)


def _png_header(image: str) -> tuple[int, int]:
    """(bit depth, colour type) from the PNG's IHDR chunk."""
    with open(image, "rb") as fh:
        head = fh.read(26)
    if len(head) < 26:
        return 8, -1
    return head[24], head[25]


def _png_pixels(img: Image.Image, image: str) -> tuple[np.ndarray, bool]:
    """SDL_image's IMG_png.c: strip 16 bit to the high byte, expand grey to 8 bit, tRNS of a
    grey image becomes a second (alpha) byte without alpha mask, grey+alpha becomes RGBA,
    palette images stay indexed unless tRNS has several transparent or translucent entries."""
    mode = img.mode
    trns = img.info.get("transparency")
    if mode in ("1", "L", "I", "I;16", "I;16B", "I;16L"):
        bit_depth, _ = _png_header(image)
        if mode == "1":
            grey = np.asarray(img.convert("L"))
            raw, key = grey, (None if trns is None else (255 if trns else 0))
        elif mode == "L":
            grey = np.asarray(img)
            raw = grey
            key = None
            if isinstance(trns, int):
                key = trns * (255 // ((1 << bit_depth) - 1)) if bit_depth < 8 else trns
        else:
            raw = np.asarray(img).astype(np.int64)
            grey = (raw >> 8).astype(np.uint8)  # png_set_strip_16 keeps the high byte
            key = trns if isinstance(trns, int) else None
        if key is None:
            return grey[:, :, None], False
        alpha = np.where(raw == key, 0, 255).astype(np.uint8)
        return np.stack([grey, alpha], axis=2), False
    if mode == "LA":
        return _la_as_rgba(np.asarray(img)), True
    if mode == "P":
        if isinstance(trns, bytes) and not _sdl_keeps_palette(trns):
            return np.asarray(img.convert("RGBA")), True
        return np.asarray(img).astype(np.uint8)[:, :, None], False
    if mode == "RGBA":
        return np.asarray(img), True
    return np.asarray(img.convert("RGB")), False


def _sdl_keeps_palette(trns: bytes) -> bool:
    """True when every tRNS entry is 255 except at most one 0 (SDL then uses a colour key)."""
    transparent = -1
    for index, value in enumerate(trns):
        if value == 0:
            if transparent >= 0:
                return False
            transparent = index
        elif value != 255:
            return False
    return True
