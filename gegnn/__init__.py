"""GeGnn: learned geodesic embeddings with a graph U-Net (Pang et al., ACM TOG 2023).

    model = gegnn.GeGnn.from_checkpoint("run/best.safetensors")
    emb = model.embed(vertices, faces)
    emb.distance(i, j); emb.field(source)

The package is built in layers that import only downward (docs/architecture.md has the table), from
the bottom: (0) config, metrics, threads, precision, graph, distributed; (1) nn/, fields/, fitting;
(2) decoders, checkpoint, queries/, finetune; (3) model; (4) training/, pictures/; (5) cli/.
"""
from .config import GeGnnConfig
from .model import DistanceDecoder, GeGnn
from .queries.embedding import Embedding

__all__ = ["GeGnn", "GeGnnConfig", "DistanceDecoder", "Embedding"]
