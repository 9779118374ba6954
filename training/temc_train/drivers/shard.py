"""A compact training shard: a data set's training (and validation) arrays in one file that
travels with the working tree to a machine with a GPU and PyTorch but no Rust toolchain,
no renderer and no network (`scripts/train-gpu`).

    python -m temc_train.drivers.shard --data ../data/spectral-v2 --out shards/v2.npz --max-mib 60 \\
        [--crop 128] [--crops-per-scene 1] [--val-mib 8] [--seed 0]

The file is a zip (`.npz`, deflated) of float16 arrays, one group per item, plus
`manifest.json` (data set name, spp list, the items and where they came from). An item is
one training scene of `data.load_split`'s split (scenes taken in a seeded random order),
either whole (`--crop 0`) or as `--crops-per-scene` random crops of `--crop` pixels, with
every noisy spp: what `data.make_sample` reads (noisy colour per spp, albedo, camera-space
normal, depth, the reference) and the per-image statistics the core takes over the *whole*
image, which a crop could not recompute: the automatic exposure scale and the depth scale.
Items are added until the next one could pass `--max-mib` (the file never does). The
validation part comes first: the centre `data.CROP` crop of each val scene (what
`data.validation_set` takes), at most `--val-mib`.

Precision: colour is stored times its image's exposure scale and the reference times its
own, depth divided by its depth scale, so float16 keeps its relative precision however dark
or bright the scene is (normal and albedo are stored as they are). Finite values past
float16's range (65504, after that normalisation: a pathological highlight) are clamped to
it, counted in the manifest and reported; NaN and infinities stay what they are (the
loader sanitises them as before).

`load(path) -> (train_scenes, val_scenes)` returns objects with `data.Scene`'s interface
(`name`, `spp`, `a` (float32 arrays), `scale`, `depth_scale`, `shape`), so
`data.make_sample`, `data.batch` and `data.validation_set` work on them unchanged.
"""

import argparse
import io
import json
import os
import zipfile
import zlib

import numpy as np

from .. import data

F16_MAX = 65504.0
FORMAT = "temc-shard"
VERSION = 1
KEYS = ("color", "albedo", "normal", "depth", "reference")
# Zip bookkeeping per entry (local header + central directory, generous) and room for the
# manifest (written last), kept free so the file never passes the limit.
ENTRY_OVERHEAD = 256
MANIFEST_RESERVE = 16 * 1024
MANIFEST_PER_ITEM = 1024


class ShardScene:
    """One shard item with `data.Scene`'s interface."""

    def __init__(self, name, spp, a, scale, depth_scale):
        self.name = name
        self.spp = list(spp)
        self.a = a
        self.scale = list(scale)
        self.depth_scale = list(depth_scale)

    @property
    def shape(self):
        return self.a["reference"].shape[:2]


def _f16(x, clamped: dict, key: str) -> np.ndarray:
    x = np.asarray(x, np.float32)
    fin = np.isfinite(x)
    over = fin & (np.abs(x) > F16_MAX)
    n = int(over.sum())
    if n:
        clamped[key] = clamped.get(key, 0) + n
        x = np.where(over, np.clip(x, -F16_MAX, F16_MAX), x)
    return x.astype(np.float16)


def _encode(sc, sl, clamped: dict) -> dict:
    """One item's arrays (float16, normalised as the module doc says) and statistics
    (float64) from a data.Scene and a (rows, cols) slice."""
    scale = np.asarray(sc.scale, np.float64)
    ds = np.asarray([np.nan if d is None else d for d in sc.depth_scale], np.float64)
    ref = sc.a["reference"][sl]
    ref_gain = np.float32(data.auto_input_scale(sc.a["reference"]))
    dgain = np.where(np.isfinite(ds), 1.0 / ds, 1.0).astype(np.float32)
    # scale and depth_scale as float64, so the loader's are the data.Scene's exactly.
    k = scale.astype(np.float32)[:, None, None, None]
    return {
        "color": _f16(sc.a["color"][(slice(None),) + sl] * k, clamped, "color"),
        "albedo": _f16(sc.a["albedo"][(slice(None),) + sl], clamped, "albedo"),
        "normal": _f16(sc.a["normal"][(slice(None),) + sl], clamped, "normal"),
        "depth": _f16(sc.a["depth"][(slice(None),) + sl] * dgain[:, None, None], clamped, "depth"),
        "reference": _f16(ref * ref_gain, clamped, "reference"),
        "scale": scale,
        "depth_scale": ds,
        "reference_gain": np.asarray([ref_gain], np.float32),
    }


def _decode(z, prefix: str, rec: dict) -> ShardScene:
    g = lambda k: z[f"{prefix}/{k}"]  # noqa: E731
    scale, ds = g("scale"), g("depth_scale")
    dmul = np.where(np.isfinite(ds), ds, 1.0).astype(np.float32)
    a = {
        "color": g("color").astype(np.float32) / scale.astype(np.float32)[:, None, None, None],
        "albedo": g("albedo").astype(np.float32),
        "normal": g("normal").astype(np.float32),
        "depth": g("depth").astype(np.float32) * dmul[:, None, None],
        "reference": g("reference").astype(np.float32) / g("reference_gain")[0],
    }
    return ShardScene(rec["name"], rec["spp"], a, [float(s) for s in scale],
                      [None if not np.isfinite(d) else float(d) for d in ds])


def _write_array(zf: zipfile.ZipFile, name: str, arr: np.ndarray) -> None:
    with zf.open(name + ".npy", "w", force_zip64=True) as f:
        np.lib.format.write_array(f, np.ascontiguousarray(arr), allow_pickle=False)


def _nbytes(arrays: dict) -> int:
    """An item's bytes in the file: each array as .npy, deflated as zipfile does it (level
    6, raw deflate), plus the zip's headers for it."""
    n = 0
    for v in arrays.values():
        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.ascontiguousarray(v), allow_pickle=False)
        c = zlib.compressobj(6, zlib.DEFLATED, -15)
        n += len(c.compress(buf.getbuffer())) + len(c.flush()) + ENTRY_OVERHEAD
    return n


def read_manifest(path: str) -> dict:
    with zipfile.ZipFile(path) as zf:
        return json.loads(zf.read("manifest.json"))


def load(path: str):
    """(train_scenes, val_scenes) of a shard, as ShardScene objects."""
    m = read_manifest(path)
    if m.get("format") != FORMAT:
        raise ValueError(f"{path}: not a {FORMAT} file")
    with np.load(path, allow_pickle=False) as z:
        train = [_decode(z, f"train/{i:05}", r) for i, r in enumerate(m["train"])]
        val = [_decode(z, f"val/{i:05}", r) for i, r in enumerate(m["val"])]
    return train, val


def _records(root: str, split: str) -> list:
    with open(os.path.join(root, "manifest.json")) as f:
        return [r for r in json.load(f)["scenes"] if r["split"] == split]


def pack(data_dir: str, out: str, max_mib: float = 60.0, crop: int = data.CROP,
         crops_per_scene: int = 1, val_mib=None, seed: int = 0, verbose: bool = True) -> dict:
    """Writes the shard; returns its manifest. One scene is in memory at a time."""
    limit = int(max_mib * 2**20)
    val_limit = int((max_mib / 8 if val_mib is None else val_mib) * 2**20)
    rng = np.random.default_rng(seed)
    clamped: dict = {}
    manifest = {"format": FORMAT, "version": VERSION,
                "dataset": os.path.basename(os.path.normpath(data_dir)),
                "crop": crop, "crops_per_scene": crops_per_scene, "seed": seed,
                "max_mib": max_mib, "train": [], "val": []}
    train_recs = _records(data_dir, "train")
    val_recs = _records(data_dir, "val")
    order = rng.permutation(len(train_recs))
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    tmp = out + f".tmp-{os.getpid()}"
    spp = set()
    full = {"train": False, "val": False}
    try:
        with open(tmp, "wb") as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as zf:
            def add(part, sc, sl, origin, cap):
                arrays = _encode(sc, sl, clamped)
                items = len(manifest["train"]) + len(manifest["val"]) + 1
                need = (_nbytes(arrays) + ENTRY_OVERHEAD * len(zf.infolist())
                        + MANIFEST_RESERVE + MANIFEST_PER_ITEM * items)
                if fh.tell() + need > cap:
                    full[part] = True
                    return False
                i = len(manifest[part])
                for k, v in arrays.items():
                    _write_array(zf, f"{part}/{i:05}/{k}", v)
                h, w = arrays["reference"].shape[:2]
                manifest[part].append({"name": sc.name if origin is None else f"{sc.name}@{origin[0]},{origin[1]}",
                                       "scene": sc.name, "origin": list(origin or (0, 0)),
                                       "shape": [h, w], "spp": sc.spp})
                spp.update(sc.spp)
                return True

            # Validation first: the centre crop validation_set takes.
            for rec in val_recs:
                sc = data.Scene(data_dir, rec)
                h, w = sc.shape
                c = min(data.CROP, h, w)
                o = ((h - c) // 2, (w - c) // 2)
                if not add("val", sc, (slice(o[0], o[0] + c), slice(o[1], o[1] + c)),
                           o if (c, c) != (h, w) else None, min(val_limit, limit)):
                    break
            for j in order:
                sc = data.Scene(data_dir, train_recs[j])
                h, w = sc.shape
                if crop <= 0 or (crop >= h and crop >= w):
                    spots = [None]
                else:
                    c = min(crop, h, w)
                    spots = [(int(rng.integers(h - c + 1)), int(rng.integers(w - c + 1)))
                             for _ in range(crops_per_scene)]
                for o in spots:
                    sl = ((slice(None), slice(None)) if o is None else
                          (slice(o[0], o[0] + c), slice(o[1], o[1] + c)))
                    if not add("train", sc, sl, o, limit):
                        break
                if full["train"]:
                    break
                if verbose and len(manifest["train"]) % 25 == 0:
                    print(f"{len(manifest['train'])} training items, {fh.tell() / 2**20:.1f} MiB",
                          flush=True)
            manifest.update({"spp": sorted(spp), "clamped": clamped,
                             "train_scenes": len({r["scene"] for r in manifest["train"]}),
                             "train_scenes_in_split": len(train_recs),
                             "val_scenes_in_split": len(val_recs)})
            zf.writestr("manifest.json", json.dumps(manifest))
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    size = os.path.getsize(out)
    assert size <= limit, (size, limit)
    if verbose:
        print(f"{out}: {size / 2**20:.1f} MiB, {len(manifest['train'])} training items from "
              f"{manifest['train_scenes']}/{len(train_recs)} scenes, {len(manifest['val'])}/"
              f"{len(val_recs)} validation scenes, spp {manifest['spp']}", flush=True)
        if full["train"]:
            print(f"stopped at --max-mib {max_mib:g}: the training split has more", flush=True)
        if full["val"]:
            print(f"validation part stopped at {val_limit / 2**20:.1f} MiB", flush=True)
        if val_recs and not manifest["val"]:
            print("warning: no validation scene fits --val-mib: training validates on its "
                  "first two training items", flush=True)
        for k, n in clamped.items():
            print(f"warning: {n} {k} values past float16's range clamped to +-{F16_MAX:g}", flush=True)
    return manifest


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a temc-render dataset folder")
    ap.add_argument("--out", required=True, help="the shard file (.npz)")
    ap.add_argument("--max-mib", type=float, default=60.0, help="the file's size limit")
    ap.add_argument("--crop", type=int, default=data.CROP,
                    help="crop size of the training items (0: whole images)")
    ap.add_argument("--crops-per-scene", type=int, default=1)
    ap.add_argument("--val-mib", type=float, default=None,
                    help="size limit of the validation part (default: an eighth of --max-mib)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    pack(a.data, a.out, a.max_mib, a.crop, a.crops_per_scene, a.val_mib, a.seed)


if __name__ == "__main__":
    main()
