r"""Pair decoders: per-vertex codes of two vertices to their distance.

Every decoder splits into ``inputs`` (the symmetric pair features and what the output needs) and
``output`` (the MLP's value to a distance), so :class:`gegnn.queries.embedding.Embedding` can run the MLP in its
own fast path between the two; ``pair_inputs`` is ``inputs`` of pairs of rows of a code table (fused into
one pass for the landmark decoder on a CPU). On a CPU in fp32, the distance and landmark decoders also run
whole, features and MLP, in one compiled pass (:meth:`PairDecoder.fused_decode`, ``src/pair_features.cpp``).
"""
from __future__ import annotations

from contextlib import nullcontext

import torch
from torch import Tensor, nn

from .fields.spectral import weyl_shape, weyl_table
from .nn import cpu_inference

__all__ = ["compiled_isa", "PairDecoder", "DistanceDecoder", "LandmarkDecoder", "SpectralDecoder", "MLP", "mlp"]

MAX_LOG_RATIO = 5.0  # a ratio decoder never predicts more than e^5 = 148 times the lower bound
ISA = "auto"  # the compiled decode's instruction set: "auto" (the widest this CPU has), "avx512", "avx2", or "none"
FUSED_COLUMNS = 32  # the compiled decode takes hidden layers whose widths are multiples of this


class MLP(nn.Sequential):
    """Layers in sequence, the last one in fp32 whatever the autocast: it is a dot product, so fp32 costs
    nothing, and a bf16 output would round every distance to 2^-8 relative (0.4%), a floor on the error
    of a model near 1% (the same split as :meth:`gegnn.queries.embedding.Embedding._decode`)."""

    def forward(self, x: Tensor) -> Tensor:
        *hidden, last = self
        for layer in hidden:
            x = layer(x)
        device = x.device.type  # one without autocast (e.g. meta) has none to leave
        with torch.autocast(device, enabled=False) if torch.amp.is_autocast_available(device) else nullcontext():
            return last(x.float())


def mlp(n_in: int, hidden: int, zero_last: bool = False) -> MLP:
    """n_in -> hidden -> hidden -> 1 with ReLUs; ``zero_last``: the last layer starts at zero."""
    m = MLP(nn.Linear(n_in, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1))
    if zero_last:
        nn.init.zeros_(m[-1].weight)
        nn.init.zeros_(m[-1].bias)
    return m


def compiled_isa() -> str:
    """The instruction set of the compiled decode here: :data:`ISA`, where ``"auto"`` is the widest this CPU
    runs (``"avx512"``, ``"avx2"`` with FMA, or ``"none"``: torch's path, faster than the kernels without
    FMA). Tests and benchmarks set :data:`ISA` to force each."""
    from ._pair_features import cpu_isa

    return cpu_isa() if ISA == "auto" else ISA


class PairDecoder(nn.Module):
    """What every decoder shares: :meth:`pair_inputs`, and ``forward`` = ``output(mlp(inputs))``."""

    def forward(self, a: Tensor, b: Tensor) -> Tensor:
        x, extra = self.inputs(a, b)
        return self.output(self.mlp(x), extra)

    def pair_inputs(self, codes: Tensor, i: Tensor, j: Tensor):
        """``inputs(codes[i], codes[j])`` (index_select, not codes[i]: advanced indexing is a generic
        scatter-gather, 6x slower for rows)."""
        return self.inputs(codes.index_select(0, i), codes.index_select(0, j))

    def pair_width(self, codes: Tensor) -> int:
        """Values one pair holds in flight in :meth:`pair_inputs` (sets the chunk of a decode)."""
        return 2 * codes.shape[1]

    def fused_layout(self) -> tuple | None:
        """The compiled decode's description of this decoder's inputs, ``(mode, D, K, embedding,
        euclidean)`` (``src/pair_features.cpp``), or None where it has none."""
        return None

    def fuses(self, codes: Tensor, layers) -> bool:
        """Whether :meth:`fused_decode` runs on these codes and MLP layers: a CPU with AVX2 or AVX512
        (:func:`compiled_isa`), fp32, no gradients, hidden widths that are multiples of :data:`FUSED_COLUMNS`."""
        return (self.fused_layout() is not None and cpu_inference(codes) and compiled_isa() != "none"
                and len(layers) >= 2
                and all(w.dtype == torch.float32 for w, _ in layers)
                and all(w.shape[1] % FUSED_COLUMNS == 0 for w, _ in layers[:-1]))

    def fused_decode(self, codes: Tensor, i: Tensor, j: Tensor, layers) -> Tensor:
        """``output(mlp(pair_inputs(codes, i, j)))`` in one compiled pass, where :meth:`fuses`: features and
        MLP a tile of 64 pairs at a time, held in cache, on all of torch's threads. ``layers``: the MLP's
        ``(weight.t(), bias)`` pairs in fp32. Equal to the torch path to within float rounding."""
        from ._pair_features import decode_pairs

        mode, d, k, embedding, euclidean = self.fused_layout()
        n = len(i)
        t = torch.empty(n)
        lower, upper = (torch.empty(n), torch.empty(n)) if mode == 1 else (torch.empty(0), torch.empty(0))
        decode_pairs(codes.contiguous(), i.contiguous(), j.contiguous(), mode, d, k, embedding, euclidean,
                     [w.contiguous() for w, _ in layers], [b.contiguous() for _, b in layers], t, lower, upper,
                     torch.get_num_threads(), compiled_isa())
        return self.output(t.unsqueeze(1), (lower, upper) if mode == 1 else None)

    def point_codes(self, corners: Tensor, bary: Tensor) -> Tensor:
        r"""Codes (P, C) of points inside faces from their corners' codes (P, 3, C) and barycentric
        coordinates (P, 3): the blend :math:`\sum_k b_k c_k` of every column."""
        return torch.einsum("pk,pkc->pc", bary, corners)


class DistanceDecoder(PairDecoder):
    r"""Distance between two embeddings (the paper's decoder).

    ``"mlp"``: :math:`d_{ij} = |\mathrm{MLP}((\mathbf{e}_i - \mathbf{e}_j)^2)|`, symmetric by
    construction. The final absolute value keeps predictions non-negative while, unlike a ReLU, never
    cutting the gradient. ``"euclidean"`` (ablation): :math:`d_{ij} = \|\mathbf{e}_i - \mathbf{e}_j\|`.

    Shapes:
        - **input:** :math:`(P, D)`, :math:`(P, D)`
        - **output:** :math:`(P,)`
    """

    def __init__(self, embed_dim: int, hidden: int, kind: str = "mlp"):
        super().__init__()
        self.kind = kind
        self.mlp = mlp(embed_dim, hidden) if kind == "mlp" else None

    def inputs(self, a: Tensor, b: Tensor) -> tuple[Tensor, None]:
        return (a - b).square(), None

    def output(self, t: Tensor, extra=None) -> Tensor:
        return t.squeeze(1).abs()

    def fused_layout(self) -> tuple | None:
        return (0, 0, 0, False, False) if self.mlp is not None else None

    def forward(self, a: Tensor, b: Tensor) -> Tensor:
        if self.mlp is None:
            return ((a - b).square().sum(dim=1) + 1e-12).sqrt()  # eps: finite gradient at a == b
        return super().forward(a, b)


class LandmarkDecoder(PairDecoder):
    r"""Distance from embeddings and landmark distance fields (landmark-guided GeGnn).

    With :math:`f_{ik}` the distance of vertex :math:`i` to landmark :math:`k` of its component and
    :math:`s_k = |f_{ik} - f_{jk}|`, the triangle inequality bounds the distance by
    :math:`L = \max_k s_k \le d_{ij} \le U = \min_k f_{ik} + f_{jk}`. An MLP corrects the lower bound:

    .. math::
        d_{ij} = L\, e^{\mathrm{MLP}(\mathbf{x}_{ij})} \quad (\text{``ratio''}),\qquad
        d_{ij} = L + (U - L)\, \sigma(\mathrm{MLP}(\mathbf{x}_{ij})) \quad (\text{``interval''}),

        \mathbf{x}_{ij} = \Big[(\mathbf{e}_i - \mathbf{e}_j)^2,\; \frac{L}{U},\; \frac{\bar s}{U},\;
        \frac{\sqrt{\overline{s^2}}}{U},\; \frac{n_i + n_j}{U},\; \frac{|n_i - n_j|}{U},\;
        \frac{\|\mathbf{p}_i - \mathbf{p}_j\|}{U},\; \log U\Big]

    with :math:`\bar s`, :math:`\overline{s^2}` the means over the K landmarks (for landmarks all
    round a short pair, :math:`s_k \approx d |\cos\theta_k|`, so they estimate d where the max is loose),
    :math:`n_i = \min_k f_{ik}` the distance to the nearest landmark (where heat-method fields are least
    accurate) and :math:`\mathbf{p}` the normalized positions. Every feature is invariant to the order of
    the landmarks and symmetric in (i, j); a query costs O(K). The distance is exactly 0 where no landmark
    separates the two vertices (L = 0), e.g. i = j.

    The ratio form starts as the bound itself (the last layer is zero) and may leave [L, U]: with
    heat-method fields the true distance lies outside it for about half of the pairs (the interval
    form's floor is 0.66% MRE at K = 64 on the validation meshes).

    A vertex code is ``[e (D) | f (K) | n (1) | p (3)]`` (see :meth:`codes`).

    Args:
        embed_dim: embedding width D.
        landmarks: K.
        hidden: MLP width.
        embedding: read the embedding difference (off: the decoder sees landmarks only).
        euclidean: read the straight-line distance.
        output: ``"ratio"`` or ``"interval"`` (ablation).

    Shapes:
        - **input:** :math:`(P, D + K + 4)`, :math:`(P, D + K + 4)`
        - **output:** :math:`(P,)`
    """

    def __init__(self, embed_dim: int, landmarks: int, hidden: int, embedding: bool = True,
                 euclidean: bool = True, output: str = "ratio"):
        super().__init__()
        self.embed_dim, self.k = embed_dim, landmarks
        self.embedding, self.euclidean, self.kind = embedding, euclidean, output
        n_in = (embed_dim if embedding else 0) + 5 + (1 if euclidean else 0) + 1
        self.mlp = mlp(n_in, hidden, zero_last=output == "ratio")  # ratio: start as the lower bound itself

    @staticmethod
    def codes(embeddings: Tensor, fields: Tensor, positions: Tensor) -> Tensor:
        """Per-vertex codes ``[e | f | n | p]`` (N, D + K + 4) in fp32."""
        fields = fields.float()
        return torch.cat([embeddings.float(), fields, fields.amin(dim=1, keepdim=True), positions.float()], dim=1)

    def inputs(self, a: Tensor, b: Tensor) -> tuple[Tensor, tuple[Tensor, Tensor]]:
        d, k = self.embed_dim, self.k
        fa, fb = a[:, d:d + k], b[:, d:d + k]
        upper = (fa + fb).amin(dim=1)
        sep = (fa - fb).abs_()
        lower = sep.amax(dim=1)  # amax/amin/sums: topk of a few was 25x slower per query on CPU
        mean, rms = sep.mean(dim=1), torch.linalg.vector_norm(sep, dim=1) / k ** 0.5
        na, nb = a[:, d + k], b[:, d + k]
        u = upper.clamp_min(1e-6)
        feats = [lower, mean, rms, na + nb, (na - nb).abs()]
        if self.euclidean:
            feats.append((a[:, d + k + 1:] - b[:, d + k + 1:]).norm(dim=1))
        parts = [torch.stack(feats, dim=1).div_(u.unsqueeze(1)), u.log().unsqueeze(1)]
        if self.embedding:
            parts.insert(0, (a[:, :d] - b[:, :d]).square())
        return torch.cat(parts, dim=1), (lower, upper)

    def pair_inputs(self, codes: Tensor, i: Tensor, j: Tensor):
        """:meth:`inputs` of the pairs (codes[i], codes[j]); on a CPU, in fp32 and without gradients, in one
        fused pass over each pair's codes (``src/pair_features.cpp``: no (pairs x K) intermediates; the same
        values to within float rounding)."""
        if not cpu_inference(codes):
            return super().pair_inputs(codes, i, j)
        from ._pair_features import landmark_features

        n = len(i)
        x = torch.empty(n, self.mlp[0].in_features)
        lower, upper = torch.empty(n), torch.empty(n)
        landmark_features(codes.detach().contiguous(), i.contiguous(), j.contiguous(), self.embed_dim, self.k,
                          self.embedding, self.euclidean, x, lower, upper, torch.get_num_threads())
        return x, (lower, upper)

    def pair_width(self, codes: Tensor) -> int:
        return self.mlp[0].in_features if cpu_inference(codes) else super().pair_width(codes)

    def fused_layout(self) -> tuple | None:
        return 1, self.embed_dim, self.k, self.embedding, self.euclidean

    def point_codes(self, corners: Tensor, bary: Tensor) -> Tensor:
        """The blend of the corners' codes, except the distance to the nearest landmark, which is that of
        the blended fields (the minimum of linear functions is not linear)."""
        codes = super().point_codes(corners, bary)
        d, k = self.embed_dim, self.k
        codes[:, d + k] = codes[:, d:d + k].amin(dim=1)
        return codes

    def output(self, t: Tensor, extra: tuple[Tensor, Tensor]) -> Tensor:
        lower, upper = extra
        t = t.squeeze(1).float()
        if self.kind == "ratio":
            d = lower * t.clamp(max=MAX_LOG_RATIO).exp()
        else:
            d = lower + (upper - lower).clamp_min(0) * torch.sigmoid(t)
        return torch.where(lower <= 0, torch.zeros_like(d), d)  # a NaN bound stays NaN, never 0


class SpectralDecoder(PairDecoder):
    r"""Biharmonic distance from truncated spectral codes, their Weyl-law tail and the embeddings
    (biharmonic GeGnn; :mod:`gegnn.fields.spectral` derives the tail).

    With :math:`d_m^2 = \sum_{k \le m} (s_k(i) - s_k(j))^2` (a lower bound), the tail scale
    :math:`\tau` and :math:`w = \tau F(r / \sqrt{2\pi\tau})` the Weyl estimate of the rest:

    .. math::
        d_{ij}^2 = d_m^2 + w\, e^{\mathrm{MLP}(\mathbf{x}_{ij})}, \qquad
        \mathbf{x}_{ij} = \Big[(\mathbf{e}_i - \mathbf{e}_j)^2,\; F,\; \frac{d_m^2}{d_m^2 + w},\;
        \log\frac{r}{\sqrt{2\pi\tau}}\Big]

    with r the straight-line distance of the normalized positions. So :math:`d \ge d_m` always, d is
    symmetric, exactly 0 for i = j (both terms vanish there, with no special case), and a query costs
    O(m + D). The MLP's last layer starts at zero: the decoder starts as the Weyl estimate itself.

    A vertex code is ``[e (D) | s (m) | tau (1) | p (3)]`` (see :meth:`codes`).

    Args:
        embed_dim: embedding width D.
        modes: m.
        hidden: MLP width.
        embedding: read the embedding difference (off: the correction sees the spectral features only).

    Shapes:
        - **input:** :math:`(P, D + m + 4)`, :math:`(P, D + m + 4)`
        - **output:** :math:`(P,)`
    """

    def __init__(self, embed_dim: int, modes: int, hidden: int, embedding: bool = True):
        super().__init__()
        self.embed_dim, self.m, self.embedding = embed_dim, modes, embedding
        self.mlp = mlp((embed_dim if embedding else 0) + 3, hidden, zero_last=True)
        self.register_buffer("weyl", weyl_table(), persistent=False)

    @staticmethod
    def codes(embeddings: Tensor, spectral: Tensor, positions: Tensor) -> Tensor:
        """Per-vertex codes ``[e | s | tau | p]`` (N, D + m + 4) in fp32 (``spectral``: (N, m + 1), as
        :func:`gegnn.fields.spectral.spectral_codes`)."""
        return torch.cat([embeddings.float(), spectral.float(), positions.float()], dim=1)

    def inputs(self, a: Tensor, b: Tensor) -> tuple[Tensor, tuple[Tensor, Tensor]]:
        d, m = self.embed_dim, self.m
        fa, fb = a[:, d:].detach(), b[:, d:].detach()  # spectral codes and positions: inputs, never learned
        bound = (fa[:, :m] - fb[:, :m]).square_().sum(dim=1)
        tau = (fa[:, m] + fb[:, m]).mul_(0.5)
        r = (fa[:, m + 1:] - fb[:, m + 1:]).norm(dim=1)
        s = r * (2 * torch.pi * tau).clamp_min(1e-30).rsqrt()
        shape = weyl_shape(s, self.weyl)
        tail = tau * shape
        feats = [shape, bound / (bound + tail).clamp_min(1e-30), s.clamp_min(1e-6).log()]
        parts = [torch.stack(feats, dim=1)]
        if self.embedding:
            parts.insert(0, (a[:, :d] - b[:, :d]).square())
        return torch.cat(parts, dim=1), (bound, tail)

    def output(self, t: Tensor, extra: tuple[Tensor, Tensor]) -> Tensor:
        bound, tail = extra
        return (bound + tail * t.squeeze(1).float().clamp(max=MAX_LOG_RATIO).exp()).sqrt()
