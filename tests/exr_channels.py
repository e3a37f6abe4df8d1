"""Read the channels of an uncompressed scanline OpenEXR file into numpy.

Enough of the format (single- or multi-part, scanlines, codec NONE, half or
float channels) for the multilayer files Blender writes, so tests can check
every render pass, not only the combined image.
"""

from __future__ import annotations

import struct

import numpy as np

_MAGIC = 20000630
_TILED, _MULTIPART = 0x200, 0x1000
_PIXEL_DTYPES = {1: np.dtype("<f2"), 2: np.dtype("<f4")}


def read_exr_channels(path) -> dict[str, np.ndarray]:
    """Channel name -> (H, W) float32 array, rows from the bottom (as Blender's passes)."""
    with open(path, "rb") as f:
        data = f.read()
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != _MAGIC or version & _TILED:
        raise ValueError(f"{path} is not a scanline OpenEXR file")
    multipart = bool(version & _MULTIPART)
    parts, pos = [], 8
    while True:
        header, pos = _read_header(data, pos)
        parts.append(_Part(header, path))
        if not multipart or data[pos] == 0:
            break
    pos += 1 if multipart else 0  # the empty header that ends the list of parts
    pos += 8 * sum(part.height for part in parts)  # line offset tables: lines follow in order
    for _ in range(sum(part.height for part in parts)):
        number = 0
        if multipart:
            (number,) = struct.unpack_from("<i", data, pos)
            pos += 4
        y, _size = struct.unpack_from("<ii", data, pos)
        pos = parts[number].read_line(data, pos + 8, y)
    planes = {}
    for part in parts:
        planes.update({name: plane[::-1].copy() for name, plane in part.planes.items()})
    return planes


def exr_channel_types(path) -> dict[str, np.dtype]:
    """Channel name -> stored pixel type of the first part (compressed files too)."""
    with open(path, "rb") as f:
        data = f.read(1 << 16)
    header, _ = _read_header(data, 8)
    return dict(_channel_list(header["channels"]))


class _Part:
    """One part's channels and pixel planes."""

    def __init__(self, header: dict[str, bytes], path):
        if header["compression"][0] != 0:
            raise ValueError(f"{path} is compressed; write it with exr_codec 'NONE'")
        x0, self.y0, x1, y1 = struct.unpack("<iiii", header["dataWindow"])
        self.width, self.height = x1 - x0 + 1, y1 - self.y0 + 1
        self.channels = _channel_list(header["channels"])
        self.planes = {name: np.empty((self.height, self.width), np.float32) for name, _ in self.channels}

    def read_line(self, data: bytes, pos: int, y: int) -> int:
        """Read scanline ``y`` starting at ``pos``; returns the position after it."""
        for name, dtype in self.channels:
            self.planes[name][y - self.y0] = np.frombuffer(data, dtype, self.width, pos)
            pos += self.width * dtype.itemsize
        return pos


def _read_header(data: bytes, pos: int) -> tuple[dict[str, bytes], int]:
    header = {}
    while data[pos] != 0:
        name, pos = _cstring(data, pos)
        _kind, pos = _cstring(data, pos)
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        header[name] = data[pos:pos + size]
        pos += size
    return header, pos + 1


def _channel_list(raw: bytes) -> list[tuple[str, np.dtype]]:
    channels, pos = [], 0
    while raw[pos] != 0:
        name, pos = _cstring(raw, pos)
        (pixel_type,) = struct.unpack_from("<i", raw, pos)
        pos += 16  # type, pLinear + reserved, x and y sampling
        channels.append((name, _PIXEL_DTYPES[pixel_type]))
    return channels


def _cstring(data: bytes, pos: int) -> tuple[str, int]:
    end = data.index(b"\0", pos)
    return data[pos:end].decode(), end + 1
