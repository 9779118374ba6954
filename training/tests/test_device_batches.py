"""device_batches.DeviceSet draws the batches data.make_sample makes, crop for crop."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from temc_train import color, data
from temc_train import device_batches as db


def scene(name, h, w, seed, spp=(1, 4)):
    """A scene with hard values: NaN, Inf, negative and huge colour, missing normals."""
    rng = np.random.default_rng(seed)
    s = len(spp)
    col = rng.exponential(0.3, (s, h, w, 3)).astype(np.float32)
    col[0, 0, 0] = [np.nan, np.inf, -1.0]
    col[-1, 1, 2] = [1e6, -0.2, 0.1]
    nrm = rng.normal(size=(s, h, w, 3)).astype(np.float32)
    nrm[:, 2, :] = 0.0
    dep = rng.uniform(0.5, 4.0, (s, h, w)).astype(np.float32)
    dep[:, 0, 1] = np.inf
    a = {"color": col, "albedo": rng.uniform(-0.1, 1.2, (s, h, w, 3)).astype(np.float32),
         "normal": nrm, "depth": dep, "reference": rng.exponential(0.3, (h, w, 3)).astype(np.float32)}
    return SimpleNamespace(name=name, spp=list(spp), a=a, shape=(h, w),
                           scale=[data.auto_input_scale(c) for c in col],
                           depth_scale=[color.depth_scale(d) for d in dep])


class Scripted:
    """A numpy Generator stand-in answering make_sample's draws from a script."""

    def __init__(self, answers):
        self.answers = list(answers)

    def integers(self, *_):
        return self.answers.pop(0)

    def random(self):
        return self.answers.pop(0)

    def uniform(self, *_):
        return self.answers.pop(0)


@pytest.mark.parametrize("mode,u", [("none", 0.1), ("albedo", 0.3), ("full", 0.9)])
def test_a_batch_is_make_samples_crops(mode, u):
    scenes = [scene("a", 24, 40, 1), scene("b", 32, 20, 2)]
    ds = db.DeviceSet("cpu")
    ds.add(scenes)
    c = 16
    picks = [(0, 1, 3, 20, True, 1, 0.7), (1, 0, 16, 2, False, 3, -0.4), (0, 0, 8, 24, True, 2, 0.0),
             (1, 1, 0, 4, False, 0, -1.0)]
    n = len(picks)
    col = lambda j, dt=torch.long: torch.tensor([p[j] for p in picks], dtype=dt)  # noqa: E731
    d = {"i": col(0), "s": col(1), "y0": col(2), "x0": col(3), "flip": col(4, torch.bool),
         "k": col(5), "stops": col(6, torch.float32), "c": c, "mode": torch.full((n,), u),
         "spin": torch.eye(3).expand(n, 3, 3)}
    got = ds.make(d)
    for j, (i, s, y0, x0, flip, k, stops) in enumerate(picks):
        rng = Scripted([int(flip), k, 0.9, stops])
        want = data.make_sample(scenes[i], rng, c, spp_index=s, aux_mode=mode, origin=(y0, x0))
        for name, g, w in zip(("chroma", "luma", "aux", "noisy", "albedo", "ref"), got, want):
            # Hue and saturation are ratios of PQ differences: float32 PQ (here) against
            # float64 (color.py) moves them by up to 1e-4 on near-grey pixels.
            tol = 2e-4 if name == "chroma" else 2e-5
            np.testing.assert_allclose(g[j].numpy(), w, rtol=tol, atol=tol, err_msg=f"{name} {j}")


def test_random_rotations_are_rotations_and_draws_stay_inside_each_scene():
    gen = torch.Generator().manual_seed(3)
    q = db.random_rotations(64, gen, "cpu")
    np.testing.assert_allclose(q @ q.transpose(1, 2), np.broadcast_to(np.eye(3), (64, 3, 3)), atol=1e-5)
    np.testing.assert_allclose(torch.linalg.det(q), 1.0, atol=1e-5)
    ds = db.DeviceSet("cpu")
    ds.add([scene("a", 24, 40, 1), scene("b", 32, 20, 2)])
    d = ds.draw(512, 16, gen)
    hw = ds.hw[d["i"]]
    assert (d["y0"] >= 0).all() and (d["y0"] + 16 <= hw[:, 0]).all()
    assert (d["x0"] >= 0).all() and (d["x0"] + 16 <= hw[:, 1]).all()
    assert set(d["k"].tolist()) == {0, 1, 2, 3} and set(d["s"].tolist()) == {0, 1}
    out = ds.batch(8, 16, gen)
    assert [tuple(t.shape) for t in out] == [(8, 2, 16, 16), (8, 1, 16, 16), (8, 7, 16, 16)] + [(8, 3, 16, 16)] * 3
    assert all(torch.isfinite(t).all() for t in out)


def test_scenes_join_as_they_land_and_the_smallest_bounds_the_crop():
    ds = db.DeviceSet("cpu")
    assert ds.add([scene("a", 24, 40, 1)]) == 1
    assert ds.add([scene("a", 24, 40, 1), scene("b", 48, 20, 2)]) == 1
    assert ds.planes.shape[:4] == (2, 2, 48, 40) and len(ds) == 2
    assert ds.draw(4, 128, torch.Generator().manual_seed(0))["c"] == 20
    with pytest.raises(ValueError, match="spp"):
        ds.add([scene("c", 8, 8, 3, spp=(2, 8))])


def test_max_spp_draws_only_the_noisier_inputs():
    """--max-input-spp: inputs whose reference is not much cleaner than them are never drawn;
    without it every spp is, from the same random stream as before."""
    gen = lambda: torch.Generator().manual_seed(5)  # noqa: E731
    scenes = [scene("a", 24, 24, 1, spp=(1, 4, 16)), scene("b", 24, 24, 2, spp=(1, 4, 16))]
    capped = db.DeviceSet("cpu", max_spp=4)
    capped.add(scenes)
    assert set(capped.draw(256, 16, gen())["s"].tolist()) == {0, 1}
    every = db.DeviceSet("cpu")
    every.add(scenes)
    assert set(every.draw(256, 16, gen())["s"].tolist()) == {0, 1, 2}
    with pytest.raises(ValueError, match="at most"):
        db.DeviceSet("cpu", max_spp=0.5).add(scenes)


def test_spp_weights_set_each_spp_share_of_the_draws():
    """--spp-weights: each noisy spp is drawn in proportion to its weight (zero: never), and
    a weight list that does not fit the data set's spp is refused."""
    scenes = [scene("a", 24, 24, 1, spp=(1, 4, 16)), scene("b", 24, 24, 2, spp=(1, 4, 16))]
    ds = db.DeviceSet("cpu", spp_weights=[1, 0, 3])
    ds.add(scenes)
    s = ds.draw(4000, 16, torch.Generator().manual_seed(3))["s"]
    assert (s == 1).sum() == 0
    assert abs((s == 2).float().mean().item() - 0.75) < 0.03
    capped = db.DeviceSet("cpu", max_spp=4, spp_weights=[1, 1, 5])
    capped.add(scenes)
    assert set(capped.draw(256, 16, torch.Generator().manual_seed(3))["s"].tolist()) == {0, 1}
    for bad in ([1, 1], [1, -1, 1], [0, 0, 0]):
        with pytest.raises(ValueError, match="spp-weights"):
            db.DeviceSet("cpu", spp_weights=bad).add(scenes)


def test_spp_weights_option_refuses_what_it_cannot_use(capsys):
    """train --spp-weights: non-numbers and samplers without per-spp draws are refused with
    the reason, before any training starts."""
    from temc_train.drivers import train
    for argv, why in ((["--spp-weights", "1,x", "--sampler", "device"], "comma-separated"),
                      (["--spp-weights", "1,2"], "needs --sampler device")):
        with pytest.raises(SystemExit):
            train.main(["--data", "nowhere", "--arch", "temc2", "--width", "0.125", "--run-dir",
                        "nowhere", *argv])
        assert why in capsys.readouterr().err
