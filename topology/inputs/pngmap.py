"""Map PNGs read with care: sized from their header before anything is decoded.

A map is a PNG whose dark pixels are walls (testbed.world.worldmap for the robots' world,
topology.radio.los for the radio). It may come from anywhere, so `read_gray(path)` checks it in
the order that costs least, and refuses with one line (`PngError`) at the first problem:

1. a regular file (a directory, a FIFO or a device is named as such, never opened for a
   read that could block or never end), of at most MAX_FILE_BYTES;
2. the PNG signature and the IHDR chunk, which give the picture's size: at most
   MAX_MAP_PIXELS pixels, checked before a single pixel is decoded;
3. every chunk whole, its CRC right, up to IEND: a truncated or damaged file is refused
   here, so that libpng never gets to print its own complaint on the terminal;
4. only then OpenCV decodes it (grey), from the bytes already read; anything libpng still
   says on stderr meanwhile is discarded, since our one line says what went wrong.

Why MAX_MAP_PIXELS = 16 million: the world's grid is at most 4000 x 4000 cells
(testbed.world.worldmap), and the los models use the picture at its own resolution, so a
larger picture is more than either can use; decoding one costs at most 64 MB (RGBA), and the
los walls keep two bytes a pixel. A 20000 x 20000 picture (400 million pixels, 849 MB to
decode, 1.24 GB for every `net move` under los) is refused from its first 33 bytes.
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
import zlib

import numpy as np

from common import boundedfile

MAX_MAP_PIXELS = 16_000_000
# The largest such picture stored uncompressed at 16 bits per channel (RGBA), and a margin.
MAX_FILE_BYTES = 8 * MAX_MAP_PIXELS + (1 << 20)
SIGNATURE = b"\x89PNG\r\n\x1a\n"


class PngError(ValueError):
    """A map file that is not a PNG this testbed reads; its message is one line."""


def check(path: str, max_pixels: int = MAX_MAP_PIXELS) -> tuple[int, int, bytes]:
    """(width, height, the file's bytes) of a PNG that passes steps 1 to 3; PngError if not."""
    what = f"map file {path}"
    size: list[int] = []

    def header(fd: int, _st) -> None:  # the picture's size, before its bytes are read
        width, height = _ihdr(os.pread(fd, 33, 0), what)
        if width * height > max_pixels:
            raise PngError(f"{what} is {width} x {height} pixels, more than the "
                           f"{max_pixels:,} a map may have")  # fmt: skip
        size[:] = [width, height]

    try:
        data = boundedfile.read(path, MAX_FILE_BYTES, header)
    except boundedfile.Refused as r:
        if r.kind == "missing":
            raise PngError(f"{what} does not exist") from None
        if r.kind == "directory":
            raise PngError(f"{what} is a directory, not a PNG") from None
        if r.kind == "special":
            raise PngError(f"{what} is not a regular file (a pipe or a device?)") from None
        if r.kind == "too_big":
            raise PngError(f"{what} is {int(r.detail) >> 20} MiB, more than a map of "
                           f"{max_pixels:,} pixels can take") from None  # fmt: skip
        raise PngError(f"{what}: {r.detail}") from None
    width, height = size
    _check_chunks(data, what)
    return width, height, data


def _ihdr(head: bytes, what: str) -> tuple[int, int]:
    """Width and height from the signature and IHDR (the first 33 bytes of a PNG)."""
    if not head.startswith(SIGNATURE):
        raise PngError(f"{what} is not a PNG (no PNG signature)")
    if len(head) < 33 or head[8:16] != b"\x00\x00\x00\x0dIHDR":
        raise PngError(f"{what} is not a PNG (no IHDR chunk at its start)")
    width, height = struct.unpack(">II", head[16:24])
    if width == 0 or height == 0:
        raise PngError(f"{what} is {width} x {height} pixels: empty")
    return width, height


def _check_chunks(data: bytes, what: str) -> None:
    """Every chunk complete with a matching CRC, ending in IEND."""
    at = len(SIGNATURE)
    while True:
        if at + 8 > len(data):
            raise PngError(f"{what} is truncated (it ends before its IEND chunk)")
        length, kind = struct.unpack(">I4s", data[at : at + 8])
        end = at + 8 + length + 4
        if length > 0x7FFFFFFF or end > len(data):
            raise PngError(f"{what} is truncated (its {kind!r} chunk is cut short)")
        crc = struct.unpack(">I", data[end - 4 : end])[0]
        if zlib.crc32(data[at + 4 : end - 4]) != crc:
            raise PngError(f"{what} is damaged (a CRC error in its {kind!r} chunk)")
        if kind == b"IEND":
            return
        at = end


@contextlib.contextmanager
def _stderr_discarded():
    """File descriptor 2 to /dev/null for the block: what libpng prints there by itself."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def read_gray(path: str, max_pixels: int = MAX_MAP_PIXELS) -> np.ndarray:
    """The map's grey levels (uint8, rows x cols) after every check above; PngError if any
    fails or OpenCV cannot decode what passed them."""
    return decode_gray(path, *check(path, max_pixels))


def decode_gray(path: str, width: int, height: int, data: bytes) -> np.ndarray:
    """Step 4: decode what `check` returned (its width, height and bytes). A picture with
    an alpha channel is laid over white first, as a viewer shows it: transparent free
    space is free, not the black its colour channels hold."""
    import cv2  # only maps need it; the rest of topology starts without it

    raw = np.frombuffer(data, dtype=np.uint8)
    with _stderr_discarded():
        img = cv2.imdecode(raw, cv2.IMREAD_GRAYSCALE)
    if img is None or img.shape != (height, width):
        raise PngError(f"map file {path} is a PNG that OpenCV cannot decode")
    if data[25:26] in (b"\x04", b"\x06"):  # IHDR colour type: grey or RGB with alpha
        with _stderr_discarded():
            full = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
        if full is not None and full.ndim == 3 and full.shape[2] == 4:
            alpha = full[..., 3].astype(np.float32) / (
                65535.0 if full.dtype == np.uint16 else 255.0
            )
            img = np.rint(img * alpha + 255.0 * (1 - alpha)).astype(np.uint8)
    return img
