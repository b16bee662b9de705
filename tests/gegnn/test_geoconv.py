import pytest
import torch

from gegnn.nn import GeoConv, aggregate

# A hand-built graph: a square 0-1-2-3 with diagonal 0-2, and vertex 4 isolated.
EDGES = torch.tensor([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]])
EDGE_INDEX = torch.cat([EDGES, EDGES.flip(1)]).t()
POS = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 1, 0.5], [0, 1, 0], [3, 3, 3]])


def dense_reference(conv: GeoConv, x, pos, edge_index):
    """F'_i = W0 F_i + b + reduce_j W1 [F_j || v_i - v_j || |v_i - v_j|], one vertex and edge at a time."""
    w1 = torch.cat([conv.lin_neighbor.weight] + ([conv.lin_geometry.weight] if conv.lin_geometry else []), 1)
    out = []
    for i in range(len(x)):
        msgs = []
        for j in edge_index[1][edge_index[0] == i].tolist():
            rel = pos[i] - pos[j]
            geo = ([rel] if conv.relative_position else []) + ([rel.norm().reshape(1)] if conv.edge_length else [])
            msgs.append(w1 @ torch.cat([x[j]] + geo))
        if msgs:
            m = torch.stack(msgs)
            agg = {"max": m.max(0).values, "mean": m.mean(0), "sum": m.sum(0)}[conv.aggr]
        else:
            agg = torch.zeros(conv.out_channels, dtype=x.dtype)
        out.append(conv.lin_self.weight @ x[i] + conv.lin_self.bias + agg)
    return torch.stack(out)


@pytest.mark.parametrize("aggr", ["max", "mean", "sum"])
@pytest.mark.parametrize("rel,length", [(True, True), (False, True), (True, False), (False, False)])
def test_geoconv_matches_dense_reference(aggr, rel, length):
    torch.manual_seed(0)
    conv = GeoConv(4, 6, aggr=aggr, relative_position=rel, edge_length=length).double()
    x = torch.randn(5, 4, dtype=torch.float64)
    expected = dense_reference(conv, x, POS.double(), EDGE_INDEX)
    torch.testing.assert_close(conv(x, POS.double(), EDGE_INDEX), expected)


@pytest.mark.parametrize("rel,length", [(True, True), (False, True), (True, False), (False, False)])
@pytest.mark.parametrize("channels", [6, 64])  # 6: below the kernel's 8 lanes; 64: whole vectors
def test_fused_inference_max_matches_the_dense_reference(rel, length, channels):
    torch.manual_seed(0)
    conv = GeoConv(4, channels, relative_position=rel, edge_length=length)
    x = torch.randn(5, 4)
    order = torch.argsort(EDGE_INDEX[0], stable=True)  # gegnn's graphs list edges by receiver
    with torch.inference_mode():  # fp32 on a CPU without gradients: src/geoconv.cpp
        fused = conv(x, POS, EDGE_INDEX[:, order])
        unsorted = conv(x, POS, EDGE_INDEX)  # not by receiver: the torch path
        own = conv.lin_self(x[4])
    torch.testing.assert_close(fused[4], own, rtol=1e-6, atol=1e-6)  # no edges: the max term is 0
    expected = dense_reference(conv.double(), x.double(), POS.double(), EDGE_INDEX).float()
    torch.testing.assert_close(fused, expected, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(unsorted, expected, rtol=1e-5, atol=1e-5)


def test_geoconv_translation_invariant():
    torch.manual_seed(0)
    conv = GeoConv(4, 8)
    x = torch.randn(5, 4)
    shifted = conv(x, POS + torch.tensor([10.0, -3.0, 7.0]), EDGE_INDEX)
    torch.testing.assert_close(shifted, conv(x, POS, EDGE_INDEX), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("aggr", ["max", "mean", "sum"])
def test_geoconv_gradients_finite_and_exact(aggr):
    # pytorch#169263: NaN gradients from scatter_reduce amax with include_self=False in some versions.
    torch.manual_seed(0)
    conv = GeoConv(3, 5, aggr=aggr).double()
    x = torch.randn(5, 3, dtype=torch.float64, requires_grad=True)
    (conv(x, POS.double(), EDGE_INDEX) ** 2).sum().backward()
    assert torch.isfinite(x.grad).all() and all(torch.isfinite(p.grad).all() for p in conv.parameters())
    assert x.grad[4].abs().sum() > 0  # isolated vertex still gets the W0 path
    torch.autograd.gradcheck(lambda t: conv(t, POS.double(), EDGE_INDEX), (x.detach().requires_grad_(),))


def test_scatter_max_gradient_matches_torch():
    torch.manual_seed(0)
    msg = torch.randn(40, 7, dtype=torch.float64, requires_grad=True)
    index = torch.randint(0, 9, (40,))
    grad_out = torch.randn(10, 7, dtype=torch.float64)
    (aggregate(msg, index, 10, "max") * grad_out).sum().backward()
    ours = msg.grad.clone()
    msg.grad = None
    ref = torch.zeros(10, 7, dtype=torch.float64).scatter_reduce(
        0, index.unsqueeze(1).expand(-1, 7), msg, "amax", include_self=False)
    (ref * grad_out).sum().backward()
    torch.testing.assert_close(ours, msg.grad)
