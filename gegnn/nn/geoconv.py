"""GeoConv: the graph convolution of GeGnn."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .scatter import AGGREGATIONS, aggregate

__all__ = ["GeoConv", "cpu_inference"]


class GeoConv(nn.Module):
    r"""The geodesic graph convolution from "Learning the Geodesic Embedding with Graph Neural Networks"
    (Pang et al., ACM TOG 2023), Eq. 1:

    .. math::
        \mathbf{f}'_i = \mathbf{W}_0 \mathbf{f}_i + \max_{j \in \mathcal{N}(i)} \mathbf{W}_1
        \left[ \mathbf{f}_j \,\|\, (\mathbf{v}_i - \mathbf{v}_j) \,\|\, \|\mathbf{v}_i - \mathbf{v}_j\| \right]

    :math:`\mathbf{W}_1` is split into a feature block, applied once per vertex before gathering to edges
    (it is linear, so this equals applying it per edge, at a fraction of the cost), and a small geometric
    block applied per edge. Only relative positions enter, so the layer is translation invariant.

    Args:
        in_channels (int): size of each input feature.
        out_channels (int): size of each output feature.
        aggr (str, optional): neighbourhood reduction, ``"max"`` (paper), ``"mean"`` or ``"sum"``.
            (default: ``"max"``)
        relative_position (bool, optional): include :math:`\mathbf{v}_i - \mathbf{v}_j`. (default: ``True``)
        edge_length (bool, optional): include :math:`\|\mathbf{v}_i - \mathbf{v}_j\|`. (default: ``True``)

    Shapes:
        - **input:** features :math:`(N, C_{in})`, positions :math:`(N, 3)`, edge_index :math:`(2, E)`
          (row 0 receives, row 1 sends; both directions listed)
        - **output:** :math:`(N, C_{out})`
    """

    def __init__(self, in_channels: int, out_channels: int, aggr: str = "max",
                 relative_position: bool = True, edge_length: bool = True):
        super().__init__()
        if aggr not in AGGREGATIONS:
            raise ValueError(f"aggr must be one of {AGGREGATIONS}, got {aggr!r}")
        self.in_channels, self.out_channels, self.aggr = in_channels, out_channels, aggr
        self.relative_position, self.edge_length = relative_position, edge_length
        self.lin_self = nn.Linear(in_channels, out_channels)  # W0 (+ the layer's bias)
        self.lin_neighbor = nn.Linear(in_channels, out_channels, bias=False)  # W1, feature block
        geo = 3 * relative_position + edge_length
        self.lin_geometry = nn.Linear(geo, out_channels, bias=False) if geo else None  # W1, geometry

    def forward(self, x: Tensor, pos: Tensor, edge_index: Tensor) -> Tensor:
        i, j = edge_index[0], edge_index[1]
        # One matmul for W0 (with the bias) and W1's feature block: both read the same x.
        weight = torch.cat([self.lin_self.weight, self.lin_neighbor.weight])
        bias = torch.cat([self.lin_self.bias, self.lin_self.bias.new_zeros(self.out_channels)])
        own, neighbor = F.linear(x, weight, bias).split(self.out_channels, dim=1)
        if self.aggr == "max" and cpu_inference(neighbor):
            fused = self._fused_max(own, neighbor, pos, edge_index)
            if fused is not None:
                return fused
        msg = neighbor.index_select(0, j)  # not neighbor[j]: advanced indexing is ~6x slower for rows
        geometry = self.edge_geometry(pos, i, j)
        if geometry is not None:  # fused multiply-add: one pass over the (E, C) messages
            msg = torch.addmm(msg, geometry.to(msg.dtype), self.lin_geometry.weight.t().to(msg.dtype))
        return own + aggregate(msg, i, x.shape[0], self.aggr)

    def _fused_max(self, own: Tensor, neighbor: Tensor, pos: Tensor, edge_index: Tensor) -> Tensor | None:
        """``own`` + the max over edge messages, in one pass without an (E, C) array and reading both halves
        of the matmul's output in place (``src/geoconv.cpp``: one new array, where a fresh array costs its
        page faults on every call); None where the edges are not sorted by receiver (gegnn's hierarchies
        always are)."""
        from .._geoconv import max_messages

        w = (self.lin_geometry.weight.t() if self.lin_geometry is not None
             else neighbor.new_zeros(0, self.out_channels))
        out = torch.empty(neighbor.shape, dtype=neighbor.dtype)
        ok = max_messages(neighbor, own, pos.float().contiguous(), edge_index[0].contiguous(),
                          edge_index[1].contiguous(), w.detach().float().contiguous(), self.relative_position,
                          self.edge_length, out, torch.get_num_threads())
        return out if ok else None

    def edge_geometry(self, pos: Tensor, i: Tensor, j: Tensor) -> Tensor | None:
        rel = pos.index_select(0, i) - pos.index_select(0, j)
        parts = ([rel] if self.relative_position else []) + \
                ([rel.norm(dim=1, keepdim=True)] if self.edge_length else [])
        return torch.cat(parts, dim=1) if parts else None

    def extra_repr(self) -> str:
        return (f"{self.in_channels}, {self.out_channels}, aggr={self.aggr!r}, "
                f"relative_position={self.relative_position}, edge_length={self.edge_length}")


def cpu_inference(x: Tensor) -> bool:
    """fp32 on a CPU with nothing to differentiate: where the compiled inference kernels apply (this
    one, and the landmark decoder's, :meth:`gegnn.decoders.LandmarkDecoder.pair_inputs`)."""
    return x.device.type == "cpu" and x.dtype == torch.float32 and not (torch.is_grad_enabled() and x.requires_grad)
