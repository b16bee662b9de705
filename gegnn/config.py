"""The configuration of a GeGnn: everything needed to rebuild the network, stored as JSON beside the weights
in every checkpoint (:mod:`gegnn.checkpoint`)."""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

__all__ = ["GeGnnConfig", "LANDMARK_FIELDS", "MESH_FIELDS"]

LANDMARK_FIELDS = ("heat", "vsp", "exact", "paths")  # the landmark fields' solvers (gegnn.fields.landmarks)
MESH_FIELDS = ("exact", "paths")  # those that need a mesh's faces (the exact solver's)


@dataclass(frozen=True)
class GeGnnConfig:
    """Everything needed to rebuild a GeGnn; stored as JSON beside the weights in every checkpoint.

    The defaults are the paper's network (the authors' public code for block counts and GroupNorm).
    The flags below the first group switch on the paper's ablations.
    """

    in_channels: int = 6                      # normalized xyz + unit normal
    channels: int = 256                       # width of every GeoConv
    embed_dim: int = 256                      # per-vertex embedding
    encoder_blocks: tuple[int, ...] = (2, 3, 3, 3, 2)  # ResBlocks after each of the pooling levels
    decoder_blocks: tuple[int, ...] = (2, 3, 3, 3, 2)  # ResBlocks after each unpooling
    groups: int = 4                           # GroupNorm groups
    decoder_hidden: int = 256                 # distance MLP: embed_dim -> hidden -> hidden -> 1
    sigma_c: float = 1 / 16                   # GeoPool cell size in xyz at the first level
    sigma_n: float = 3 / 16                   # ... in normal space; inf = plain grid pooling
    # Ablations
    aggr: str = "max"                         # "max" | "mean" | "sum"
    relative_position: bool = True            # v_i - v_j in GeoConv
    edge_length: bool = True                  # |v_i - v_j| in GeoConv
    decoder: str = "mlp"                      # "mlp" | "euclidean" (distance = ||e_i - e_j||)
    # Landmark guidance (this project's extension; 0 = the paper's model): K landmark distance fields
    # per component, decoded together with the embeddings by a LandmarkDecoder.
    landmarks: int = 0
    landmark_embedding: bool = True           # the decoder reads the embedding difference
    landmark_euclidean: bool = True           # ... and the straight-line distance
    landmark_output: str = "ratio"            # "ratio": d = L exp(MLP); "interval": d = L + (U - L) sigmoid(MLP)
    landmark_fields: str = "heat"             # their solver: "heat" (the heat method, ~1.9% off: models up to v2),
                                              # "vsp" (virtual source propagation, 0.1-0.3% off), "exact"
                                              # or "paths" (real paths within 0.05% of exact)
    # Biharmonic distances (0 = none): m truncated spectral modes per component and their Weyl-law tail,
    # corrected by a SpectralDecoder that reads the embeddings (gegnn.fields.spectral).
    spectral: int = 0
    spectral_embedding: bool = True           # the correction reads the embedding difference
    distance: str = "geodesic"                # what the model was trained to predict: "geodesic" | "biharmonic"
    # Point clouds (0 = meshes): the graph joins every point to its k nearest neighbours, the normals are
    # estimated and the landmark fields come from the points alone (gegnn.fields.pointcloud).
    points: int = 0

    def __post_init__(self):
        object.__setattr__(self, "encoder_blocks", tuple(self.encoder_blocks))
        object.__setattr__(self, "decoder_blocks", tuple(self.decoder_blocks))
        if len(self.encoder_blocks) != len(self.decoder_blocks):
            raise ValueError("encoder_blocks and decoder_blocks need one entry per pooling level each")
        if self.channels % self.groups:
            raise ValueError(f"channels ({self.channels}) must be divisible by groups ({self.groups})")
        if self.decoder not in ("mlp", "euclidean"):
            raise ValueError(f"decoder must be 'mlp' or 'euclidean', got {self.decoder!r}")
        if self.landmark_output not in ("ratio", "interval"):
            raise ValueError(f"landmark_output must be 'ratio' or 'interval', got {self.landmark_output!r}")
        if self.landmark_fields not in LANDMARK_FIELDS:
            raise ValueError(f"landmark_fields must be one of {', '.join(LANDMARK_FIELDS)}, got {self.landmark_fields!r}")
        if self.points and self.landmark_fields in MESH_FIELDS:
            raise ValueError(f"{self.landmark_fields} landmark fields need a mesh; a point-cloud model reads heat or "
                             f"vsp fields")
        if self.landmarks < 0 or self.spectral < 0:
            raise ValueError(f"landmarks and spectral must be >= 0, got {self.landmarks} and {self.spectral}")
        if self.distance not in ("geodesic", "biharmonic"):
            raise ValueError(f"distance must be 'geodesic' or 'biharmonic', got {self.distance!r}")
        if self.landmarks and self.spectral:
            raise ValueError("a model reads landmark fields (geodesic) or spectral codes (biharmonic), not both")
        if self.points < 0 or (self.points and self.spectral):
            raise ValueError(f"points must be >= 0 and takes no spectral codes, got {self.points}")

    @property
    def levels(self) -> int:
        """Pooling levels of the U-Net (one per entry of ``encoder_blocks``)."""
        return len(self.encoder_blocks)

    @property
    def reads_embeddings(self) -> bool:
        """Whether the decoder reads the network's embeddings (the ablations --landmark-no-embedding and
        --spectral-no-embedding decode the fields alone: the network then gets no gradient)."""
        return not ((self.landmarks and not self.landmark_embedding) or (self.spectral and not self.spectral_embedding))

    def to_json(self) -> str:
        """The config as JSON (checkpoints keep it in their metadata)."""
        # inf (plain grid pooling) is written as the JSON extension Infinity, which json reads back.
        return json.dumps(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, text: str) -> "GeGnnConfig":
        """The config of :meth:`to_json`'s text."""
        return cls(**json.loads(text))
