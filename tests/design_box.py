"""Designs drawn from the inverse search's default box (every silicone, tip and stock magnet), for tests that hold a
claim over the design space rather than at the fixtures' designs."""

from __future__ import annotations

__all__ = ["box_designs", "plan_or_refusal"]


def box_designs(n: int, seed: int) -> list:
    """``n`` designs of the inverse search's default box (every silicone, tip and stock magnet), as it samples them:
    the buildable ones (a design the build's preflight refuses is no sensor to weigh)."""
    from magfab.check import preflight
    from magfab.design import derive
    from magfab.errors import InputError
    from magfab.inverse.space import Space, candidate_spec
    from magfab.inverse.targets import parse_targets
    from magfab.spec import load_spec

    targets, base = parse_targets(""), load_spec(None)
    out = []
    for params in Space(targets, base).latin_hypercube(4 * n, seed):
        try:
            out.append(preflight(derive(candidate_spec(Space(targets, base).point(params), base, targets, "w"))))
        except InputError:
            continue
        if len(out) == n:
            break
    return out


def plan_or_refusal(jig, prediction) -> tuple[list | None, str]:
    """``jig``'s weight plan for ``prediction`` and "", or None and the one line that refuses it."""
    from magfab.errors import ScanError

    try:
        return jig.plan(prediction), ""
    except ScanError as e:
        return None, str(e)
