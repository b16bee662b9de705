"""Training a GeGnn: batches from a geodata store (:mod:`~gegnn.training.data`), the device and loader
processes of a run (:mod:`~gegnn.training.devices`), the decoder warm-up (:mod:`~gegnn.training.warmup`),
the shipped models' recipes as presets (:mod:`~gegnn.training.presets`), what a run will cost
(:mod:`~gegnn.training.estimate`), a run directory's files (:mod:`~gegnn.training.rundir`) and the training
and evaluation loops (:mod:`~gegnn.training.loop`).

Sits above :mod:`gegnn.model` (it builds models); what it shares with finetuning, which the model offers
and so sits below it, lives there: the pair loop :mod:`gegnn.fitting`, the process group
:mod:`gegnn.distributed`, the metric :mod:`gegnn.metrics`. This file imports nothing (docs/architecture.md).
"""
