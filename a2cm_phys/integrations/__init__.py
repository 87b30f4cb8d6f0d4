"""Adapters to other libraries' APIs over our batched games (``torchrl``: the
``[torchrl]`` extra). Nothing in the package imports them; they import only ``config``
and ``envs``."""
