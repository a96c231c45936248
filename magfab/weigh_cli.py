"""``magfab weigh-plan FIRST.csv PLAN.json``: the weight plan for a skin of its own stiffness, the middle step of the
two-stage bench (docs/bundle.md section 1b; the engine is :func:`magfab.export.weigh_plan.adapted_plan`).

Registered into ``magfab`` by :func:`register`, which hands over the CLI's error handling (one line and exit 2 for
the user's input, 130 for Ctrl-C) and how ``calibrate`` finds the spec and build folder, so this module never imports
:mod:`magfab.cli`."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import click

# magfab's own modules are imported lazily, inside the command, as in magfab.cli: `magfab --help` loads none of them.

Handler = Callable[[], AbstractContextManager[None]]
_handled: Handler = contextlib.nullcontext
_target: Callable[[Path | None, Path | None, Path], tuple[Any, Path]]


def register(group: click.Group, handled: Handler,
             target: Callable[[Path | None, Path | None, Path], tuple[Any, Path]]) -> None:
    """Add ``weigh-plan`` to ``group``: its errors handled by ``handled``, its spec found by ``target(spec, out,
    weighings)`` as ``magfab calibrate`` finds it (the build folder the weighings are in, or the one we stand in)."""
    global _handled, _target
    _handled, _target = handled, target
    group.add_command(weigh_plan)


@click.command("weigh-plan")
@click.argument("first", metavar="FIRST.csv", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("plan_out", metavar="PLAN.json", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--spec", "spec", type=click.Path(dir_okay=False, path_type=Path),
              help="The spec the sensor was built from (default: the build folder's own spec.json).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              help="The build folder whose spec to use (default: the one FIRST.csv is in, or the one you are in).")
@click.option("--force", is_flag=True, help="Overwrite PLAN.json if it exists.")
def weigh_plan(first: Path, plan_out: Path, spec: Path | None, out_dir: Path | None, force: bool) -> None:
    """Write the weight plan for this sensor's skin to PLAN.json, from its first two weighings (FIRST.csv, from
    `magfab-readout weigh FIRST.csv --first`): the model fitted to them gives the skin's stiffness, and the plan
    weighs it over its own range, where the build's plan (for the softest skin of the band) weighs a stiff skin over
    part of it. Then: `magfab-readout weigh OUT.csv --plan PLAN.json` and `magfab calibrate --weights OUT.csv`."""
    with _handled():
        from .check import preflight
        from .design import derive
        from .errors import ScanError
        from .export.weigh_plan import adapted_plan
        from .formats import bounded
        from .formats.weights_csv import read_weights_csv
        from .models.predict import predict

        if plan_out.exists() and not force:
            raise ScanError(f"{plan_out} exists: a plan is not overwritten (another name, or --force)")
        loaded, _ = _target(spec, out_dir, first)
        if loaded.array is not None:
            raise ScanError(f"{first.name}: an array is calibrated from scans; it has no weight plan")
        weighings = read_weights_csv(first, least=2)  # its errors name the file
        raw = bounded.read_bytes(first, "weighings CSV")
        design = preflight(derive(loaded))
        doc = adapted_plan(design, predict(design), weighings, first.name, hashlib.sha256(raw).hexdigest())
        text = json.dumps(doc, indent=1, sort_keys=True) + "\n"
        if not plan_out.parent.is_dir():
            raise ScanError(f"{plan_out}: its folder {plan_out.parent} does not exist")
        partial = plan_out.with_name(plan_out.name + ".partial")
        try:
            partial.write_text(text, encoding="utf-8")
            os.replace(partial, plan_out)  # whole or not at all
        finally:
            partial.unlink(missing_ok=True)
        mu = doc["adapted"]["mu_ratio"]
        heaviest = max(s["coins"] for s in doc["steps"])
        click.echo(f"plan for {loaded.name}'s skin: shear modulus {mu['value']:.2f} +/- {mu['sd']:.2f} of nominal, "
                   f"planned as {doc['stiffness']:g} times the softest skin's; {len(doc['steps'])} steps, at most "
                   f"{heaviest} coins, written to {plan_out}")
        click.echo(f"next: magfab-readout weigh weighings.csv --cap-g G --plan {plan_out}")
