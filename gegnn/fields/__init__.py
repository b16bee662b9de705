"""Distance fields the network reads, computed from the geometry alone: the heat method on meshes
(:mod:`~gegnn.fields.heat`) and point clouds (:mod:`~gegnn.fields.cloud_heat`), farthest-point landmarks
and their fields (:mod:`~gegnn.fields.landmarks`), spectral codes (:mod:`~gegnn.fields.spectral`), the
point-cloud graph (:mod:`~gegnn.fields.pointcloud`), the field cache of training
(:mod:`~gegnn.fields.cache`) and the exact fields they are measured against (:mod:`~gegnn.fields.exact`).

Imports only the layer below (``gegnn.threads``, the compiled ``gegnn._*`` modules); never the model,
the trainer or the command line (docs/architecture.md).
"""
