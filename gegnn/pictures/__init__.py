"""Pictures of distance fields: PNG panels (:mod:`~gegnn.pictures.render`) and the interactive page
(:mod:`~gegnn.pictures.viewer`, with its ``assets/``; a mesh too large for a page drawn decimated,
:mod:`~gegnn.pictures.display`). Imports the decoders and fields below it, never the trainer or the command
line (docs/architecture.md).
"""
