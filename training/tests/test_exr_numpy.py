"""exr_numpy reads what OpenEXR reads: scan lines and tiles, float and half, every
compression it covers; and data.read_exr falls back to it without OpenEXR."""

import builtins
import os

import Imath
import numpy as np
import OpenEXR
import pytest

from temc_train import data, exr_numpy

RENDERED = os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data", "render-16x12.exr")


def write(path, planes, compression, half=()):
    """Scan lines (this binding cannot write tiles; the rendered file has them)."""
    h, w = next(iter(planes.values())).shape
    header = OpenEXR.Header(w, h)
    header["compression"] = Imath.Compression(compression)
    ptype = lambda n: Imath.PixelType(Imath.PixelType.HALF if n in half else Imath.PixelType.FLOAT)  # noqa: E731
    header["channels"] = {n: Imath.Channel(ptype(n)) for n in planes}
    f = OpenEXR.OutputFile(str(path), header)
    f.writePixels({n: np.ascontiguousarray(p, np.float16 if n in half else np.float32).tobytes()
                   for n, p in planes.items()})
    f.close()


@pytest.mark.parametrize("compression", ["NO_COMPRESSION", "RLE_COMPRESSION", "ZIPS_COMPRESSION",
                                         "ZIP_COMPRESSION"])
def test_files_read_as_written(tmp_path, compression):
    rng = np.random.default_rng(1)
    h, w = 37, 21  # partial blocks and tiles
    planes = {"b": rng.exponential(1.0, (h, w)), "a": np.zeros((h, w)), "c.Z": rng.normal(size=(h, w)),
              "h": rng.uniform(0, 4, (h, w))}
    planes["b"][3, 4] = np.inf
    planes["a"][5:9] = 2.5  # runs that RLE shortens
    path = tmp_path / "x.exr"
    write(path, planes, getattr(Imath.Compression, compression), half={"h"})
    got = exr_numpy.read(str(path))
    assert sorted(got) == sorted(planes)
    for n, p in planes.items():
        want = p.astype(np.float16 if n == "h" else np.float32).astype(np.float32)
        np.testing.assert_array_equal(got[n], want, err_msg=n)


def test_a_rendered_file_reads_as_openexr_reads_it(monkeypatch):
    """temc-render's own output (64x64 RLE tiles): `temc-render render --scene cornell-warm
    --spp 4 --size 16x12 --threads 1 -o tests/data/render-16x12.exr`."""
    want = data.read_exr(RENDERED)
    real = builtins.__import__

    def no_openexr(name, *args, **kw):
        if name in ("OpenEXR", "Imath"):
            raise ImportError(name)
        return real(name, *args, **kw)

    monkeypatch.setattr(builtins, "__import__", no_openexr)
    got = data.read_exr(RENDERED)
    assert want["color"].shape == (12, 16, 3) and np.abs(want["color"]).sum() > 0
    for k in want:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)


def test_what_it_cannot_read_is_refused(tmp_path):
    p = tmp_path / "not.exr"
    p.write_bytes(b"\x76\x2f\x31\x00" + bytes(64))
    with pytest.raises(exr_numpy.ExrError, match="not an OpenEXR"):
        exr_numpy.read(str(p))
    path = tmp_path / "piz.exr"
    write(path, {"a": np.ones((4, 4))}, Imath.Compression.PIZ_COMPRESSION)
    with pytest.raises(exr_numpy.ExrError, match="compression 4"):
        exr_numpy.read(str(path))
