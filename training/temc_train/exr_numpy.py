"""Reads the EXR files temc-render writes with numpy and the standard library alone.

The GPU machine that trains has PyTorch but not the OpenEXR package, and no network to
install it; scripts/train-gpu renders scenes there as it trains. This reader covers what
such files use: one part, scan lines or one-level tiles, float32 or half channels, and no,
RLE, ZIPS or ZIP compression (temc-render writes RLE in 64x64 tiles). Anything else is
refused with its name, never misread. `data.read_exr` uses it where OpenEXR is missing;
tests/test_exr_numpy.py reads the same files with both.
"""

import struct
import zlib

import numpy as np

MAGIC = 20000630
COMPRESSIONS = {0: "none", 1: "rle", 2: "zips", 3: "zip"}
LINES_PER_CHUNK = {"none": 1, "rle": 1, "zips": 1, "zip": 16}
SAMPLE = {1: np.dtype("<f2"), 2: np.dtype("<f4")}


class ExrError(ValueError):
    """A file this reader cannot read (not an EXR, or a feature it does not cover)."""


def _header(buf: bytes):
    """(attributes {name: (type, bytes)}, offset of the offset table)."""
    magic, version = struct.unpack_from("<ii", buf, 0)
    if magic != MAGIC:
        raise ExrError("not an OpenEXR file")
    if version & 0x1800:  # multi-part or deep data
        raise ExrError("multi-part and deep EXR files are not supported")
    pos, attrs = 8, {}
    while buf[pos] != 0:
        name_end = buf.index(b"\0", pos)
        type_end = buf.index(b"\0", name_end + 1)
        (size,) = struct.unpack_from("<i", buf, type_end + 1)
        value = type_end + 5
        attrs[buf[pos:name_end].decode()] = (buf[name_end + 1:type_end].decode(), buf[value:value + size])
        pos = value + size
    return attrs, pos + 1


def _channels(raw: bytes) -> list:
    """[(name, dtype)] in the file's (sorted) order."""
    out, pos = [], 0
    while raw[pos] != 0:
        end = raw.index(b"\0", pos)
        ptype, _, _, xs, ys = struct.unpack_from("<iB3sii", raw, end + 1)
        if ptype not in SAMPLE or (xs, ys) != (1, 1):
            raise ExrError(f"channel {raw[pos:end].decode()!r}: unsupported sample type or subsampling")
        out.append((raw[pos:end].decode(), SAMPLE[ptype]))
        pos = end + 1 + 16
    return out


def _rle(data: bytes) -> bytes:
    out, i, n = bytearray(), 0, len(data)
    while i < n:
        c = data[i] - 256 if data[i] > 127 else data[i]
        if c < 0:
            out += data[i + 1:i + 1 - c]
            i += 1 - c
        else:
            out += data[i + 1:i + 2] * (c + 1)
            i += 2
    return bytes(out)


def _unpredict(raw: bytes) -> bytes:
    """Undoes OpenEXR's byte predictor and the split into two halves (RLE and ZIP)."""
    t = np.frombuffer(raw, np.uint8).copy()
    if t.size:
        t[1:] -= 128  # uint8 arithmetic wraps modulo 256, as the predictor does
        t = np.cumsum(t, dtype=np.uint8)
    half = (t.size + 1) // 2
    out = np.empty_like(t)
    out[0::2], out[1::2] = t[:half], t[half:]
    return out.tobytes()


def _decompress(data: bytes, how: str, expected: int) -> bytes:
    if how == "none" or len(data) == expected:  # a block that did not shrink is stored raw
        return data
    raw = _rle(data) if how == "rle" else zlib.decompress(data)
    return _unpredict(raw)


def read(path: str) -> dict:
    """Every channel of a single-part EXR as float32 [H, W] arrays, by name."""
    with open(path, "rb") as f:
        buf = f.read()
    attrs, pos = _header(buf)
    chans = _channels(attrs["channels"][1])
    how = COMPRESSIONS.get(attrs["compression"][1][0])
    if how is None:
        raise ExrError(f"compression {attrs['compression'][1][0]} is not supported (none, RLE, ZIPS, ZIP)")
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"][1])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    out = {name: np.zeros((h, w), np.float32) for name, _ in chans}
    if "tiles" in attrs:
        tw, th, mode = struct.unpack("<IIB", attrs["tiles"][1])
        if mode & 0xF:
            raise ExrError("mip-mapped and rip-mapped tiles are not supported")
        blocks = [(tx * tw, ty * th, min(tw, w - tx * tw), min(th, h - ty * th))
                  for ty in range(-(-h // th)) for tx in range(-(-w // tw))]
    else:
        lines = LINES_PER_CHUNK[how]
        blocks = [(0, y, w, min(lines, h - y)) for y in range(0, h, lines)]
    offsets = struct.unpack_from(f"<{len(blocks)}Q", buf, pos)
    for (bx, by, bw, bh), off in zip(blocks, offsets):
        if "tiles" in attrs:
            tx, ty, _, _, size = struct.unpack_from("<5i", buf, off)
            bx, by = tx * tw, ty * th
            bw, bh = min(tw, w - bx), min(th, h - by)
            data = buf[off + 20:off + 20 + size]
        else:
            y, size = struct.unpack_from("<ii", buf, off)
            by = y - y0
            data = buf[off + 8:off + 8 + size]
        row = sum(dt.itemsize for _, dt in chans) * bw
        raw = _decompress(data, how, row * bh)
        if len(raw) != row * bh:
            raise ExrError(f"{path}: a block decodes to {len(raw)} bytes, not {row * bh}")
        lines = np.frombuffer(raw, np.uint8).reshape(bh, row)
        col = 0
        for name, dt in chans:
            n = dt.itemsize * bw
            out[name][by:by + bh, bx:bx + bw] = lines[:, col:col + n].copy().view(dt).astype(np.float32)
            col += n
    return out
