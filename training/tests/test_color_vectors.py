"""The Python colour transform against the vectors the Rust core writes
(tests/data/color_vectors.json, made by tests/color_vectors.rs): training and inference
must see the same numbers, to 1e-5."""

import json
import pathlib

import numpy as np
import pytest

from temc_train import color

VECTORS = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "color_vectors.json"
TOL = 1e-5


def num(v):
    return {"nan": np.nan, "inf": np.inf, "-inf": -np.inf}.get(v, v) if isinstance(v, str) else v


def arr(v):
    return np.array([num(x) for x in v], dtype=np.float64)


def close(got, want, what):
    """Within TOL: absolute where |want| <= 1, relative above (linear HDR values)."""
    got = np.asarray(got, np.float64)
    want = np.asarray(want, np.float64)
    err = np.abs(got - want) / np.maximum(1.0, np.abs(want))
    assert np.all(err <= TOL), f"{what}: python {got} vs rust {want}"


@pytest.fixture(scope="module")
def vectors():
    if not VECTORS.exists():
        pytest.skip(f"{VECTORS} is absent; the Rust side writes it: "
                    "`TEMC_BLESS=1 cargo test --release --test color_vectors`")
    return json.loads(VECTORS.read_text())


def test_constants_agree(vectors):
    assert vectors["pq_nits_per_unit"] == color.NITS_PER_UNIT
    assert vectors["linear_max"] == color.LINEAR_MAX
    if "highlight_knee" in vectors:
        assert np.float32(vectors["highlight_knee"]) == color.HIGHLIGHT_KNEE


def test_pixels(vectors):
    assert len(vectors["pixels"]) > 40
    for p in vectors["pixels"]:
        name = p["name"]
        rgb = arr(p["rgb"])
        close(color.sanitize_rgb(rgb), arr(p["sanitized"]), f"{name} sanitized")
        # The core writes as "pq" the R'G'B' that the six-sector inverse recovers from
        # "hsv" (tests/color_vectors.rs); the forward PQ values differ from it only by f32
        # rounding through HSV (at most 6e-8 for the current vectors).
        close(color.hsv_to_rgb(arr(p["hsv"])), arr(p["pq"]), f"{name} pq from hsv")
        pq, excess = color.to_pq(rgb, p["input_scale"])
        close(pq, arr(p["pq"]), f"{name} forward pq")
        close(excess, num(p["excess"]), f"{name} excess")
        hsv, _ = color.encode(rgb, p["input_scale"])
        close(hsv, arr(p["hsv"]), f"{name} hsv")
        close(color.decode(arr(p["hsv"]), num(p["excess"]), p["input_scale"]), arr(p["decoded"]),
              f"{name} decoded")


def test_hsv_inverse(vectors):
    for c in vectors["hsv_inverse"]:
        close(color.hsv_to_rgb(arr(c["hsv"])), arr(c["rgb_pq"]), c["name"])


def test_spectral(vectors):
    for c in vectors["spectral"]:
        edges, values = arr(c["edges"]), arr(c["values"])
        close(color.spectral_to_xyz(values, edges), arr(c["xyz"]), f"{c['name']} xyz")
        close(color.spectral_to_linear_srgb(values, edges), arr(c["rgb"]), f"{c['name']} rgb")


def test_batched_images_match_per_pixel():
    rng = np.random.default_rng(0)
    img = (10 ** rng.uniform(-6, 3, size=(8, 9, 3))).astype(np.float32)
    hsv, ex = color.encode(img)
    for i in range(8):
        for j in range(9):
            h1, e1 = color.encode(img[i, j])
            assert np.array_equal(h1, hsv[i, j]) and e1 == ex[i, j]
    back = color.decode(hsv, ex)
    assert np.all(np.isfinite(back))
    np.testing.assert_allclose(back, img, rtol=1e-4, atol=1e-9)
