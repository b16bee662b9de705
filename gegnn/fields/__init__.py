"""Distance fields the network reads, computed from the geometry alone: farthest-point landmarks and their
fields (:mod:`~gegnn.fields.landmarks`), on a mesh by virtual sources (the default's, from
:mod:`geodata.approximate_geodesic`) or the heat method (:mod:`~gegnn.fields.heat`), on a point cloud by
virtual sources on its local triangles (:mod:`~gegnn.fields.cloud_vsp`) or the heat method
(:mod:`~gegnn.fields.cloud_heat`), with the sides of its close walls told apart
(:mod:`~gegnn.fields.cloud_sides`); spectral codes (:mod:`~gegnn.fields.spectral`), the point-cloud graph
(:mod:`~gegnn.fields.pointcloud`), the field cache of training (:mod:`~gegnn.fields.cache`) and the exact
fields they are measured against (:mod:`~gegnn.fields.exact`).

Imports only the layer below (``gegnn.threads``, the compiled ``gegnn._*`` modules); never the model,
the trainer or the command line (docs/architecture.md).
"""
