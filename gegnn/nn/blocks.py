"""Residual blocks of GeoConvs."""
from __future__ import annotations

from torch import Tensor, nn

from .geoconv import GeoConv

__all__ = ["ResBlock", "ResBlocks"]


class ResBlock(nn.Module):
    r"""Two :class:`GeoConv` layers with GroupNorm, ReLU and a skip connection (the authors'
    ``GraphResBlock2``):

    .. math::
        \mathbf{y} = \mathrm{ReLU}\big(\mathrm{GN}(\mathrm{conv}_2(\mathrm{ReLU}(\mathrm{GN}(\mathrm{conv}_1
        (\mathbf{x}))))) + \mathbf{s}(\mathbf{x})\big)

    where :math:`\mathbf{s}` is the identity, or a linear map with GroupNorm when the widths differ.
    GroupNorm acts on each vertex's channels, so a mesh's output never depends on the other meshes in
    its batch.

    Args:
        in_channels (int): input width.
        out_channels (int): output width.
        groups (int, optional): GroupNorm groups. (default: ``4``)
        **conv_kwargs: passed to :class:`GeoConv` (``aggr``, ``relative_position``, ``edge_length``).

    Shapes:
        - **input:** features :math:`(N, C_{in})`, positions :math:`(N, 3)`, edge_index :math:`(2, E)`
        - **output:** :math:`(N, C_{out})`
    """

    def __init__(self, in_channels: int, out_channels: int, groups: int = 4, **conv_kwargs):
        super().__init__()
        self.conv1 = GeoConv(in_channels, out_channels, **conv_kwargs)
        self.norm1 = nn.GroupNorm(groups, out_channels)
        self.conv2 = GeoConv(out_channels, out_channels, **conv_kwargs)
        self.norm2 = nn.GroupNorm(groups, out_channels)
        self.relu = nn.ReLU()
        self.skip = nn.Identity() if in_channels == out_channels else nn.Sequential(
            nn.Linear(in_channels, out_channels, bias=False), nn.GroupNorm(groups, out_channels))

    def forward(self, x: Tensor, pos: Tensor, edge_index: Tensor) -> Tensor:
        y = self.relu(self.norm1(self.conv1(x, pos, edge_index)))
        y = self.norm2(self.conv2(y, pos, edge_index))
        return self.relu(y + self.skip(x))


class ResBlocks(nn.Module):
    """``num_blocks`` :class:`ResBlock` in sequence; the first maps ``in_channels`` to ``out_channels``."""

    def __init__(self, in_channels: int, out_channels: int, num_blocks: int, groups: int = 4,
                 **conv_kwargs):
        super().__init__()
        self.blocks = nn.ModuleList(ResBlock(out_channels if k else in_channels, out_channels, groups, **conv_kwargs)
                                    for k in range(num_blocks))

    def forward(self, x: Tensor, pos: Tensor, edge_index: Tensor) -> Tensor:
        for block in self.blocks:
            x = block(x, pos, edge_index)
        return x
