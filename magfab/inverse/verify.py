"""Verification by building: a design ``magfab design`` offers is one ``magfab build`` builds.

The full chain's figures say what a design would do; only the build says it can be made (its board routed, its
parts modelled and their meshes sound, its bundle rendered). :func:`built` builds each verified design that meets
every requirement into ``DIR/builds/NAME`` (the spec it was built from is ``DIR/builds/NAME/spec.json``) exactly as
``magfab build designs/NAME.toml --out DIR/builds/NAME`` would. A design whose build is refused is a failed
verification, its reason the build's one line, and is never on the front nor chosen.

It is bounded by the verification budget (``study.verify`` designs at most, one build each) and resumable: each
outcome is stored in the study (user attribute ``built:N``) as soon as it is known, so a run interrupted between
builds (Ctrl-C ends the build under way, which leaves nothing half-written) builds only the rest when run again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import InputError, MagfabError
from ..pipeline import build
from ..spec import Spec
from .evaluate import bench_point
from .space import candidate_spec
from .study import Record
from .targets import Targets

__all__ = ["BUILDS", "PREFIX", "build_refusal", "built"]

#: The study folder's sub-folder the verified designs are built into.
BUILDS = "builds"
#: How a failed verification's reason begins.
PREFIX = "build refused: "

Progress = Callable[[int, int], None]


def build_refusal(spec: Spec, out: Path) -> str | None:
    """Build ``spec`` into ``out`` as ``magfab build`` does; None when it was built, else the build's one-line
    refusal (what ``magfab build`` prints before exiting). An interrupt is not caught."""
    try:
        build(spec, out)
    except MagfabError as exc:  # the user's input (exit 2), or a tool failing on it (exit 1)
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    except Exception as exc:  # as the search records a design's bug: failed, and the reason says so
        return f"bug: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
    return None


def built(study: Any, verified: list[Record], names: list[str], targets: Targets, base: Spec, folder: Path,
          progress: Progress | None = None) -> list[Record]:
    """``verified`` with each record that meets every requirement ("ok") built (module doc): as it was where its
    build succeeded (a previous run's stored outcome counts), else failed with the build's reason. ``study``: the
    Optuna study the outcomes are stored in (anything with ``user_attrs`` and ``set_user_attr``)."""
    kept = dict(study.user_attrs)
    todo = [i for i, r in enumerate(verified) if r.state == "ok"]
    out = list(verified)
    for n, i in enumerate(todo):
        r, key = verified[i], f"built:{verified[i].number}"
        if progress:
            progress(n, len(todo))
        if key not in kept:
            try:
                # the design as written (designs/NAME.toml, dimensions on the printer's step) and verified
                spec = candidate_spec(bench_point(r.point, base, targets), base, targets, names[i])
            except InputError as exc:  # the search evaluated this spec: not expected, but never offered unbuilt
                kept[key] = str(exc)
            else:
                kept[key] = build_refusal(spec, folder / BUILDS / names[i]) or ""
            study.set_user_attr(key, kept[key])
        if kept[key]:
            out[i] = replace(r, state="failed", reason=PREFIX + str(kept[key]))
    if progress:
        progress(len(todo), len(todo))
    return out
