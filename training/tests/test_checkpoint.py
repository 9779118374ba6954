"""checkpoint.Checkpoint, the one reader and writer of runs: the round trip of each form,
and older runs (synthetic ones in the forms the committed runs had) read upgraded, build,
resume and ship."""

import glob
import os

import numpy as np
import pytest
import torch

from temc_train.checkpoint import OLD_HPARAMS, Checkpoint, load_checkpoint
from temc_train.drivers import budget, ship, train
from temc_train.models import RECON_DEFAULTS, build
from test_data_train import dataset  # noqa: F401  (the fixture)

RUNS = os.path.join(os.path.dirname(__file__), "..", "runs")
TRAINING_KEYS = ["model", "opt", "state", "arch", "width", "recon", "dataset"]


def tiny(levels=1, guide=False):
    torch.manual_seed(0)
    return build("temc2", 0.0625, levels, 5, "both", guide)


def adam_state(model) -> dict:
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    sum(p.sum() for p in model.parameters()).backward()
    opt.step()
    return train.compact_optimizer_state(opt.state_dict())


def outputs(model):
    xs = [torch.rand(1, c, 32, 32, generator=torch.Generator().manual_seed(3)) for c in (2, 1, 7)]
    with torch.no_grad():
        return model.eval()(*xs)


def test_a_training_checkpoint_round_trips(tmp_path):
    model = tiny()
    recon = dict(RECON_DEFAULTS, levels=1, guide=False)
    state = {"step": 7, "train_s": 12.5, "gpu_seconds": 0.0,
             "rng": np.random.default_rng(0).bit_generator.state, "hparams": {"lr": 1e-4}}
    ck = Checkpoint(model=train.cpu_state(model.state_dict()), opt=adam_state(model), state=state,
                    arch="temc2", width=0.0625, recon=recon, dataset="tiny")
    path = str(tmp_path / "checkpoint.pt")
    ck.write(path)
    raw = torch.load(path, weights_only=True)
    assert list(raw) == TRAINING_KEYS  # the file's form is drivers/train.py's, unchanged
    back = Checkpoint.read(path)
    assert back.training and back.steps == 7
    assert (back.arch, back.width, back.recon, back.dataset, back.state) == ("temc2", 0.0625, recon, "tiny", state)
    assert back.opt["state"].keys() == ck.opt["state"].keys()
    assert all(torch.equal(back.model[k], v) for k, v in ck.model.items())
    assert back.info() == {"dataset": "tiny", "train_steps": 7}
    assert back.recipe() == {**OLD_HPARAMS, "lr": 1e-4}
    built, arch, width = back.build()
    for a, b in zip(outputs(built), outputs(model)):
        assert torch.equal(a, b)


def test_a_final_model_round_trips(tmp_path):
    model = tiny()
    summary = {"train_steps": 3, "train_seconds": 1.0, "gpu_seconds": 0.0, "params": (10, 2)}
    path = str(tmp_path / "model.pt")
    Checkpoint(model=model.state_dict(), arch="temc2", width=0.0625, recon=dict(RECON_DEFAULTS, levels=1),
               dataset="tiny", summary=summary).write(path)
    raw = torch.load(path, weights_only=True)
    assert list(raw) == ["model", "arch", "width", "recon", "dataset", "train_steps", "train_seconds",
                         "gpu_seconds", "params"]
    back = Checkpoint.read(path)
    assert not back.training and back.steps == 3 and back.summary["params"] == (10, 2)
    _, arch, width, info = load_checkpoint(path)
    assert (arch, width, info) == ("temc2", 0.0625, {"dataset": "tiny", "train_steps": 3})


def test_a_bare_state_dict_needs_arch_and_width(tmp_path):
    path = str(tmp_path / "bare.pt")
    torch.save(tiny(levels=RECON_DEFAULTS["levels"]).state_dict(), path)
    ck = Checkpoint.read(path)
    assert ck.bare and ck.recon == RECON_DEFAULTS and ck.info() == {}
    with pytest.raises(ValueError, match="needs --arch"):
        ck.build()
    assert ck.build("temc2", 0.0625)[1:] == ("temc2", 0.0625)
    with pytest.raises(ValueError, match="has arch 'temc2', not 'ae'"):
        Checkpoint(model={}, arch="temc2", width=0.0625).build("ae", 0.0625)


def old_checkpoint(model, recon=True) -> dict:
    """The oldest committed form (21aae6e): no data set name, no GPU seconds, no hparams,
    "recon" without guide or fixed_range (or, older still, none)."""
    ck = {"model": model.state_dict(), "opt": adam_state(model),
          "state": {"step": 41, "train_s": 3600.0, "rng": np.random.default_rng(5).bit_generator.state},
          "arch": "temc2", "width": 0.0625}
    if recon:
        ck["recon"] = {"levels": 1, "kernel": 5, "split": "both", "demodulate": False, "eps": 0.01}
    return ck


@pytest.mark.parametrize("recon", [True, False], ids=["recon-without-guide", "no-recon"])
def test_an_old_checkpoint_reads_upgraded(tmp_path, recon):
    model = tiny(levels=1 if recon else RECON_DEFAULTS["levels"])
    path = str(tmp_path / "checkpoint.pt")
    torch.save(old_checkpoint(model, recon), path)
    ck = Checkpoint.read(path)
    assert ck.training and ck.dataset is None and ck.state["gpu_seconds"] == 0.0
    assert ck.recon == dict(RECON_DEFAULTS, levels=1 if recon else RECON_DEFAULTS["levels"])
    assert ck.recipe() == OLD_HPARAMS and "hparams" not in ck.state  # read, not stored
    assert ck.info() == {"train_steps": 41}
    built, *_ = ck.build()
    for a, b in zip(outputs(built), outputs(model)):
        assert torch.equal(a, b)
    assert budget.hours_for(str(tmp_path), 10.0, 0.5) == pytest.approx(1.5)
    facts = ship.checkpoint_facts(path, built, str(tmp_path / "some-data"))
    assert (facts["dataset"], facts["gpu_seconds"], facts["hparams"]) == ("some-data", 0.0, OLD_HPARAMS)
    # Written back, it is in the current form.
    ck.write(path)
    raw = torch.load(path, weights_only=True)
    assert list(raw) == TRAINING_KEYS and raw["recon"] == ck.recon and raw["state"]["gpu_seconds"] == 0.0


def test_an_old_checkpoint_resumes(dataset, tmp_path):  # noqa: F811
    run = tmp_path / "run"
    args = ["--data", dataset, "--arch", "temc2", "--width", "0.0625", "--levels", "1", "--run", str(run),
            "--crop", "32", "--batch", "2", "--val-minutes", "0", "--threads", "1"]
    train.main(args + ["--max-steps", "1"])
    path = str(run / "checkpoint.pt")
    raw = torch.load(path, weights_only=True)
    old = {k: raw[k] for k in ("model", "opt", "arch", "width")}
    old["state"] = {k: raw["state"][k] for k in ("step", "train_s", "rng")}
    old["recon"] = {k: raw["recon"][k] for k in ("levels", "kernel", "split", "demodulate", "eps")}
    torch.save(old, path)
    train.main(args + ["--max-steps", "2"])
    raw = torch.load(path, weights_only=True)
    assert list(raw) == TRAINING_KEYS and raw["state"]["step"] == 2
    assert raw["recon"] == dict(RECON_DEFAULTS, levels=1)
    assert raw["dataset"] == os.path.basename(dataset) and raw["state"]["gpu_seconds"] == 0.0


def test_a_checkpoint_never_holds_non_finite_weights(tmp_path):
    model = tiny()
    path = str(tmp_path / "checkpoint.pt")
    good = Checkpoint(model=model.state_dict(), opt=None, state={"step": 1}, arch="temc2", width=0.0625)
    good.write(path)
    bad = {k: v.clone() for k, v in model.state_dict().items()}
    next(v for v in bad.values() if v.is_floating_point())[0] = float("nan")
    with pytest.raises(SystemExit, match="non-finite"):
        Checkpoint(model=bad, opt=None, state={"step": 2}, arch="temc2", width=0.0625).write(path)
    assert torch.load(path, weights_only=True)["state"]["step"] == 1  # the last one is kept


def test_a_large_checkpoint_drops_the_moments(tmp_path):
    model = tiny()
    path = str(tmp_path / "checkpoint.pt")
    ck = Checkpoint(model=model.state_dict(), opt=adam_state(model), state={"step": 1},
                    arch="temc2", width=0.0625)
    ck.write(path, limit=10**9)
    assert torch.load(path, weights_only=True)["opt"] is not None
    ck.write(path, limit=1000)
    saved = torch.load(path, weights_only=True)
    assert saved["opt"] is None and saved["state"]["opt_dropped"] and ck.opt is not None


@pytest.mark.parametrize("run", sorted(glob.glob(os.path.join(RUNS, "*", "checkpoint.pt"))),
                         ids=lambda p: os.path.basename(os.path.dirname(p)))
def test_committed_runs_read_as_training_checkpoints(run):
    ck = Checkpoint.read(run)
    # Adam's moments may be left out only on record (opt_dropped): a resume restarts them.
    assert ck.training and ck.steps > 0 and (ck.opt is not None or ck.state.get("opt_dropped"))
    assert set(ck.recon) == set(RECON_DEFAULTS) and ck.info()["train_steps"] == ck.steps
    assert list(ck.to_dict()) == TRAINING_KEYS


def test_two_checkpoints_average_to_the_mean_of_their_weights(tmp_path):
    """drivers.average: the weights' mean, the first checkpoint's state and steps, no moments;
    checkpoints of different networks are refused."""
    from temc_train.drivers import average
    a, b = tiny(), tiny()
    with torch.no_grad():
        for p in b.parameters():
            p.add_(1.0)
    state = {"step": 7, "train_s": 3.0, "gpu_seconds": 0.0}
    for name, m, st in (("a", a, state), ("b", b, dict(state, step=5))):
        Checkpoint(model=m.state_dict(), arch="temc2", width=0.0625, dataset="tiny",
                   opt=adam_state(m), state=st).write(str(tmp_path / f"{name}.pt"))
    average.main([str(tmp_path / "a.pt"), str(tmp_path / "b.pt"), str(tmp_path / "mean.pt")])
    got = Checkpoint.read(str(tmp_path / "mean.pt"))
    assert got.steps == 7 and got.opt is None and got.state["opt_dropped"] == "weights averaged"
    sa, sb = a.state_dict(), b.state_dict()
    moved = [k for k, v in got.model.items() if torch.is_floating_point(v)
             and torch.allclose(v, (sa[k] + sb[k]) / 2, atol=1e-6) and not torch.equal(v, sa[k])]
    assert all(torch.allclose(v, (sa[k] + sb[k]) / 2, atol=1e-6) if torch.is_floating_point(v)
               else torch.equal(v, sa[k]) for k, v in got.model.items())
    assert len(moved) >= len(list(a.parameters()))  # every weight moved half way
    other = Checkpoint(model=tiny(levels=2).state_dict(), arch="temc2", width=0.0625,
                       recon=dict(RECON_DEFAULTS, levels=2))
    with pytest.raises(ValueError):
        Checkpoint.read(str(tmp_path / "a.pt")).averaged(other)


def test_one_checkpoint_alone_is_written_without_its_moments(tmp_path):
    """drivers.average with one checkpoint: its weights, steps and seconds exactly, no Adam
    moments (a run's end shipped within the tree budget), and a smaller file."""
    from temc_train.drivers import average
    m = tiny()
    state = {"step": 11, "train_s": 4.0, "gpu_seconds": 1.0}
    Checkpoint(model=m.state_dict(), arch="temc2", width=0.0625, dataset="tiny",
               opt=adam_state(m), state=state).write(str(tmp_path / "end.pt"))
    average.main([str(tmp_path / "end.pt"), str(tmp_path / "slim.pt")])
    got = Checkpoint.read(str(tmp_path / "slim.pt"))
    assert got.opt is None and got.state["opt_dropped"] == "left out for the tree budget"
    assert got.steps == 11 and got.state["train_s"] == 4.0 and got.state["gpu_seconds"] == 1.0
    assert all(torch.equal(v, m.state_dict()[k]) for k, v in got.model.items())
    assert os.path.getsize(tmp_path / "slim.pt") < os.path.getsize(tmp_path / "end.pt")
    with pytest.raises(SystemExit):
        average.main(["--branches", str(tmp_path / "end.pt"), str(tmp_path / "bad.pt")])


def test_three_checkpoints_average_to_the_mean_of_their_weights(tmp_path):
    """drivers.average takes several checkpoints (snapshots along one cycle): each weight
    is the mean of all three, and the first one's steps stay."""
    from temc_train.drivers import average
    nets = [tiny() for _ in range(3)]
    with torch.no_grad():
        for i, m in enumerate(nets):
            for p in m.parameters():
                p.fill_(float(i))
    for i, m in enumerate(nets):
        Checkpoint(model=m.state_dict(), arch="temc2", width=0.0625, dataset="tiny",
                   opt=adam_state(m), state={"step": 9 - i, "train_s": 1.0, "gpu_seconds": 0.0}
                   ).write(str(tmp_path / f"{i}.pt"))
    average.main([str(tmp_path / f"{i}.pt") for i in range(3)] + [str(tmp_path / "mean.pt")])
    got = Checkpoint.read(str(tmp_path / "mean.pt"))
    assert got.steps == 9 and got.opt is None
    params = [k for k, _ in nets[0].named_parameters()]
    # Near (0 + 1 + 2) / 3 = 1: adam_state's step moved each net's weights by its lr.
    assert params and all(torch.allclose(got.model[k], sum(m.state_dict()[k] for m in nets) / 3,
                                         atol=1e-6)
                          and torch.allclose(got.model[k], torch.ones_like(got.model[k]), atol=1e-2)
                          for k in params)


def test_branch_ends_average_with_every_branch_s_training_time(tmp_path):
    """drivers.average --branches: two runs from one start, averaged, count the start's
    seconds once and each branch's own on top (the card's CPU hours); a 'branch' with less
    time than its start is refused."""
    from temc_train.drivers import average
    seconds = {"end1": (30.0, 2.0), "end2": (25.0, 0.0), "start": (10.0, 0.0)}
    for name, (cpu, gpu) in seconds.items():
        m = tiny()
        Checkpoint(model=m.state_dict(), arch="temc2", width=0.0625, dataset="tiny", opt=None,
                   state={"step": int(cpu), "train_s": cpu, "gpu_seconds": gpu}
                   ).write(str(tmp_path / f"{name}.pt"))
    paths = [str(tmp_path / f"{n}.pt") for n in ("end1", "end2", "start")]
    average.main(["--branches", *paths, str(tmp_path / "soup.pt")])
    got = Checkpoint.read(str(tmp_path / "soup.pt"))
    assert got.steps == 30 and got.state["train_s"] == 10.0 + 20.0 + 15.0
    assert got.state["gpu_seconds"] == 2.0
    average.main([*paths, str(tmp_path / "plain.pt")])
    assert Checkpoint.read(str(tmp_path / "plain.pt")).state["train_s"] == 30.0
    with pytest.raises(ValueError, match="less train_s"):
        average.main(["--branches", paths[2], paths[0], str(tmp_path / "bad.pt")])
