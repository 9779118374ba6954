"""Training batches sampled where the model trains (issue 35: feed the GPU).

`data.make_sample` builds one crop at a time in numpy; on a GPU that made the 16 cores the
limit (the GPU sat at 26-100 % use). Here the training scenes live on the training device
as tensors, and a whole batch is drawn there in a few tensor operations, with the same
recipe as `data.make_sample`:

- a random scene, a random noisy spp and a random crop, a random flip and quarter turn:
  one gather per batch (the crop, flip and turn are folded into its indices);
- normals turned with the image (`data._transform_normal`'s rule), and half of them by a
  random 3-D rotation;
- the core's automatic exposure of that noisy image, jittered by up to one stop;
- aux dropout: no aux with probability 0.2, albedo only with 0.2, else everything;
- the network's encoding (PQ then HSV, `color.encode`) in float32 on the device.

What does not depend on the draw is done once, in numpy, when a scene is added: colour and
reference sanitised (`color.sanitize_rgb`), albedo clamped, normals made unit (zero where
missing), depth divided by its image's depth scale. `tests/test_device_batches.py` checks
the result against `data.make_sample` crop for crop.
"""

import numpy as np
import torch

from . import color

# Per noisy image: linear colour 3, albedo 3, unit camera-space normal 3, depth 1.
PLANES = 10
P_COLOR_ONLY = 0.2
P_ALBEDO_ONLY = 0.2
_PQ_K = color.NITS_PER_UNIT / color.PQ_MAX_NITS


def pq_encode(y: torch.Tensor) -> torch.Tensor:
    """`color.pq_encode` in float32."""
    ym = y.clamp(0.0, 1.0) ** color.M1
    return ((color.C1 + color.C2 * ym) / (1.0 + color.C3 * ym)) ** color.M2


def rgb_to_hsv(rgb: torch.Tensor) -> torch.Tensor:
    """`color.rgb_to_hsv` on [..., 3] in float32: hexcone HSV in [0, 1]."""
    r, g, b = rgb.unbind(-1)
    mx, _ = rgb.max(-1)
    mn, _ = rgb.min(-1)
    d = mx - mn
    safe = torch.where(d > 0, d, torch.ones_like(d))
    h6 = torch.where(mx == r, (g - b) / safe, torch.where(mx == g, (b - r) / safe + 2.0, (r - g) / safe + 4.0))
    h = h6 / 6.0
    h = h - torch.floor(h)
    h = torch.where((d > 0) & (h < 1.0), h, torch.zeros_like(h))
    s = torch.where(mx > 0, d / torch.where(mx > 0, mx, torch.ones_like(mx)), torch.zeros_like(mx))
    return torch.stack([h, s, mx], -1)


def encode(rgb: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """`color.encode` of sanitised linear `rgb` [..., 3] at input scale `scale` (broadcast
    against rgb[..., 0]): HSV [..., 3]."""
    y = rgb * (scale * _PQ_K)[..., None]
    m, _ = y.max(-1, keepdim=True)
    y = torch.where(m > 1.0, y / m.clamp_min(1.0), y)
    return rgb_to_hsv(pq_encode(y))


def _planes(scene, s: int) -> np.ndarray:
    """One noisy image's draw-independent planes [H, W, PLANES]."""
    a = scene.a
    unit = color.normal(a["normal"][s]) * 2.0 - 1.0  # exactly 0 where the normal is missing
    return np.concatenate([color.sanitize_rgb(a["color"][s]), color.albedo(a["albedo"][s]), unit,
                           color.depth(a["depth"][s], scene.depth_scale[s])[..., None]],
                          -1).astype(np.float32)


def _pad(x: np.ndarray, h: int, w: int) -> np.ndarray:
    return np.pad(x, [(0, 0)] * (x.ndim - 3) + [(0, h - x.shape[-3]), (0, w - x.shape[-2]), (0, 0)])


def _quarter_turns(k: torch.Tensor, flip: torch.Tensor) -> torch.Tensor:
    """[n, 3, 3]: what the flip, then k counter-clockwise quarter turns do to a camera-space
    normal (`data._transform_normal`)."""
    n = k.shape[0]
    m = torch.eye(3, device=k.device).repeat(n, 1, 1)
    m[:, 0, 0] = torch.where(flip, -1.0, 1.0)
    turn = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], device=k.device)
    for t in range(1, 4):
        m = torch.where((k >= t)[:, None, None], turn @ m, m)
    return m


def random_rotations(n: int, gen: torch.Generator, device) -> torch.Tensor:
    """[n, 3, 3] uniformly random rotations (`data.random_rotation`, batched)."""
    q, r = torch.linalg.qr(torch.randn(n, 3, 3, generator=gen, device=device))
    q = q * torch.sign(torch.diagonal(r, dim1=-2, dim2=-1))[:, None, :]
    q[:, :, 0] *= torch.where(torch.linalg.det(q) < 0, -1.0, 1.0)[:, None]
    return q


class DeviceSet:
    """Training scenes as tensors on `device`: per noisy image its PLANES planes, per scene
    its reference, padded to the largest scene (each scene's crops stay inside its own
    size). Scenes join as they are rendered (`add`)."""

    def __init__(self, device, max_spp: int = 0, spp_weights=None):
        self.device = torch.device(device)
        self.names, self.spp = [], None
        # Noisy inputs drawn only up to this spp (0: all), each in its relative share of the
        # draws (None: equal); see train.py's --max-input-spp and --spp-weights. `weights`
        # stays None without either, so the draw keeps its old random stream.
        self.max_spp, self.spp_weights, self.weights = max_spp, spp_weights, None
        self.planes = self.reference = self.scale = self.hw = None

    def __len__(self):
        return len(self.names)

    def add(self, scenes) -> int:
        """Moves `scenes` (`data.Scene` or `shard.ShardScene`; all with the same spp list)
        to the device; returns how many were new."""
        have = set(self.names)
        new = [s for s in scenes if s.name not in have]
        if not new:
            return 0
        self.spp = self.spp or list(new[0].spp)
        if any(list(s.spp) != self.spp for s in new):
            raise ValueError(f"every scene needs the noisy spp {self.spp}")
        if (self.max_spp or self.spp_weights is not None) and self.weights is None:
            self.weights = self._weights()
        h = max([s.shape[0] for s in new] + ([self.planes.shape[2]] if self.names else []))
        w = max([s.shape[1] for s in new] + ([self.planes.shape[3]] if self.names else []))
        planes = np.stack([_pad(np.stack([_planes(s, i) for i in range(len(self.spp))]), h, w) for s in new])
        ref = np.stack([_pad(color.sanitize_rgb(s.a["reference"]).astype(np.float32), h, w) for s in new])
        parts = {"planes": torch.from_numpy(planes), "reference": torch.from_numpy(ref),
                 "scale": torch.tensor([list(s.scale) for s in new], dtype=torch.float32),
                 "hw": torch.tensor([list(s.shape) for s in new])}
        for key, t in parts.items():
            t = t.to(self.device)
            old = getattr(self, key)
            if old is not None and key in ("planes", "reference"):
                old = torch.nn.functional.pad(old, [0, 0, 0, w - old.shape[-2], 0, h - old.shape[-3]])
            setattr(self, key, t if old is None else torch.cat([old, t]))
        self.names += [s.name for s in new]
        self.min_side = int(self.hw.min())  # kept here: reading it per batch syncs the GPU
        return len(new)

    def _weights(self) -> torch.Tensor:
        """The draw's weight per noisy spp (spp_weights or equal, zero above max_spp),
        checked against the spp list."""
        w = [1.0] * len(self.spp) if self.spp_weights is None else [float(x) for x in self.spp_weights]
        if len(w) != len(self.spp) or min(w) < 0:
            raise ValueError(f"--spp-weights needs {len(self.spp)} weights >= 0 "
                             f"(for spp {self.spp}), got {w}")
        if self.max_spp:
            if all(v > self.max_spp for v in self.spp):
                raise ValueError(f"no noisy spp of {self.spp} is at most {self.max_spp}")
            w = [x if v <= self.max_spp else 0.0 for x, v in zip(w, self.spp)]
        if sum(w) <= 0:
            raise ValueError(f"--spp-weights {w} draws no noisy input")
        return torch.tensor(w, device=self.device)

    def batch(self, n: int, crop: int, gen: torch.Generator) -> list:
        """n random training crops: (chroma [n,2,c,c], luma [n,1,c,c], aux [n,7,c,c],
        noisy [n,3,c,c], albedo [n,3,c,c], reference [n,3,c,c]), float32 on the device,
        as `data.batch` makes them. c is `crop`, or the smallest scene's side if less."""
        return self.make(self.draw(n, crop, gen))

    def draw(self, n: int, crop: int, gen: torch.Generator) -> dict:
        """The random choices of n samples (what `make` turns into a batch)."""
        dev = self.device
        u = lambda: torch.rand(n, generator=gen, device=dev)  # noqa: E731
        i = torch.randint(len(self), (n,), generator=gen, device=dev)
        c = min(crop, self.min_side)
        hw = self.hw[i]
        spin = torch.where((u() < 0.5)[:, None, None], random_rotations(n, gen, dev),
                           torch.eye(3, device=dev).expand(n, 3, 3))
        if self.weights is None:
            s = torch.randint(len(self.spp), (n,), generator=gen, device=dev)
        else:
            s = torch.multinomial(self.weights, n, replacement=True, generator=gen)
        return {"i": i, "s": s, "c": c,
                "y0": (u() * (hw[:, 0] - c + 1)).long(), "x0": (u() * (hw[:, 1] - c + 1)).long(),
                "flip": u() < 0.5, "k": torch.randint(4, (n,), generator=gen, device=dev),
                "spin": spin, "stops": u() * 2.0 - 1.0, "mode": u()}

    def make(self, d: dict) -> list:
        """The batch of the choices `d` (`draw`'s)."""
        i, s = d["i"], d["s"]
        ys, xs = self._source(d["y0"], d["x0"], d["flip"], d["k"], d["c"])
        px = self.planes[i[:, None, None], s[:, None, None], ys, xs]  # [n, c, c, PLANES]
        ref = self.reference[i[:, None, None], ys, xs]
        rgb, alb, nrm, dep = px[..., :3], px[..., 3:6], px[..., 6:9], px[..., 9]
        nrm = torch.einsum("nyxj,nij->nyxi", nrm, d["spin"] @ _quarter_turns(d["k"], d["flip"]))
        scale = self.scale[i, s] * 2.0 ** d["stops"]
        keep_albedo = (d["mode"] >= P_COLOR_ONLY)[:, None, None, None].float()
        keep_geometry = (d["mode"] >= P_COLOR_ONLY + P_ALBEDO_ONLY)[:, None, None, None].float()
        alb = alb * keep_albedo
        aux = torch.cat([alb, ((nrm * keep_geometry + 1.0) * 0.5).clamp(0.0, 1.0),
                         dep[..., None] * keep_geometry], -1)
        hsv = encode(rgb, scale[:, None, None])
        first = lambda x: x.permute(0, 3, 1, 2).contiguous()  # noqa: E731
        k = scale[:, None, None, None]
        return [first(hsv[..., :2]), first(hsv[..., 2:]), first(aux), first(rgb * k), first(alb),
                first(ref * k)]

    @staticmethod
    def _source(y0, x0, flip, k, c):
        """Per sample, the source pixel of every output pixel of a c x c crop at (y0, x0)
        flipped (x -> c-1-x) then turned k quarter turns counter-clockwise (np.rot90)."""
        a = torch.arange(c, device=y0.device)
        r, q = torch.meshgrid(a, a, indexing="ij")
        r, q, kk = r[None], q[None], k[:, None, None]
        p = torch.where(kk == 0, r, torch.where(kk == 1, q, torch.where(kk == 2, c - 1 - r, c - 1 - q)))
        x = torch.where(kk == 0, q, torch.where(kk == 1, c - 1 - r, torch.where(kk == 2, c - 1 - q, r)))
        x = torch.where(flip[:, None, None], c - 1 - x, x)
        return y0[:, None, None] + p, x0[:, None, None] + x
