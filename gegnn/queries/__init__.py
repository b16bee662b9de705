"""What a computed embedding answers: :class:`~gegnn.queries.embedding.Embedding` (distances, fields,
matrices, paths, log maps), distance matrices written to files (:mod:`~gegnn.queries.pairwise`), geodesic
paths (:mod:`~gegnn.queries.paths`), log maps (:mod:`~gegnn.queries.logmap`), shape statistics
(:mod:`~gegnn.queries.statistics`), a user's mesh and index files (:mod:`~gegnn.queries.files`), and large
meshes embedded through a proxy (:mod:`~gegnn.queries.proxy`).

Imports the fields below it, never the model (which makes an Embedding), the trainer or the command line
(docs/architecture.md).
"""
