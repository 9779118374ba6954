"""Rules of docs/contracts.md §1 that the shared vectors do not pin down on their own:
reference points, the highlight restore and the auxiliary buffers."""

import numpy as np

from temc_train import color


def test_pq_reference_point_and_round_trip():
    # PQ(100 cd/m2) ~ 0.50808 (architecture note §4.3); linear 1.0 is 100 cd/m2.
    assert abs(color.pq_encode(0.01) - 0.50808) < 1e-5
    y = np.logspace(-7, 0, 50)
    np.testing.assert_allclose(color.pq_decode(color.pq_encode(y)), y, rtol=1e-9)


def test_negative_component_keeps_luminance():
    rgb = np.array([0.2, 0.5, -0.1])
    s = color.sanitize_rgb(rgb)
    assert s.min() == 0.0
    assert abs((s * color.LUMA).sum() - (rgb * color.LUMA).sum()) < 1e-7
    assert np.all(color.sanitize_rgb([-1.0, -1.0, 0.5]) == 0)  # Y < 0: black


def test_highlight_restore():
    # A pixel 5x over the PQ ceiling comes back when the network keeps V at the ceiling,
    # and stays removed when the network darkens it below the knee.
    rgb = np.array([500.0, 250.0, 50.0])
    hsv, excess = color.encode(rgb)
    assert excess == 5.0 and hsv[2] == 1.0
    np.testing.assert_allclose(color.decode(hsv, excess), rgb, rtol=1e-4)
    dim = hsv * np.array([1, 1, 0.9], np.float32)
    assert color.decode(dim, excess).max() < 100.0


def test_decode_accepts_any_network_output():
    junk = np.array([[np.nan, 2.0, -1.0], [np.inf, -0.5, 1.5], [-3.25, 0.5, 0.5]], np.float32)
    out = color.decode(junk, np.array([np.inf, np.nan, 1.0]))
    assert np.all(np.isfinite(out)) and np.all(out >= 0)


def test_aux_channels():
    h, w = 2, 3
    albedo = np.full((h, w, 3), 0.5, np.float32)
    albedo[0, 0] = [np.nan, -1.0, 7.0]
    normal = np.zeros((h, w, 3), np.float32)
    normal[0, 1] = [0.0, 0.0, 5.0]
    normal[0, 2] = [np.inf, 0.0, 0.0]
    depth = np.array([[1.0, 4.0, np.inf], [np.nan, -2.0, 2.0]], np.float32)
    aux = color.aux_channels(albedo, normal, depth)
    assert aux.shape == (7, h, w) and aux.dtype == np.float32
    assert list(aux[:3, 0, 0]) == [0.0, 0.0, 1.0]
    assert list(aux[3:6, 0, 1]) == [0.5, 0.5, 1.0]  # unit +z
    assert list(aux[3:6, 0, 2]) == [0.5, 0.5, 0.5]  # non-finite: the zero vector
    assert list(aux[3:6, 1, 1]) == [0.5, 0.5, 0.5]  # zero length stays zero
    # Divided by the largest finite positive depth (4); +Inf (background) is the far end.
    np.testing.assert_array_equal(aux[6], [[0.25, 1.0, 1.0], [0.0, 0.0, 0.5]])
    # No positive finite depth at all: zeros.
    none = color.aux_channels(albedo, normal, np.full((h, w), -1.0, np.float32))
    assert np.all(none[6] == 0)
