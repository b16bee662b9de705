"""``python -m gegnn.cli`` (torchrun ``-m gegnn.cli`` too): the ``gegnn`` command."""
from . import main

main()
