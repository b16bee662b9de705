"""GeGnn: learned geodesic embeddings with a graph U-Net (Pang et al., ACM TOG 2023).

    model = gegnn.GeGnn.from_checkpoint("run/best.safetensors")
    emb = model.embed(vertices, faces)
    emb.distance(i, j); emb.field(source)
"""
from .embedding import Embedding
from .model import DistanceDecoder, GeGnn, GeGnnConfig

__all__ = ["GeGnn", "GeGnnConfig", "DistanceDecoder", "Embedding"]
