"""The CIE 1931 2-degree observer as temc uses it: the table parsed from the Rust source
(color/src/cie1931.rs, its one home), checked against the CIE's values (colour-science's
independent copy, 1 nm, 360..830 nm), and the spectral bands' conversion checked against
the tracer's (the integral of the spectrum times the interpolated table)."""

import warnings

import numpy as np
import pytest

from temc_train import color

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour


def test_parsed_table_is_the_cie_table():
    c = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    lam, ref = np.asarray(c.wavelengths, float), np.asarray(c.values, float)
    keep = (lam >= 360) & (lam <= 830)
    assert np.array_equal(lam[keep], np.arange(360.0, 831.0))
    assert color.CIE_1931_2DEG.shape == (471, 3)
    np.testing.assert_allclose(color.CIE_1931_2DEG, ref[keep], rtol=0, atol=1e-9)
    # Rows of CIE 018:2019 (as color/src/cie.rs checks them too).
    for nm, xyz in [(450, (0.3362, 0.038, 1.77211)), (555, (0.5120501, 1.0, 0.005749999)),
                    (600, (1.0622, 0.631, 0.0008))]:
        np.testing.assert_array_equal(color.cmf_tabulated(float(nm)), xyz)
    assert abs(color.CIE_1931_2DEG[:, 1].sum() - 106.85692) < 1e-5


def test_interpolation_and_integral():
    a, b = color.cmf_tabulated(600.0), color.cmf_tabulated(601.0)
    np.testing.assert_allclose(color.cmf_tabulated(600.5), 0.5 * (a + b), atol=1e-15)
    assert not color.cmf_tabulated([359.0, 831.0, np.nan]).any()
    t = color.cmf_tabulated_integral(360.0, 830.0)
    ends = 0.5 * (color.cmf_tabulated(360.0) + color.cmf_tabulated(830.0))
    np.testing.assert_allclose(t, color.CIE_1931_2DEG.sum(0) - ends, atol=1e-9)
    parts = [360.0, 402.3, 402.7, 555.0, 700.25, 830.0]
    acc = sum(color.cmf_tabulated_integral(x, y) for x, y in zip(parts[:-1], parts[1:]))
    np.testing.assert_allclose(acc, t, atol=1e-9)
    assert not color.cmf_tabulated_integral(500.0, 400.0).any()


def test_parser_reads_rows_and_refuses_damage():
    good = (
        "pub const FIRST_NM: f64 = 400.0;\n"
        "#[rustfmt::skip]\n"
        "pub const CIE_1931_2DEG: [[f64; 3]; 2] = [\n"
        "    [0.5, 0.0000025, 1.0], // 400\n"
        "    [1e-3, 2.0, 0.0], // 401\n"
        "];\n"
    )
    first, t = color.parse_cie1931_rs(good)
    assert first == 400.0
    np.testing.assert_array_equal(t, [[0.5, 2.5e-6, 1.0], [1e-3, 2.0, 0.0]])
    for bad in [good.replace("; 2]", "; 3]"),            # declared length
                good.replace("// 401", "// 402"),        # a skipped nm
                good.replace("[1e-3, 2.0, 0.0]", "[1e-3, 2.0]"),  # a short row
                good.replace("FIRST_NM", "FIRST")]:
        with pytest.raises(ValueError):
            color.parse_cie1931_rs(bad)


def tracer_xyz(s):
    """XYZ as the tracer's film computes it in expectation: the integral of s(lam) times
    the interpolated table over 360..830 nm (midpoint, 0.01 nm), over the integral of y-bar."""
    lam = 360.0 + (np.arange(47000) + 0.5) * 0.01
    xyz = (color.cmf_tabulated(lam) * s(lam)[:, None]).sum(0) * 0.01
    return xyz / color.cmf_tabulated_integral(360.0, 830.0)[1]


def test_bands_convert_a_spectrum_as_the_tracer_does():
    line = lambda lam: np.where((lam >= 549.5) & (lam < 550.5), 3.0, 0.0)  # noqa: E731
    got = color.spectral_to_xyz(np.array([3.0]), [549.5, 550.5])
    want = tracer_xyz(line)
    assert np.abs(got - want).max() <= 1e-4 * np.abs(want).max(), (got, want)

    bb = lambda lam: 1e17 / (lam ** 5 * (np.exp(1.4388e7 / (lam * 3000.0)) - 1.0))  # noqa: E731
    edges = np.arange(360.0, 831.0)
    sub = edges[:-1, None] + (np.arange(100) + 0.5)[None] / 100
    means = bb(sub).mean(1).astype(np.float32)
    got = color.spectral_to_xyz(means, edges)
    want = tracer_xyz(bb)
    assert np.abs(got - want).max() <= 1e-4 * np.abs(want).max(), (got, want)
    assert abs(tracer_xyz(lambda lam: np.ones_like(lam))[1] - 1.0) < 1e-6
