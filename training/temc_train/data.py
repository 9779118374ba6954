"""Training data from a `temc-render dataset` folder (layout: docs/render.md).

Each scene's EXRs are read once and cached beside them as `arrays.npz` (float32). A
training sample follows the paper's recipe where it fits:

- a random scene of the split, a random noisy spp, and a random 128x128 crop;
- a random flip and 90-degree rotation. Normals are first turned into camera space (the
  camera comes from the scene file), so the image transform can be applied to them too.
  Half the samples then get a random 3-D rotation of the normals, so world-space normals
  (what Blender and most renderers write) are also in distribution;
- exposure: the core's automatic rule (0.18 over the log-average luminance of the whole
  noisy image, `src/color`), jittered by up to one stop, applied to noisy and reference
  alike;
- aux dropout: with probability `p_color_only` no aux at all (the contract's fill: albedo
  0, zero normal, depth 0), with `p_albedo_only` albedo without normal and depth, else
  everything. One model then serves the three input sets.

The network's inputs are the core's encoding (`color.py`, the same numbers as
`src/color`): chroma (H, S), luma (V) and aux [7]. What the reconstruction filters and the
loss compares is linear: the sanitised noisy radiance, the albedo feature (for
demodulation) and the reference, noisy and reference both times the sample's exposure, so
that the loss's PQ encoding sees the luminances the network saw.
"""

import json
import os

import numpy as np

from . import color

CROP = 128


def read_exr(path: str) -> dict:
    """Layers of one temc-render EXR as float32 arrays: color/albedo/normal [H,W,3],
    depth [H,W]. Without the OpenEXR package (the GPU machine), exr_numpy reads it."""
    try:
        import Imath
        import OpenEXR
    except ImportError:
        from . import exr_numpy

        ch = exr_numpy.read(path)
        return {"color": np.stack([ch[f"color.{c}"] for c in "RGB"], -1),
                "albedo": np.stack([ch[f"albedo.{c}"] for c in "RGB"], -1),
                "normal": np.stack([ch[f"normal.{c}"] for c in "XYZ"], -1),
                "depth": ch["depth.Z"]}

    f = OpenEXR.InputFile(path)
    try:
        dw = f.header()["dataWindow"]
        w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
        pt = Imath.PixelType(Imath.PixelType.FLOAT)

        def ch(name):
            return np.frombuffer(f.channel(name, pt), np.float32).reshape(h, w)

        return {
            "color": np.stack([ch(f"color.{c}") for c in "RGB"], -1),
            "albedo": np.stack([ch(f"albedo.{c}") for c in "RGB"], -1),
            "normal": np.stack([ch(f"normal.{c}") for c in "XYZ"], -1),
            "depth": ch("depth.Z").copy(),
        }
    finally:
        f.close()


def camera_frame(scene_text: str) -> np.ndarray:
    """Rows: the camera's right, up and backward axes in world space, as temc-render builds
    them (right = forward x world up, so the camera's right is the image's +x)."""
    for line in scene_text.splitlines():
        t = line.split("#")[0].split()
        if t and t[0] == "camera":
            eye = np.array([float(v) for v in t[t.index("eye") + 1:t.index("eye") + 4]])
            tgt = np.array([float(v) for v in t[t.index("target") + 1:t.index("target") + 4]])
            fwd = (tgt - eye) / np.linalg.norm(tgt - eye)
            right = np.cross(fwd, [0.0, 1.0, 0.0])
            right /= np.linalg.norm(right)
            up = np.cross(right, fwd)
            return np.stack([right, up, -fwd]).astype(np.float32)
    return np.eye(3, dtype=np.float32)


class Scene:
    """One scene's arrays: noisy renders per spp and the reference."""

    def __init__(self, root: str, record: dict):
        self.name = record["name"]
        d = os.path.join(root, record["dir"])
        cache = os.path.join(d, "arrays.npz")
        self.spp = [int(s) for s, _ in record["noisy"]]
        self.noisy_paths = [os.path.join(d, f) for _, f in record["noisy"]]
        self.reference_path = os.path.join(d, record["reference"])
        if not os.path.exists(cache):
            layers = [read_exr(os.path.join(d, f)) for _, f in record["noisy"]]
            ref = read_exr(os.path.join(d, record["reference"]))
            frame = camera_frame(open(os.path.join(d, "scene.txt")).read())
            arrays = {
                "color": np.stack([x["color"] for x in layers]),
                "albedo": np.stack([x["albedo"] for x in layers]),
                # Camera-space normals, so flips and rotations can be applied to them.
                "normal": np.stack([x["normal"] @ frame.T for x in layers]),
                "depth": np.stack([x["depth"] for x in layers]),
                "reference": ref["color"],
            }
            tmp = cache + f".tmp-{os.getpid()}.npz"
            np.savez(tmp, **arrays)
            os.replace(tmp, cache)
        z = np.load(cache)
        self.a = {k: z[k] for k in z.files}
        # Automatic exposure and depth normalisation per noisy image, over the whole image
        # (as the core does before tiling).
        self.scale = [auto_input_scale(c) for c in self.a["color"]]
        self.depth_scale = [color.depth_scale(d) for d in self.a["depth"]]
        # Noise2Noise targets: the reference render's prefixes (independent of the noisy
        # inputs' seed), read on first use.
        self._prefixes = {int(s): os.path.join(d, f) for s, f in record.get("reference_prefixes", [])}

    def noisy_reference(self, spp: int) -> np.ndarray:
        """The reference render's first `spp` samples (a Noise2Noise target)."""
        key = f"reference_spp{spp}"
        if key not in self.a:
            if spp not in self._prefixes:
                raise KeyError(f"{self.name}: no {spp}-spp reference prefix")
            self.a[key] = read_exr(self._prefixes[spp])["color"]
        return self.a[key]

    def has_reference_prefix(self, spp: int) -> bool:
        return spp in self._prefixes

    @property
    def shape(self):
        return self.a["reference"].shape[:2]


def auto_input_scale(rgb: np.ndarray) -> float:
    """The core's automatic exposure (src/color/mod.rs `auto_input_scale`)."""
    c = color.sanitize_rgb(rgb.reshape(-1, 3)).astype(np.float64)
    y = c @ np.asarray(color.LUMA, np.float32).astype(np.float64)
    y = y[y > 1e-8]
    if y.size == 0:
        return 1.0
    return float(np.clip(color.AUTO_EXPOSURE_KEY / np.exp(np.log(y).mean()), 1e-20, 1e20))


def _records(root: str, split: str, prefix_spp=None) -> list:
    """The manifest's finished scenes of a split; with `prefix_spp`, only those that have a
    reference prefix at that spp (Noise2Noise targets), so the rest are never read."""
    with open(os.path.join(root, "manifest.json")) as f:
        m = json.load(f)
    return [r for r in m["scenes"] if r["split"] == split
            and (not prefix_spp or any(int(s) == prefix_spp for s, _ in r.get("reference_prefixes", [])))]


def load_split(root: str, split: str, prefix_spp=None) -> list:
    """Every finished scene of a split (see `_records` for `prefix_spp`)."""
    return [Scene(root, r) for r in _records(root, split, prefix_spp)]


def refresh_split(root: str, split: str, scenes: list, prefix_spp=None) -> list:
    """`scenes` plus the split's scenes finished since they were loaded: a run started while
    the data set still renders trains on every scene as it lands."""
    have = {s.name for s in scenes}
    new = [Scene(root, r) for r in _records(root, split, prefix_spp) if r["name"] not in have]
    if new:
        print(f"{len(new)} new {split} scene(s), {len(scenes) + len(new)} in all", flush=True)
    return scenes + new


class SceneLoader:
    """A split's scenes as they finish, read in worker processes: on a GPU machine that
    renders while it trains, reading a scene's EXRs (exr_numpy, about a quarter second)
    on the training thread would leave the GPU idle. `poll` hands back the scenes read
    since the last call and never waits. Workers are spawned, not forked (the parent
    holds CUDA state)."""

    def __init__(self, root: str, split: str, have, workers: int = 2):
        import concurrent.futures
        import multiprocessing

        self.root, self.split, self.seen = root, split, set(have)
        self.pool = concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
        self.pending = []

    def poll(self) -> list:
        for r in _records(self.root, self.split):
            if r["name"] not in self.seen:
                self.seen.add(r["name"])
                self.pending.append(self.pool.submit(Scene, self.root, r))
        done = [f for f in self.pending if f.done()]
        self.pending = [f for f in self.pending if not f.done()]
        return [f.result() for f in done]

    def close(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q.astype(np.float32)


def _transform(x: np.ndarray, flip: bool, k: int) -> np.ndarray:
    if flip:
        x = x[:, ::-1]
    return np.rot90(x, k, axes=(0, 1))


def _transform_normal(n: np.ndarray, flip: bool, k: int) -> np.ndarray:
    """Camera-space normals under the image transform: a horizontal flip mirrors x, each
    quarter turn (counter-clockwise on screen) turns (x, y) to (-y, x)."""
    n = _transform(n, flip, k).copy()
    if flip:
        n[..., 0] = -n[..., 0]
    for _ in range(k % 4):
        n[..., [0, 1]] = np.stack([-n[..., 1], n[..., 0]], -1)
    return n


def make_sample(scene: Scene, rng: np.random.Generator, crop: int = CROP, spp_index=None,
                augment: bool = True, aux_mode: str = "random", p_color_only: float = 0.2,
                p_albedo_only: float = 0.2, origin=None, target_spp=None):
    """(chroma [2,c,c], luma [1,c,c], aux [7,c,c], noisy [3,c,c], albedo [3,c,c],
    reference [3,c,c]) float32 for one crop; noisy and reference are linear, times the
    exposure. With `target_spp` the "reference" is the reference render's prefix at that
    spp instead (Noise2Noise)."""
    h, w = scene.shape
    c = min(crop, h, w)
    s = int(rng.integers(len(scene.spp))) if spp_index is None else spp_index
    if origin is None:
        y0, x0 = int(rng.integers(h - c + 1)), int(rng.integers(w - c + 1))
    else:
        y0, x0 = origin
    sl = (slice(y0, y0 + c), slice(x0, x0 + c))
    noisy = scene.a["color"][s][sl]
    ref = (scene.a["reference"] if target_spp is None else scene.noisy_reference(target_spp))[sl]
    alb = scene.a["albedo"][s][sl]
    nrm = scene.a["normal"][s][sl]
    dep = color.depth(scene.a["depth"][s][sl], scene.depth_scale[s])
    scale = scene.scale[s]
    if augment:
        flip, k = bool(rng.integers(2)), int(rng.integers(4))
        noisy, ref, alb, dep = (_transform(x, flip, k) for x in (noisy, ref, alb, dep))
        nrm = _transform_normal(nrm, flip, k)
        if rng.random() < 0.5:
            nrm = nrm @ random_rotation(rng).T
        scale *= float(2.0 ** rng.uniform(-1.0, 1.0))
    mode = aux_mode
    if mode == "random":
        u = rng.random()
        mode = "none" if u < p_color_only else "albedo" if u < p_color_only + p_albedo_only else "full"
    if mode in ("none", "albedo"):
        nrm = np.zeros_like(nrm)
        dep = np.zeros_like(dep)
    if mode == "none":
        alb = np.zeros_like(alb)
    hsv, _ = color.encode(np.ascontiguousarray(noisy), scale)
    k = np.float32(scale)
    lin = lambda x: np.moveaxis(color.sanitize_rgb(np.ascontiguousarray(x)), -1, 0) * k  # noqa: E731
    albedo = np.moveaxis(color.albedo(alb), -1, 0)
    aux = np.concatenate([albedo,
                          np.moveaxis(color.normal(nrm), -1, 0),
                          np.asarray(dep, np.float32)[None]])
    hsv = np.moveaxis(hsv, -1, 0)
    f32 = lambda x: np.ascontiguousarray(x, dtype=np.float32)  # noqa: E731
    return (f32(hsv[:2]), f32(hsv[2:3]), f32(aux), f32(lin(noisy)), f32(albedo), f32(lin(ref)))


def batch(scenes: list, rng: np.random.Generator, n: int, crop: int = CROP, **kw):
    """A training batch as six stacked arrays (make_sample's)."""
    items = [make_sample(scenes[int(rng.integers(len(scenes)))], rng, crop, **kw) for _ in range(n)]
    return [np.stack(x) for x in zip(*items)]


def validation_set(scenes: list, crop: int = CROP) -> list:
    """Deterministic validation batches: the centre crop of every scene at every spp, with
    full aux and the automatic exposure (no augmentation)."""
    rng = np.random.default_rng(0)
    out = []
    for sc in scenes:
        h, w = sc.shape
        c = min(crop, h, w)
        for s in range(len(sc.spp)):
            out.append(make_sample(sc, rng, crop, spp_index=s, augment=False, aux_mode="full",
                                   origin=((h - c) // 2, (w - c) // 2)))
    return [np.stack(x) for x in zip(*out)] if out else []


def ready(root: str, n_train: int, n_val: int) -> bool:
    """Whether a data set that is still rendering has `n_train` training and `n_val`
    validation scenes finished (scripts/train-gpu waits for them before training)."""
    try:
        return len(_records(root, "train")) >= n_train and len(_records(root, "val")) >= n_val
    except (OSError, ValueError, KeyError):
        return False  # no manifest yet, or one being replaced
