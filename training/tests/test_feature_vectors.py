"""The automatic exposure and the aux features against tests/data/feature_vectors.json,
the file tests/feature_vectors.rs checks the Rust core against: training must feed the
network what the core feeds it."""

import json

import numpy as np
import pytest

from temc_train import color
from temc_train.vectors import feature_vectors
from temc_train.data import auto_input_scale

from test_color_vectors import arr, num


@pytest.fixture(scope="module")
def vectors():
    if not feature_vectors.OUT.exists():
        pytest.skip(f"{feature_vectors.OUT} is absent: python -m temc_train.vectors.feature_vectors")
    return json.loads(feature_vectors.OUT.read_text())


def test_the_file_is_what_the_generator_writes(vectors):
    # A change to the Python side shows here first; regenerate, then run the Rust test.
    assert json.loads(json.dumps(feature_vectors.vectors())) == vectors


def test_constants_agree(vectors):
    assert vectors["auto_exposure_key"] == color.AUTO_EXPOSURE_KEY


def test_exposure(vectors):
    assert len(vectors["exposure"]) >= 10
    for c in vectors["exposure"]:
        rgb = arr(c["rgb"]).reshape(-1, 3).astype(np.float32)
        got = auto_input_scale(rgb)
        assert got == pytest.approx(c["scale"], rel=vectors["exposure_tolerance"]), c["name"]


@pytest.mark.parametrize("kind, fn", [("albedo", color.albedo), ("normal", color.normal)])
def test_albedo_and_normal(vectors, kind, fn):
    for c in vectors[kind]:
        got = fn(arr(c["in"]).astype(np.float32))
        np.testing.assert_allclose(got, arr(c["out"]), atol=vectors["feature_tolerance"], rtol=0,
                                   err_msg=f"{kind} {c['in']}")


def test_depth(vectors):
    for c in vectors["depth"]:
        d = arr(c["in"]).astype(np.float32)
        s = color.depth_scale(d)
        assert s == (None if c["scale"] is None else num(c["scale"])), c["name"]
        np.testing.assert_allclose(color.depth(d, s), arr(c["out"]),
                                   atol=vectors["feature_tolerance"], rtol=0, err_msg=c["name"])


def test_aux_channels_pack_the_features(vectors):
    # The [7, H, W] the network reads: the three features of one image, depth over the whole.
    albedo = np.array([arr(c["in"]) for c in vectors["albedo"][:4]], np.float32)[None]
    normal = np.array([arr(c["in"]) for c in vectors["normal"][:4]], np.float32)[None]
    d = vectors["depth"][0]
    depth = arr(d["in"])[:4].astype(np.float32)[None]
    aux = color.aux_channels(albedo, normal, depth)
    want_a = np.array([arr(c["out"]) for c in vectors["albedo"][:4]])
    want_n = np.array([arr(c["out"]) for c in vectors["normal"][:4]])
    assert aux.shape == (7, 1, 4)
    np.testing.assert_array_equal(aux[:3, 0].T, want_a)
    np.testing.assert_allclose(aux[3:6, 0].T, want_n, atol=vectors["feature_tolerance"])
    # Its first four depths hold the image's largest, so their statistic is the case's.
    np.testing.assert_array_equal(aux[6, 0], arr(d["out"])[:4])
