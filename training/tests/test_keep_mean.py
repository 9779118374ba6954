"""The keep-mean stage: the committed vectors (which Rust checks too) are what keep_mean.py
computes now, and the properties the core relies on: means come back, factors are clamped,
black stays black, nothing non-finite leaves."""

import json

import numpy as np

from temc_train import keep_mean as km


def test_vectors_are_current():
    """Regenerate with `python -m temc_train.vectors.keep_mean` when the stage changes."""
    want = json.loads(km.VECTORS.read_text())
    got = km.vector_cases()
    assert [c["name"] for c in got] == [c["name"] for c in want]
    for g, w in zip(got, want):
        np.testing.assert_allclose(g["want"], w["want"], rtol=1e-7, atol=1e-9)
        # keep_mean itself (float32 out) within the tolerance Rust is held to
        shape = (g["h"], g["w"], 3)
        den, noisy = np.reshape(g["output"], shape), np.reshape(g["input"], shape)
        out = (km.stage(den, noisy) if g["block"] == "stage"
               else km.keep_mean(den, noisy, g["block"], g["clamp"], g["ldr"]))
        np.testing.assert_allclose(out.ravel(), w["want"], rtol=1e-5, atol=1e-5)


def test_the_stage_keeps_the_image_mean_past_the_block_clamp():
    """A block whose output is 10x too dark: the block pass stops at 4x, the global pass
    brings the image's mean back (the dark room of docs/keep-mean-measured.md)."""
    rng = np.random.default_rng(3)
    noisy = (rng.random((130, 200, 3)) ** 3).astype(np.float32)
    out = km.stage(0.1 * noisy, noisy)
    np.testing.assert_allclose(out.mean((0, 1)), noisy.mean((0, 1)), rtol=1e-5)
    one_pass = km.keep_mean(0.1 * noisy, noisy, km.BLOCK, km.CLAMP)
    assert np.all(one_pass.mean((0, 1)) < 0.5 * noisy.mean((0, 1)))


def test_block_means_follow_the_input():
    """Factors up to SPREAD_ABOVE scale their own pixels: block sums come back exactly."""
    rng = np.random.default_rng(1)
    noisy = (2 * rng.random((96, 64, 3)) ** 4).astype(np.float32)
    darker = noisy * 0.85
    assert 1 / 0.85 < km.SPREAD_ABOVE
    out = km.keep_mean(darker, noisy, 32, 4.0)
    np.testing.assert_allclose(km.block_sums(out, 32), km.block_sums(noisy, 32), rtol=1e-5)


def test_heavy_tailed_flat_colour_keeps_its_mean():
    """A filter that drops the outliers (here: the median) darkens; the stage undoes it."""
    rng = np.random.default_rng(2)
    base = np.array([0.8, 0.1, 0.05])
    noisy = (2 * base * rng.random((110, 150, 3)) ** 2).astype(np.float32)
    med = np.broadcast_to(np.median(noisy, axis=(0, 1)), noisy.shape).astype(np.float32)
    out = km.stage(med, noisy)
    ratio = out.mean((0, 1)) / noisy.mean((0, 1))
    assert np.all(np.abs(ratio - 1) < 0.01), ratio


def test_clamp_black_and_non_finite():
    noisy = np.full((8, 8, 3), 10.0, np.float32)
    out = np.zeros((8, 8, 3), np.float32)
    out[:, 4:] = 1.0
    scaled = km.keep_mean(out, noisy, 4, 2.0, above=np.inf)
    assert np.all(scaled[:, :4] == 0) and np.all(scaled[:, 6:] == 2.0)
    # With the spread, the part of the factor 2 above SPREAD_ABOVE multiplies the window's
    # mean (0.5: the window covers the image); pixels whose factor stays at or below
    # SPREAD_ABOVE (columns 0-2) stay black.
    got = km.keep_mean(out, noisy, 4, 2.0)
    assert np.all(got[:, :3] == 0)
    np.testing.assert_allclose(got[:, 6:], km.SPREAD_ABOVE + (2.0 - km.SPREAD_ABOVE) * 0.5, rtol=1e-6)
    huge = km.keep_mean(np.full((4, 4, 3), 60000, np.float32), np.full((4, 4, 3), 65504, np.float32))
    assert np.isfinite(huge).all() and huge.max() <= 65504


def test_missing_energy_comes_back_smooth_not_in_the_remnants():
    """Twin of src/keep_mean.rs's test: a block whose filter dropped most of its energy keeps
    one remnant; the stage brings the mean back over the block, not into the remnant (scaling
    alone made it 3.3x brighter)."""
    noisy = np.full((64, 64, 3), 0.1, np.float32)
    out = np.full((64, 64, 3), 0.03, np.float32)
    out[40, 23] = 0.5
    got = km.stage(out, noisy)
    np.testing.assert_allclose(got.astype(np.float64).mean((0, 1)), 0.1, rtol=1e-5)
    assert np.all((got[40, 23] > 0.5) & (got[40, 23] < 1.0)), got[40, 23]
    dark = np.delete(got.reshape(-1, 3), 40 * 64 + 23, axis=0)
    assert np.all((dark > 0.095) & (dark < 0.105))
    old = km.keep_mean(km.keep_mean(out, noisy, km.BLOCK, km.CLAMP, above=np.inf), noisy, 0,
                       km.GLOBAL_CLAMP, above=np.inf)
    assert np.all(old[40, 23] > 1.6)


def test_a_dimmed_lamp_does_not_light_the_black_beside_it():
    """Twin of src/keep_mean.rs's test: a 2x2 lamp the filters dimmed to 60 % on black, over
    a dim floor, through the blocks alone (the lamp's own factor, which would give it back
    before them, left out). The spread before the clip (2026-12-07) lit the black around it
    with a share of the lamp's window mean; the core's spread, over the output clipped at
    SPREAD_CLIP times its window mean, leaves it nearly black, the lamp gets its light back
    and the mean stays exact (the last pass scales)."""
    noisy = np.zeros((64, 64, 3), np.float32)
    noisy[30:32, 30:32] = 1000.0
    noisy[40:, :] = 0.05  # a dim floor
    out = noisy.copy()
    out[30:32, 30:32] = 600.0
    black = noisy[:40, :, 0] == 0
    unclipped = lambda o, excess: km.clipped_spread(o, excess, clip=np.inf)
    before = km.stage(out, noisy, spread=unclipped, last_spreads=True, lamps=False)
    assert before[20, 31].min() > 0.5  # black sky lit by the lamp's window
    got = km.stage(out, noisy, lamps=False)
    assert got[:40][black].max() <= 0.05
    assert abs(got[30, 30, 0] / 1000.0 - 1) < 0.05
    assert abs(got.astype(np.float64).sum() / noisy.astype(np.float64).sum() - 1) < 1e-5
    # With its own factor first, the lamp is 900 before the blocks, which then only scale.
    assert np.all(km.stage(out, noisy)[:40][black] == 0)


def test_a_dimmed_lamp_takes_its_own_light_back():
    """Twin of src/keep_mean.rs's test: a 2x2 lamp the filters dimmed to 80 % over a lit
    floor. Without its own factor the blocks raise the floor 22 % to pay for it; with it the
    lamp gets its light back and the floor stays as it was."""
    noisy = np.full((64, 64, 3), 0.1, np.float32)
    noisy[30:32, 30:32] = 1000.0
    out = noisy.copy()
    out[30:32, 30:32] = 800.0
    before = km.stage(out, noisy, lamps=False)
    assert before[5, 5, 0] > 0.12
    got = km.stage(out, noisy)
    np.testing.assert_allclose(got[5, 5], 0.1, rtol=1e-4)
    np.testing.assert_allclose(got[30:32, 30:32], 1000.0, rtol=1e-4)


def test_a_lone_high_sample_is_not_a_lamp():
    """Twin of src/keep_mean/lamps.rs's test: a firefly of the noisy input (one pixel) whose
    remnant the output kept is no lamp (the opening drops it), so its light goes back over
    the block, not into the remnant; a 2x2 lamp beside it is one."""
    noisy = np.full((40, 40, 3), 0.1, np.float32)
    noisy[10, 10] = 400.0
    noisy[25:27, 25:27] = 400.0
    out = np.full((40, 40, 3), 0.1, np.float32)
    out[10, 10] = 5.0
    out[25:27, 25:27] = 300.0
    got = km.restore_lamps(out, noisy)
    assert np.all(got[10, 10] == 5.0)
    assert np.all(got[25:27, 25:27] > 300.0)
    rest = np.delete(got.reshape(-1, 3), [10 * 40 + 10, 25 * 40 + 25, 25 * 40 + 26, 26 * 40 + 25, 26 * 40 + 26], 0)
    assert np.all(rest == np.float32(0.1))
