"""How a weight plan's coins are laid in the weight jig's cap: the one rule, for magfab's plan (``magfab.jig``) and
for the readout's check of a plan file (``weigh --plan``). Standard library only."""

from __future__ import annotations

from typing import List

__all__ = ["coin_layout"]


def coin_layout(coins: int, pockets: int) -> List[int]:
    """How many coins go in each pocket (in order round the cap) for an even number of ``coins``: pairs dealt to the
    opposite pockets in turn, so each opposite pair holds equal stacks."""
    if coins % 2:
        raise ValueError(f"coins go in opposite pairs: {coins} is odd")
    half = pockets // 2
    out = [0] * pockets
    for k in range(coins // 2):
        out[k % half] += 1
        out[k % half + half] += 1
    return out
