"""The GeGnn graph U-Net (Pang et al., "Learning the Geodesic Embedding with Graph Neural Networks",
ACM TOG 2023): one forward pass gives an embedding per vertex; a small MLP decodes a pair of embeddings
to a distance."""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from contextlib import nullcontext

import numpy as np
import torch
from torch import Tensor, nn

from geodata.mesh import Mesh, unique_edges, vertex_normals
from geodata.stages.normalize import normalization

from .checkpoint import load_checkpoint, save_checkpoint
from .config import LANDMARK_FIELDS, MESH_FIELDS, GeGnnConfig
from .decoders import DistanceDecoder, LandmarkDecoder, SpectralDecoder
from .fields.cache import FieldSpec
from .graph import Graph, mesh_graph
from .nn import GeoConv, GeoPool, GeoUnpool, Hierarchy, ResBlocks, build_hierarchy
from .precision import resolve
from .queries.embedding import Embedding
from .queries.proxy import cloud_subset, cloud_weights, proxy_of, proxy_size
from .threads import beside, fewer_for_torch

__all__ = ["GeGnnConfig", "GeGnn", "DistanceDecoder", "LandmarkDecoder", "SpectralDecoder"]

# Shipped models, in gegnn/weights/, made by `gegnn export` (docs/model-card.md); the first is the default.
PRETRAINED = {
    "landmark": "gegnn-landmark-v4.safetensors",  # landmark-guided, K = 256 fields by virtual sources: the most accurate
    "landmark-v3": "gegnn-landmark-v3.safetensors",  # the previous default, trained on 0.3.2's fields, no tubes
    "landmark-v2": "gegnn-landmark-v2.safetensors",  # the one before, K = 256 heat-method fields
    "landmark-v1": "gegnn-landmark-v1.safetensors",  # the one before, K = 128
    "paper": "gegnn-classic-v1.safetensors",      # the paper's model (no landmarks)
    "biharmonic": "gegnn-biharmonic-v1.safetensors",  # biharmonic distances: spectral codes + Weyl tail
    "points": "gegnn-points-v3.safetensors",      # point clouds: landmark-v3's weights on a kNN graph, vsp fields
    "points-v2": "gegnn-points-v2.safetensors",   # the previous one (landmark-v2's weights, cloud heat-method fields)
    "points-v1": "gegnn-points-v1.safetensors",   # the one before (gegnn-landmark-v1's weights, K = 128)
}


class GeGnn(nn.Module):
    """Graph U-Net over a GeoPool hierarchy; ``GeGnn()`` is the paper's default network.

    ``forward(hierarchy)`` returns per-vertex codes, ``forward(hierarchy, pairs)`` the decoded distances
    of the pairs; ``embed(vertices, faces)`` runs the whole pipeline on one raw mesh.
    """

    def __init__(self, config: GeGnnConfig | None = None):
        super().__init__()
        self.config = config = config or GeGnnConfig()
        c, conv = config.channels, dict(aggr=config.aggr, relative_position=config.relative_position,
                                        edge_length=config.edge_length)
        self.stem = GeoConv(config.in_channels, c, **conv)
        self.stem_norm = nn.GroupNorm(config.groups, c)
        self.pool, self.unpool = GeoPool(), GeoUnpool()
        self.encoder = nn.ModuleList(ResBlocks(c, c, n, config.groups, **conv) for n in config.encoder_blocks)
        # Decoder stages take [skip || upsampled], hence 2c in.
        self.decoder = nn.ModuleList(ResBlocks(2 * c, c, n, config.groups, **conv)
                                     for n in config.decoder_blocks)
        self.head = nn.Sequential(nn.Linear(c, c, bias=False), nn.GroupNorm(config.groups, c), nn.ReLU(),
                                  nn.Linear(c, config.embed_dim))
        if config.landmarks:
            self.distance = LandmarkDecoder(config.embed_dim, config.landmarks, config.decoder_hidden,
                                            config.landmark_embedding,
                                            config.landmark_euclidean, config.landmark_output)
        elif config.spectral:
            self.distance = SpectralDecoder(config.embed_dim, config.spectral, config.decoder_hidden,
                                            config.spectral_embedding)
        else:
            self.distance = DistanceDecoder(config.embed_dim, config.decoder_hidden, config.decoder)

    # -- graphs -------------------------------------------------------------------------------------
    mesh_graph = staticmethod(mesh_graph)

    def hierarchy(self, graph: Graph) -> Hierarchy:
        """The GeoPool hierarchy this network's config asks for."""
        return build_hierarchy(graph, self.config.levels, self.config.sigma_c, self.config.sigma_n)

    # -- network ------------------------------------------------------------------------------------
    def forward(self, h: Hierarchy, pairs: Tensor | None = None, fields: Tensor | None = None) -> Tensor:
        """Vertex codes of the level-0 vertices of ``h``: the embeddings (N, embed_dim), or with
        landmarks or spectral modes the decoder's codes ``[e | fields | pos]`` (``fields``: (N, K) landmark
        distances or (N, m + 1) spectral codes, in normalized units). With ``pairs`` (P, 2) indexing those
        vertices, the decoded distances (P,) instead (one call, so DistributedDataParallel sees the
        decoder's parameters used inside forward)."""
        z = self.codes(self._unet(h), h, fields)
        if pairs is None:
            return z
        pairs = pairs.long()
        return self.distance(z[pairs[:, 0]], z[pairs[:, 1]])

    def codes(self, trunk: Tensor, h: Hierarchy, fields: Tensor | None = None) -> Tensor:
        """The vertex codes from the U-Net's output features ``trunk`` (N, channels): the head, and with
        landmarks the landmark fields and positions appended (see ``forward``)."""
        z = self.head(trunk)
        spec = FieldSpec.of(self.config)
        if spec is not None:
            if fields is None or fields.shape != (len(z), spec.columns):
                raise ValueError(f"a model with {spec.kind} fields ({spec.name}) needs fields of shape "
                                 f"({len(z)}, {spec.columns})")
            z = type(self.distance).codes(z, fields, h.graphs[0].pos)
        return z

    def _unet(self, h: Hierarchy) -> Tensor:
        g = h.graphs[0]
        x = torch.cat([g.pos, g.normal], dim=1)
        x = torch.relu(self.stem_norm(self.stem(x, g.pos, g.edge_index)))
        skips = []
        for level, blocks in enumerate(self.encoder):
            skips.append(x)
            coarse = h.graphs[level + 1]
            x = self.pool(x, h.clusters[level], coarse.num_nodes)
            x = blocks(x, coarse.pos, coarse.edge_index)
        for stage, blocks in enumerate(self.decoder):
            level = h.depth - 1 - stage
            fine = h.graphs[level]
            x = torch.cat([skips[level], self.unpool(x, h.clusters[level])], dim=1)
            x = blocks(x, fine.pos, fine.edge_index)
        return x

    # -- inference on raw meshes -----------------------------------------------------------------------
    def embed(self, vertices: np.ndarray, faces: np.ndarray | None = None, device=None, precision: str = "fp32",
              normals: np.ndarray | None = None, proxy="auto", fields: str | None = None):
        """Embed one mesh, or for a point-cloud model (``config.points``) one point cloud, given as NumPy
        arrays in any units (one forward pass).

        Vertices are normalized here (bounding box centered, longest half-extent 1, as in training);
        normals and edges are computed here (a cloud's normals may be given instead); distances from the
        result are in the input's units, between the input's vertices (a cloud's duplicate points share
        their codes; its ``part`` labels the parts of its neighbour graph). ``device`` (default: where the
        model is) moves the model there, as ``model.to(device)`` would, and the embedding lives there.
        ``precision`` governs the network and the returned embedding's decoder alike: ``"fp32"`` (the
        default), ``"bf16"`` (the network under bf16 autocast, the decoder's hidden layers in bf16: the
        network 1.6x faster on a CPU with AVX512-BF16, embeddings within ~1% (relative norm) of fp32), or
        ``"auto"``: bf16 only where the hardware has native bf16 (:mod:`gegnn.precision`), except for a
        decoder with a compiled fp32 decode on a CPU, which is faster (:func:`gegnn.precision.resolve_decoder`). A mesh of more than
        ``PROXY_ABOVE`` (40,000) vertices is embedded through a proxy of the same surface with ``PROXY_VERTICES``
        (20,000) (``proxy``: ``"auto"``, another vertex count, or None for the mesh itself;
        :mod:`gegnn.queries.proxy`): the network and fields run at the resolution the model knows, every vertex
        of the mesh gets the code of its closest point on its own connected part's proxy (never more vertices in
        all than the proxy's, however many parts: :func:`gegnn.queries.proxy.part_budget`), and all queries
        answer on the mesh's own vertices. A cloud of more points likewise: a random subset of that size is embedded, and every point
        gets the blend of its 3 nearest subset points' codes. With more than one torch thread
        (``torch.set_num_threads``) the U-Net runs on a thread of its own while the fields are computed,
        and a cloud's row-wise steps are spread over the threads (:mod:`gegnn.threads`); the result is the
        same to the bit. ``fields``: a landmark model's fields by another solver than the one it was trained
        on (its config's ``landmark_fields``; None: those), e.g. ``"exact"``, the exact solver's: the ceiling of
        the fields, at 4-15x a vsp field's time, or ``"paths"``, real paths within 0.05% of exact: the default
        model as close to the truth as with exact fields, at about 3x its own embed's time (docs/queries.md).

        Returns:
            :class:`gegnn.queries.embedding.Embedding`
        """
        # resolved for the device the model will run on; an unknown precision fails before any work. The
        # embedding's decoder resolves the request itself (a compiled fp32 decode may beat bf16).
        requested, precision = precision, resolve(precision, next(self.parameters()).device if device is None else device)
        if device is not None:  # outside inference mode: moved parameters stay trainable
            self.to(device)
        with torch.inference_mode():
            target = proxy_size(len(vertices), proxy)
            if target is None:
                return self._embed(vertices, faces, precision, normals, requested, fields)
            if self.config.points:  # a cloud: a subset embedded, each point blended from its 3 nearest there
                points = np.asarray(vertices, dtype=np.float64)
                subset = cloud_subset(points, target)
                emb = self._embed(points[subset], faces, precision, None if normals is None else
                                  np.asarray(normals)[subset], requested)
                corners, weights = cloud_weights(points, subset)
                return emb.blended(corners, weights, part=emb.part[corners[:, 0]],
                                   ambiguous=emb.ambiguous[corners].any(axis=1), walls=emb.walls[corners].any(axis=1),
                                   scatter=emb.scatter)
            vertices, faces = _validated(vertices, faces)
            proxy = proxy_of(vertices, faces, target)  # each vertex's closest point on its part's proxy
            return self._embed(proxy.mesh.vertices, proxy.mesh.faces, precision, None, requested, fields).at_points(
                proxy.face, proxy.bary, vertices=vertices, faces=faces)

    def _embed(self, vertices, faces, precision, normals, requested, fields=None):
        """One forward pass with the network in ``precision`` ("fp32" or "bf16"); the embedding's decoder
        gets the ``requested`` precision to resolve; ``fields``: :meth:`embed`'s."""
        if fields is not None and (fields not in LANDMARK_FIELDS or not self.config.landmarks or self.config.points
                                   or (fields in MESH_FIELDS and faces is None)):
            raise ValueError(f"fields={fields!r}: a mesh landmark model reads fields by one of "
                             f"{', '.join(LANDMARK_FIELDS)}; this model has {self.config.landmarks} landmarks"
                             f"{' on point clouds' if self.config.points else ''}")
        device = next(self.parameters()).device
        if self.config.points:
            if faces is not None:
                raise ValueError("a point-cloud model takes points only (faces=None)")
            hierarchy, fields, scale, expand, part, walls = self.cloud_inputs(vertices, normals, device)
        else:
            if faces is None:
                raise ValueError("this model embeds meshes: give faces, or use a point-cloud model "
                                 "(trained with gegnn train --neighbors)")
            hierarchy, fields, scale = self.inputs(vertices, faces, device, fields)
            expand, part, walls = None, None, None
        was_training = self.training
        self.eval()

        def autocast():
            return torch.autocast(device.type, dtype=torch.bfloat16) if precision == "bf16" else nullcontext()

        def unet():  # autocast and inference mode hold per thread
            h = hierarchy()
            with autocast(), torch.inference_mode():
                return h, self._unet(h)

        with fewer_for_torch():  # the network's kernels leave the fields a core
            trunk = beside(unet)  # on another core while the fields are computed here: read only by the codes
            fields = fields()
            h, trunk = trunk.result()
        with autocast(), torch.inference_mode():
            codes = self.codes(trunk, h, fields).float()
        self.train(was_training)
        if expand is not None:
            codes = codes[torch.as_tensor(expand, device=device)]
        sides = {} if walls is None else dict(ambiguous=walls.ambiguous, walls=walls.walls, scatter=walls.scatter)
        return Embedding(codes, self.distance, scale, requested, vertices=vertices, faces=faces, part=part, **sides)

    def inputs(self, vertices: np.ndarray, faces: np.ndarray, device, fields: str | None = None
               ) -> tuple[Callable, Callable, float]:
        """What the network reads for one mesh in any units, as two functions that :meth:`embed` runs side
        by side (the U-Net does not read the fields; their codes do): one giving the GeoPool hierarchy of
        the normalized mesh (bounding box centered, longest half-extent 1), one the landmark fields or
        spectral codes in normalized units (None for the paper's model); and the scale back to the input's
        units."""
        vertices, faces = _validated(vertices, faces)
        center, scale = normalization(vertices)
        scale = scale or 1.0  # a single point: keep units
        mesh = Mesh((vertices - center) / scale, faces)
        spec = FieldSpec.of(self.config)
        if fields is not None:  # another solver's landmark fields (embed's ``fields``)
            spec = dataclasses.replace(spec, solver=fields)

        def hierarchy():
            graph = self.mesh_graph(mesh.vertices, vertex_normals(mesh), unique_edges(mesh.faces))
            return self.hierarchy(graph).to(device)

        def fields():
            return None if spec is None else torch.as_tensor(spec.compute(mesh.vertices, mesh.faces), device=device)
        return hierarchy, fields, scale

    def cloud_inputs(self, points: np.ndarray, normals: np.ndarray | None, device):
        """What a point-cloud model reads for one cloud in any units (:mod:`gegnn.fields.pointcloud`), as
        :meth:`inputs` gives it for a mesh: a function giving the hierarchy of its distinct points,
        normalized (their normals estimated there), one giving their landmark fields (the heat method's
        row-by-row set-up is made here, on all of torch's threads; the rest on one, by the function), the
        scale back to the input's units; the distinct point of every input point (N,), the part of every input
        point (N,), and what :func:`gegnn.fields.cloud_sides.close_walls` saw of close sheets, per input point
        (:func:`gegnn.fields.pointcloud.cloud_graph`)."""
        from .fields.cloud_sides import Walls
        from .fields.pointcloud import cloud_graph, cloud_landmark_solver, collinear

        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not np.isfinite(points).all():
            raise ValueError(f"points must be a finite (N, 3) array, got shape {points.shape}")
        distinct, first, expand = np.unique(points, axis=0, return_index=True, return_inverse=True)
        if len(distinct) <= self.config.points:
            raise ValueError(f"{len(distinct)} distinct points: a cloud needs more than the {self.config.points} "
                             "neighbours each point's graph edges come from")
        if normals is not None:
            normals = np.asarray(normals, dtype=np.float64)
            if normals.shape != points.shape or not np.isfinite(normals).all():
                raise ValueError(f"normals must be a finite array of the points' shape {points.shape}")
            normals = normals[first] / np.maximum(np.linalg.norm(normals[first], axis=1, keepdims=True), 1e-30)
        if collinear(distinct):
            raise ValueError(f"the {len(distinct)} distinct points lie on a line: a point cloud must sample a surface")
        center, scale = normalization(distinct)
        p = (distinct - center) / scale
        g = cloud_graph(p, self.config.points, normals)
        spec = FieldSpec.of(self.config)
        solver = None if spec is None else cloud_landmark_solver(g.points, g.part, normals=normals, solver=spec.solver)

        def hierarchy():
            return self.hierarchy(self.mesh_graph(g.points, g.normals, g.edges)).to(device)

        def fields():
            return None if spec is None else torch.as_tensor(solver(spec.size).distances, device=device)
        expand = expand.reshape(-1)
        walls = Walls(g.walls.ambiguous[expand], g.walls.walls[expand], g.walls.scatter)
        return hierarchy, fields, scale, expand, g.part[expand], walls

    def finetune(self, vertices: np.ndarray, faces: np.ndarray, **options):
        """Finetune in place on one mesh from exact distances of a few of its vertices; returns the
        held-out error before and after (:func:`gegnn.finetune.finetune`, which lists the options)."""
        from .finetune import finetune
        return finetune(self, vertices, faces, **options)

    # -- checkpoints ------------------------------------------------------------------------------------
    def save(self, path, metadata: dict | None = None) -> None:
        """Single-file safetensors checkpoint: weights plus the config (JSON) in the metadata."""
        save_checkpoint(path, self, metadata=metadata)

    @classmethod
    def pretrained(cls, name: str | None = None, map_location="cpu") -> "GeGnn":
        """A model shipped in the package (fp16 weights; docs/model-card.md has data and accuracy).

        Args:
            name: a key of :data:`PRETRAINED`: ``"landmark"`` (the default: the most accurate geodesic
                model, landmark-v4: K = 256 landmark fields by virtual source propagation, trained with tubes,
                tori and knots), ``"landmark-v3"`` (the previous default), ``"landmark-v2"`` (heat-method
                fields), ``"landmark-v1"`` (K = 128), ``"paper"``
                (the paper's model), ``"biharmonic"`` (biharmonic distances), ``"points"`` (point clouds:
                ``model.embed(points)``; points-v3, landmark-v3's weights on fields by virtual sources),
                ``"points-v2"`` or ``"points-v1"`` (the previous ones, cloud heat-method fields).
        """
        with pretrained_file(name) as path:
            return cls.from_checkpoint(path, map_location)

    @classmethod
    def from_checkpoint(cls, path, map_location="cpu") -> "GeGnn":
        """Rebuild the network from a checkpoint file alone (config from its metadata), on the device
        ``map_location``."""
        ckpt = load_checkpoint(path)
        model = cls(ckpt.config)
        model.load_state_dict(ckpt.model_state)  # fp16 weights are cast to the model's fp32
        return model.to(map_location).eval()


def pretrained_file(name: str | None = None):
    """A context giving the path of the shipped model ``name`` (default: the first of :data:`PRETRAINED`)."""
    from importlib.resources import as_file, files

    name = name or next(iter(PRETRAINED))
    if name not in PRETRAINED:
        raise ValueError(f"no pretrained model {name!r}; shipped: {', '.join(PRETRAINED)}")
    return as_file(files("gegnn") / "weights" / PRETRAINED[name])


def _validated(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or not len(v):
        raise ValueError(f"vertices must be a non-empty (N, 3) array, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or not len(f):
        raise ValueError(f"faces must be a non-empty (F, 3) array, got shape {f.shape}")
    if not np.isfinite(v).all():
        raise ValueError("vertices contain non-finite coordinates")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError("face index out of range")
    return v, f.astype(np.int64)


