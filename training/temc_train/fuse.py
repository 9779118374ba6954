"""Export-time graph rewrites that compute exactly the same function faster in tract.

tract folds a BatchNormalization into the convolution before it, but not into a transposed
convolution, and it runs Concat as a copy of every skip tensor. Both cost time on every
tile (docs/tract-vs-onnxruntime.md measures how much). These rewrites, applied to an
eval-mode model before ONNX export, remove them:

- `fold_bn_after_deconv`: ConvTranspose2d followed by BatchNorm2d becomes one
  ConvTranspose2d whose weights and bias absorb the (eval-mode, affine) normalisation.
- `split_concat_1x1`: `conv1x1(cat([a, b, c]))` becomes `conv1x1_a(a) + conv1x1_b(b) +
  conv1x1_c(c)`, the same linear map with the concatenation never materialised.

Both work on a torch.fx trace, so they apply to any of temc's architectures.
"""

import copy
import operator

import torch
import torch.fx as fx
from torch import nn


def _module(gm: fx.GraphModule, node: fx.Node):
    return gm.get_submodule(node.target) if node.op == "call_module" else None


@torch.no_grad()
def fold_bn_after_deconv(gm: fx.GraphModule) -> int:
    """Folds every eval-mode BatchNorm2d whose only input is a ConvTranspose2d used only by
    it. Returns how many were folded."""
    n = 0
    for node in list(gm.graph.nodes):
        bn = _module(gm, node)
        if not isinstance(bn, nn.BatchNorm2d):
            continue
        src = node.args[0]
        deconv = _module(gm, src) if isinstance(src, fx.Node) else None
        if not isinstance(deconv, nn.ConvTranspose2d) or len(src.users) != 1:
            continue
        if deconv.groups != 1:
            continue
        scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
        shift = bn.bias - bn.running_mean * scale
        # ConvTranspose2d weight is [in, out, kh, kw]: output channels are dim 1.
        deconv.weight.mul_(scale.view(1, -1, 1, 1))
        bias = deconv.bias if deconv.bias is not None else torch.zeros_like(shift)
        deconv.bias = nn.Parameter(bias * scale + shift)
        node.replace_all_uses_with(src)
        gm.graph.erase_node(node)
        n += 1
    gm.graph.lint()
    gm.recompile()
    return n


@torch.no_grad()
def split_concat_1x1(gm: fx.GraphModule) -> int:
    """Rewrites conv1x1(cat(xs, dim=1)) as a sum of per-input 1x1 convs. Returns the count."""
    n = 0
    for node in list(gm.graph.nodes):
        conv = _module(gm, node)
        if not (isinstance(conv, nn.Conv2d) and conv.kernel_size == (1, 1)
                and conv.stride == (1, 1) and conv.padding == (0, 0) and conv.groups == 1):
            continue
        cat = node.args[0]
        if not (isinstance(cat, fx.Node) and cat.op == "call_function"
                and cat.target in (torch.cat, torch.concat) and len(cat.users) == 1):
            continue
        parts = cat.args[0]
        dim = cat.args[1] if len(cat.args) > 1 else cat.kwargs.get("dim", 0)
        if dim != 1:
            continue
        widths = [p.meta["tensor_meta"].shape[1] for p in parts]
        if sum(widths) != conv.in_channels:
            continue
        start = 0
        terms = []
        with gm.graph.inserting_before(node):
            for i, (p, c) in enumerate(zip(parts, widths)):
                sub = nn.Conv2d(c, conv.out_channels, 1, bias=(i == 0 and conv.bias is not None))
                sub.weight.copy_(conv.weight[:, start:start + c])
                if sub.bias is not None:
                    sub.bias.copy_(conv.bias)
                start += c
                name = f"{node.target.replace('.', '_')}_part{i}"
                gm.add_submodule(name, sub)
                terms.append(gm.graph.call_module(name, (p,)))
            acc = terms[0]
            for t in terms[1:]:
                acc = gm.graph.call_function(operator.add, (acc, t))
        node.replace_all_uses_with(acc)
        gm.graph.erase_node(node)
        gm.graph.erase_node(cat)
        n += 1
    gm.graph.eliminate_dead_code()
    gm.graph.lint()
    gm.recompile()
    return n


def fuse_for_inference(model: nn.Module, example_inputs) -> fx.GraphModule:
    """Traces an eval-mode model and applies both rewrites; returns the rewritten module."""
    from torch.fx.passes.shape_prop import ShapeProp

    # A copy: the folds rewrite weights in place and the caller's model must stay intact.
    model = copy.deepcopy(model).eval()
    gm = fx.symbolic_trace(model)
    ShapeProp(gm).propagate(*example_inputs)
    fold_bn_after_deconv(gm)
    split_concat_1x1(gm)
    return gm
