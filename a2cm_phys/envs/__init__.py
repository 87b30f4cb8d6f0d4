"""The game: the rules once per mode (``grid``, ``physics``) and thin APIs over them
(``parallel``: PettingZoo-style, ``gym``: Gymnasium joint view, ``vector``: batched)."""
