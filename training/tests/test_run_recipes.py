"""The scripts that resume the committed runs (scripts/train-all on the CPU, scripts/gpu-session
through scripts/train-gpu on a lent GPU) ask for the network and the reconstruction each
run's checkpoint holds. train.py switches a fixed function (train.SWITCHABLE) to whatever
the flags say, so a flag left out would go on training the shipped weights without the
fence they ship with, and record the switch in the checkpoint. A recipe may switch a fixed
function to the setting its run ships with (ship.SHIP_RECON and FILE_RECON): training as
the model runs, on purpose."""

import os
import re
import shlex

import pytest

from temc_train.checkpoint import Checkpoint
from temc_train.drivers import ship, train

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
SCRIPTS = os.path.join(ROOT, "scripts")


def script(name: str) -> str:
    """A script's text with its continuation lines joined."""
    with open(os.path.join(SCRIPTS, name)) as f:
        return f.read().replace("\\\n", " ")


def array(text: str, name: str) -> list:
    """The words of a bash array assignment `name=(...)`; shell variables read as 1 (the
    recipes' variables are numbers: the learning rate, minutes)."""
    m = re.search(rf"^\s*{name}=\((.*?)\)", text, re.S | re.M)
    assert m, f"no {name}=(...) array"
    return ["1" if w.startswith("$") else w for w in shlex.split(m.group(1), comments=True)]


def train_all_recipes():
    """(run, train.py arguments) of every `pair` in scripts/train-all."""
    text = script("train-all")
    common = array(text, "common")
    out = []
    for line in text.splitlines():
        if not line.startswith("pair "):
            continue
        words = shlex.split(line, comments=True)[1:]
        cut = words.index("--")
        for half in (words[:cut], words[cut + 1:]):
            run, _hours, arch, width, *flags = half
            out.append((run, ["--arch", arch, "--width", width, *common, *flags]))
    return out


def gpu_session_recipes():
    """(run, train.py arguments) of every scripts/train-gpu call in scripts/gpu-session, as
    train-gpu's `one` composes them: its common arguments, the network, then the extras."""
    text = script("gpu-session")
    train_gpu = script("train-gpu")
    common = array(train_gpu, "common")
    net = re.search(r'^\s*one "\$out" (--arch \S+ --width \S+)', train_gpu, re.M).group(1).split()
    # The first assignment of each `*_from` variable: the run a recipe continues.
    starts = dict(re.findall(r"^(\w+_from)=(\S+)$", text, re.M)[::-1])
    out = []
    for line in text.splitlines():
        if "scripts/train-gpu" not in line or "exec" not in line:
            continue
        words = [w for w in shlex.split(line, comments=True) if w != ";;"]
        at = words.index("--from")
        source = words[at + 1]
        source = starts.get(source.lstrip("$"), source)
        flags = words[at + 2:]
        out.append((os.path.basename(source), [*common, *net, *flags]))
    return out


RECIPES = [("train-all", *r) for r in train_all_recipes()] + \
          [("gpu-session", *r) for r in gpu_session_recipes()]


def test_every_script_is_read():
    """The parsers above found the runs they are meant to check (an edit that changes the
    scripts' form fails here, not silently)."""
    runs = {(s, r) for s, r, _ in RECIPES}
    assert ("train-all", "temc2-w0.125-energy") in runs
    assert ("train-all", "temc2-w0.0625-single") in runs
    assert ("gpu-session", "temc2-w0.125-l3") in runs
    assert ("gpu-session", "temc2-w0.0625-l3") in runs


@pytest.mark.parametrize("source,run,args", RECIPES, ids=[f"{s}:{r}" for s, r, _ in RECIPES])
def test_recipe_matches_its_checkpoint(source, run, args):
    path = os.path.join(ROOT, "training", "runs", run, "checkpoint.pt")
    if not os.path.exists(path):
        pytest.skip(f"{run}: no committed checkpoint")
    a = train.arg_parser().parse_args(["--data", "unused", "--run", "unused", *args])
    ck = Checkpoint.read(path)
    assert (a.arch, a.width) == (ck.arch, ck.width)
    wanted = train.recon_settings(a)
    held = {k: ck.recon.get(k) for k in wanted}
    shipped = shipped_recon(run)
    differ = {k for k in wanted if wanted[k] != held[k]}
    switched = {k for k in differ if k in train.SWITCHABLE and k in shipped and wanted[k] == shipped[k]}
    assert differ == switched, (f"{source} resumes {run} with {wanted}, its checkpoint holds "
                                f"{held} and it ships with {shipped}")


def shipped_recon(run: str) -> dict:
    """The reconstruction settings a run's model files ship with ({} for a run that ships
    none; the files of one run must agree)."""
    files = [f for f, (r, *_) in ship.SHIPPED.items() if r == run]
    recons = [{**ship.SHIP_RECON, **ship.FILE_RECON.get(f, {})} for f in files]
    assert all(r == recons[0] for r in recons), f"{run}'s files ship with {recons}"
    return recons[0] if recons else {}
